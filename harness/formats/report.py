"""Writing a run's results: traces (CSV), plots (PNG), ``summary.json`` and ``report.md``
in ``results/<scene>/``."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from harness.description import scene_kinds
from harness.judges import fmu_reference, metrics, revolutions
from harness.engine.run import RunResult
from harness.formats import plotting, rectifier_report
from harness.formats.run_files import (files_line, fmt, identity_lines, reference_error_lines, report_heading,
                                       save_figure, streamed_lines, summary_head, title_of, write_run)


def summarize_driveline(result: RunResult, reference=None) -> dict:
    """summary.json of a driveline run (or of a scene of no known kind, which may still hold a
    lever coupling: ``summarize`` says which kinds are which)."""
    scene = result.scene
    names = metrics.signals(result.scene)
    summary = summary_head(result)
    if len(result.times) > 1:
        # by the traces' own names (component.variable): one naming of a signal everywhere
        summary["statistics"] = {full: metrics.statistics(result.times, result.traces, [full],
                                                          scene.experiment.transient).get(full)
                                 for full in names.values() if full in result.traces}
    if "energy_balance" in scene.features and result.ok:
        if (problem := scene_kinds.driveline_problem(scene)) is None:
            summary["energy_balance"] = metrics.energy_balance(scene, result.times, result.traces)
            if (why := metrics.untrusted(summary["energy_balance"])) is not None:
                summary["untrusted"] = why
        else:       # the balance books the driveline's works and energies: not this system's
            summary["energy_balance_unavailable"] = f"{problem}: the driveline's energy balance does not apply"
    load_torque = f"{scene_kinds.roles(scene)[2]}.load_torque"
    if len(result.times) > 1 and result.ok and names.get("w2") in result.traces:
        summary["spectrum"] = metrics.spectral_components(result.times, result.traces, [names["tau2"], load_torque],
                                                          names["w2"], scene.experiment.transient)
    if reference is not None and len(result.times) and reference.info.get("source", "monolithic") != "monolithic":
        made = fmu_reference.summary(scene, result.times, result.traces, reference)
        summary.update(made)
    elif reference is not None and len(result.times):
        summary["error_vs_reference"] = metrics.driveline_errors(scene, result.times, result.traces, reference.times,
                                                                 reference.traces)
        summary["reference"] = {"source": "monolithic", "method": reference.method, "wall_time_s": reference.wall_time,
                                "rhs_evaluations": reference.n_rhs,
                                "energy_balance": metrics.energy_balance(
                                    scene, reference.times, reference.traces,
                                    reference.traces[f"{scene_kinds.roles(scene)[1]}.dissipated_energy"])}
    return summary


def write_report(path: Path, summary: dict):
    lines = report_heading(summary)
    lines.append(f"Master **{summary['master']}**, communication step {summary['step_s']:g} s, "
                 f"0 ... {summary['stop_s']:g} s; wall time {summary['wall_time_s']:.2f} s "
                 f"({summary['counters'].get('fmu_calls', 0)} FMI calls).")
    if summary.get("diagnosis") and summary["diagnosis"].get("kind") == "interrupted":
        lines += ["", f"**The run was interrupted (Ctrl-C):** {summary['failure']}.", "",
                  "What was computed until then is in traces.csv; the figures below cover that part only."]
    elif summary["failure"]:
        lines += ["", f"**The run failed:** {summary['failure']}", "",
                  "The traces up to the failure are in traces.csv."]
    if summary.get("untrusted"):
        lines += ["", f"**Not to be trusted:** {summary['untrusted']}."]
    if summary.get("unconnected_inputs"):
        lines += ["", f"**Unconnected:** {summary['unconnected_inputs']['note']}."]
    if summary.get("unchecked_connections"):
        lines += ["", f"**Units not checked:** {summary['unchecked_connections']['note']}."]
    lines += streamed_lines(summary, "the statistics and plots below use 1 row in {stride}, the energy balance every row")
    stats = summary.get("statistics")
    if stats:
        lines += ["", f"## Motion after the start-up transient (t >= {summary['transient_s']:g} s)", ""]
        if summary.get("transient_note"):
            lines += [f"The run is shorter than its scene: {summary['transient_note']}.", ""]
        if not any(stats.values()):
            lines += [f"No steady window: the run ended before the start-up transient did (t < "
                      f"{summary['transient_s']:g} s), so there are no statistics.", ""]
        lines += ["| signal | mean | amplitude A = (max-min)/2 | unevenness (w_max-w_min)/w_mean |",
                  "|---|---|---|---|"]
        for name, s in stats.items():
            if s:
                lines.append(f"| {name} | {fmt(s['mean'])} | {fmt(s['amplitude'])} | "
                             f"{fmt(s.get('unevenness'))} |")
        lines += ["", "Units: w [rad/s], a [rad/s^2], tau [N*m]; the coupling's tau1 is the torque on the drive shaft "
                  "(negative: it brakes the engine), its tau2 the torque on the driven shaft; each signal is "
                  "named as in traces.csv."]
    source = (summary.get("reference") or {}).get("source", "monolithic")
    lines += reference_error_lines(summary, f"Error against the {source} reference",
                                   "torques relative to the mean transmitted torque, speeds to the mean speed"
                                   if source == "monolithic" else "each signal relative to its RMS in the reference")
    if summary.get("energy_balance_unavailable"):
        lines += ["", "## Energy balance", "", f"Not computed: {summary['energy_balance_unavailable']}."]
    eb = summary.get("energy_balance")
    if eb:
        lines += ["", "## Energy balance", "",
                  f"work in {eb['work_in_J']:.6g} J - work out {eb['work_out_J']:.6g} J - kinetic change "
                  f"{eb['kinetic_change_J']:.4g} J - elastic change {eb['elastic_change_J']:.4g} J - dissipated "
                  f"{eb['dissipated_J']:.4g} J = residual {eb['residual_J']:.4g} J "
                  f"(**{100 * eb['residual_relative']:.2g} %** of the work in)."]
    spectrum = summary.get("spectrum")
    if spectrum:
        drawn = " (spectrum.png)" if "spectrum.png" in (summary.get("files") or ()) else ""
        lines += ["", f"## Spectrum{drawn}", "",
                  f"Amplitudes after the transient at the driven shaft's rotation frequency (its mean speed "
                  f"{spectrum['rotation_frequency_rad_s']:.4g} rad/s) and in the oscillograms' band 415-425 rad/s "
                  "(docs/physics.md#the-oscillograms-spectrum):", "",
                  "| signal | at the rotation frequency | in 415-425 rad/s |", "|---|---|---|"]
        for name, entry in spectrum.items():
            if isinstance(entry, dict):
                cells = [f"{entry[k]['amplitude']:.3g} N*m at {entry[k]['frequency_rad_s']:.4g} rad/s"
                         if k in entry else "-" for k in ("rotation", "band")]
                lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    if "parameters" in summary:
        lines += identity_lines(summary)
    lines += ["", files_line(summary)]
    if "revolution.png" in (summary.get("files") or []):
        lines.append(f"revolution.png, revolutions.png and {U12_PLOT} are over the driven shaft's angle, as the "
                     f"monograph draws its figures: U12 and the torques over the last whole revolution, the speeds "
                     f"and accelerations over the last {REVOLUTIONS_SHOWN}, U12 over the last {U12_REVOLUTIONS}.")
    path.write_text("\n".join(lines) + "\n")


#: revolutions of the driven shaft in the speeds-and-accelerations view over the angle
REVOLUTIONS_SHOWN = 3
#: U12 over the driven shaft's angle (the coupling's transfer function, a function of the
#: angle: over time it is a band of 60 revolutions), over its last two revolutions
U12_PLOT = "u12_over_angle.png"
U12_REVOLUTIONS = 2


def driven_angle(scene, times, traces) -> np.ndarray:
    """The driven shaft's angle [rad] along a run: its recorded ``phi``, else its speed
    integrated by trapezoids from 0 (at 1 ms steps a few 1e-7 rad of the revolution's
    2 pi: invisible in a plot)."""
    _, _, load = scene_kinds.roles(scene)
    if f"{load}.phi" in traces:
        return np.asarray(traces[f"{load}.phi"], dtype=float)
    w = np.asarray(traces[f"{load}.w"], dtype=float)
    t = np.asarray(times, dtype=float)
    return np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])


def angle_views(scene, times, traces) -> dict:
    """What the plots over the driven shaft's angle show, as the monograph draws its
    figures: U12 and the two torques over the last whole revolution (``revolution``), the
    speeds and accelerations over the last ``REVOLUTIONS_SHOWN`` (``revolutions``; fewer
    if the run has fewer).  Each view: ``angle`` [deg from the window's start], ``t``
    [s], and the traces by short name (``-tau1``: the torque the drive side transmits);
    None when the run holds not one whole revolution."""
    names = metrics.signals(scene)
    phi2 = driven_angle(scene, times, traces)
    views = {}
    for key, count, shown in (("revolution", 1, ("U12", "tau1", "tau2")),
                              ("revolutions", REVOLUTIONS_SHOWN, ("w1", "w2", "a1", "a2")),
                              ("u12", U12_REVOLUTIONS, ("U12",))):
        window = revolutions.last_revolutions(phi2, count)
        while window.stop - window.start < 2 and count > 1:
            count -= 1
            window = revolutions.last_revolutions(phi2, count)
        if window.stop - window.start < 2:
            views[key] = None
            continue
        view = {"angle": np.degrees(revolutions.revolution_angle(phi2, window)), "t": np.asarray(times)[window],
                "count": count}
        for short in shown:
            if names[short] in traces:
                values = np.asarray(traces[names[short]], dtype=float)[window]
                view["-tau1" if short == "tau1" else short] = -values if short == "tau1" else values
        views[key] = view
    return views


def plot(out: Path, result: RunResult, reference=None):
    plt = plotting.pyplot()
    names = metrics.signals(result.scene)
    t = result.times
    tr = result.traces
    transient = result.scene.experiment.transient
    title = title_of(result)

    # The drive side's torque is plotted as the torque it transmits, -tau1, so both curves share a sign.
    for filename, quantity, unit, a, b, sign in (("speeds.png", "speed", "rad/s", "w1", "w2", 1.0),
                                                 ("torques.png", "torque", "N*m", "tau1", "tau2", -1.0),
                                                 ("accelerations.png", "acceleration", "rad/s^2", "a1", "a2", 1.0)):
        if names[a] not in tr or names[b] not in tr:
            continue
        drive, driven = sign * np.asarray(tr[names[a]], dtype=float), np.asarray(tr[names[b]], dtype=float)
        shown = f"-{names[a]}" if sign < 0 else names[a]
        save_figure(plotting.time_view(t, [(f"{shown} (drive)", drive), (f"{names[b]} (driven)", driven)], quantity,
                                       unit, transient, title,
                                       (f"{names[b]} - ({shown})" if sign < 0 else f"{names[b]} - {names[a]}",
                                        driven - drive)),
                    out / filename)
    if scene_kinds.roles(result.scene)[2] is not None:   # our load shaft (a user's FMU in its place: no angle to plot over)
        plot_over_angle(out, result.scene, t, tr, title)
        _plot_spectrum(out, result, title, plt)
    if reference is not None and all(names[k] in tr for k in ("w1", "w2", "tau2")):
        save_figure(reference_figure(t, tr, reference, names, result.master, title), out / "vs_reference.png")


def reference_figure(t, traces, reference, names: dict, master: str, title: str):
    """vs_reference.png: w1, w2 and tau2 of the co-simulation over the reference's, and the
    errors of both speeds and both torques, co-simulation - reference (positive: the
    co-simulation above the reference; drive side blue, driven side red; a dense error drawn
    as its envelope)."""
    plt = plotting.pyplot()
    fig, axes = plt.subplots(5, 1, figsize=(11, 12), sharex=True, layout="constrained")
    n = min(len(t), len(reference.times))
    for ax, key, unit in zip(axes, ("w1", "w2", "tau2"), ("rad/s", "rad/s", "N*m")):
        name = names[key]
        ax.plot(reference.times[:n], reference.traces[name][:n], "k-", lw=1.2, label=f"reference ({fmu_reference.label(reference)})")
        ax.plot(t[:n], traces[name][:n], "C1--", lw=0.8, label=f"co-simulation ({master})")
        ax.set_ylabel(f"{name} [{unit}]")
    for ax, pair, unit in ((axes[3], ("w1", "w2"), "rad/s"), (axes[4], ("tau1", "tau2"), "N*m")):
        for key, color in zip(pair, plotting.PAIR_COLOURS):
            name = names[key]
            if name in traces and name in reference.traces:
                plotting.trace(ax, t[:n], np.asarray(traces[name][:n]) - np.asarray(reference.traces[name][:n]),
                               color, f"error {name}")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_ylabel(f"co-simulation - reference\n[{unit}]")
    axes[-1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        plotting.legend_outside(ax)
    fig.suptitle(f"{title}: co-simulation vs reference")
    return fig


def _angle_panels(names: dict) -> dict:
    """The over-angle figures: file -> (view, [(y label, [(short name, legend)])]), each
    legend naming its signal as the traces do."""
    return {"revolution.png": ("revolution", [("U12 [1]", [("U12", names["U12"])]),
                                              ("torque [N*m]", [("-tau1", f"-{names['tau1']} (drive)"),
                                                                ("tau2", f"{names['tau2']} (driven)")])]),
            "revolutions.png": ("revolutions", [("speed [rad/s]", [("w1", f"{names['w1']} drive"),
                                                                   ("w2", f"{names['w2']} driven")]),
                                                ("acceleration [rad/s^2]",
                                                 [("a1", f"{names['a1']} drive"), ("a2", f"{names['a2']} driven")])]),
            U12_PLOT: ("u12", [("U12 = dPhi/dphi2 [1]", [("U12", f"{names['U12']}, the coupling's transfer function")])])}


def plot_over_angle(out: Path, scene, times, traces, title: str):
    """``revolution.png`` (U12 and the torques over the driven shaft's last whole
    revolution) and ``revolutions.png`` (speeds and accelerations over its last few), over
    the driven shaft's angle as the monograph's figures are; nothing when the run holds
    no whole revolution."""
    views = angle_views(scene, times, traces)
    panels = _angle_panels(metrics.signals(scene))
    for filename, (key, rows) in panels.items():
        if views[key] is not None:
            save_figure(angle_figure(views[key], key, rows, title), out / filename)


def angle_figure(view: dict, key: str, rows: list, title: str):
    """One figure over the driven shaft's angle: a panel per (y label, [(short name,
    legend)]) of ``rows``, drawn from ``view`` (``angle_views``)."""
    plt = plotting.pyplot()
    fig, axes = plt.subplots(len(rows), 1, figsize=(11, 1.2 + 2.8 * len(rows)), sharex=True, squeeze=False,
                             layout="constrained")
    for ax, (label, series) in zip(axes[:, 0], rows):
        for short, legend in series:
            if short in view:
                ax.plot(view["angle"], view[short], "-", lw=0.9, label=legend)
        if key == "u12":
            ax.axhline(1.0, color="0.5", lw=0.8, ls="--", label="1 (synchronous)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        # one panel of long labels: its legend above it, so the curve keeps the figure's width
        (plotting.legend_above if key == "u12" else plotting.legend_outside)(ax)
    count = view["count"]
    axes[-1, 0].set_xlabel(f"driven shaft angle phi2 [deg] over its last {'whole revolution' if count == 1 else f'{count} whole revolutions'} "
                           f"(t = {view['t'][0]:.3f} ... {view['t'][-1]:.3f} s)")
    axes[-1, 0].set_xticks(np.arange(0.0, 360.0 * count + 1.0, 90.0 if count == 1 else 180.0))
    fig.suptitle(title if key != "u12" else f"{title}: U12 over the driven shaft's angle")
    return fig


def _plot_spectrum(out: Path, result: RunResult, title: str, plt):
    """spectrum.png: amplitude spectra of the driven-shaft torque and the load torque after
    the transient, each marked at the bins the report states (the peak near the driven
    shaft's rotation frequency and in the oscillograms' 415-425 rad/s band,
    docs/physics.md#the-oscillograms-spectrum, both from ``metrics.spectral_components``), with
    the window and the frequency resolution said."""
    names = metrics.signals(result.scene)
    load_torque = f"{scene_kinds.roles(result.scene)[2]}.load_torque"
    transient = result.scene.experiment.transient
    t, tr = result.times, result.traces
    keep = t >= t[0] + transient
    if keep.sum() < 8:
        return
    stated = metrics.spectral_components(t, tr, [names["tau2"], load_torque], names["w2"], transient)
    rotation = abs(stated["rotation_frequency_rad_s"])
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True, layout="constrained")
    resolution = None
    for ax, (name, label) in zip(axes, ((names["tau2"], f"{names['tau2']}, torque on the driven shaft"),
                                        (load_torque, f"{load_torque}, the load's resisting torque"))):
        if name not in tr:
            continue
        omega, amplitude = metrics.amplitude_spectrum(t, tr[name], transient)
        resolution = float(omega[1] - omega[0]) if len(omega) > 1 else resolution
        ax.semilogy(omega, np.maximum(amplitude, 1e-6), "C0-", lw=0.7, label=label)
        ax.axvline(rotation, color="C3", ls="--", lw=0.8, label=f"mean driven-shaft speed {rotation:.4g} rad/s")
        ax.axvspan(*metrics.OSCILLOGRAM_BAND, color="C2", alpha=0.3, label="415-425 rad/s (oscillograms)")
        for key, marker, color in (("rotation", "o", "C3"), ("band", "s", "C2")):
            peak = stated.get(name, {}).get(key)
            if peak:        # the bin and amplitude report.md states
                ax.plot(peak["frequency_rad_s"], peak["amplitude"], marker, color=color, mfc="none", ms=8, mew=1.5,
                        label=f"peak {peak['amplitude']:.3g} N*m at {peak['frequency_rad_s']:.4g} rad/s")
        ax.set_ylabel("amplitude [N*m]")
        ax.set_ylim(1e-4, None)
        ax.grid(alpha=0.3)
        plotting.legend_outside(ax)
    axes[-1].set_xlim(0.0, 600.0)
    window = t[keep][-1] - t[keep][0]
    axes[-1].set_xlabel("angular frequency [rad/s]" + ("" if resolution is None else
                        f"  (Hann window over {window:.4g} s: bins {resolution:.3g} rad/s apart)"))
    fig.suptitle(f"{title}: spectrum after t = {t[0] + transient:g} s")
    save_figure(fig, out / "spectrum.png")


def write_driveline(out: Path, result: RunResult, reference=None, plots: bool = True) -> dict:
    return write_run(out, result, reference, summarize_driveline, write_report, plot, plots)


@dataclass(frozen=True)
class KindReport:
    """What a kind of scene's run reports: its summary (``summarize(result, reference)``,
    what summary.json holds) and its files (``write(out, result, reference, plots)``)."""
    summarize: Callable[..., dict]
    write: Callable[..., dict]


#: each kind of scene's report (harness.description.scene_kinds.KINDS)
REPORTS = {"driveline": KindReport(summarize_driveline, write_driveline),
           "rectifier": KindReport(rectifier_report.summarize, rectifier_report.write)}


def report_of(scene) -> KindReport:
    """The report of ``scene``'s kind; a scene of no known kind (a user's FMU in a role of
    the driveline) gets the driveline's, which leaves out what its roles do not give."""
    return REPORTS.get(scene_kinds.kind_of(scene), REPORTS["driveline"])


def summarize(result: RunResult, reference=None) -> dict:
    """What summary.json holds for ``result``, by its kind of scene's report (a run from
    Python without ``out`` gets it without any file written)."""
    return report_of(result.scene).summarize(result, reference)


def write(out: Path, result: RunResult, reference=None, plots: bool = True) -> dict:
    """A run's files in ``out`` (see ``harness.formats.run_files.write_run``), written by
    its kind of scene's report; ``plots``: false draws none."""
    return report_of(result.scene).write(out, result, reference, plots)
