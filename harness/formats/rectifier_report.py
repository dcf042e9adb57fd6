"""The freewheel rectifier scene's run report: summary, report.md (engagement phases,
gaps, energy balance, the kinematics beside the source's description) and plots; the
analysis it reports is harness.judges.rectifier's."""
from __future__ import annotations

import math

import numpy as np

from harness.description import scene_kinds
from harness.formats import plotting
from harness.formats.run_files import (files_line, identity_lines, reference_error_lines, report_heading,
                                       save_figure, streamed_lines, summary_head, title_of, write_run)
from harness.judges.rectifier import analyse, errors


def summarize(result, reference=None) -> dict:
    scene = result.scene
    summary = summary_head(result)
    if len(result.times) > 1:
        summary["freewheel"] = analyse(scene, result.times, result.traces)
        summary["energy_balance"] = summary["freewheel"]["energy_balance"]
    if reference is not None and len(result.times):
        summary["error_vs_reference"] = errors(scene, result.times, result.traces, reference)
        summary["reference"] = {"method": reference.method, "wall_time_s": reference.wall_time,
                                "rhs_evaluations": reference.n_rhs,
                                "energy_balance": analyse(scene, reference.times, reference.traces)["energy_balance"]}
    return summary


def _f(x, digits=4):
    if x is None:
        return "-"
    if isinstance(x, float) and x != 0.0 and (abs(x) >= 1e4 or abs(x) < 1e-3):
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def write_report(path, summary: dict):
    lines = report_heading(summary) + [
             f"Master **{summary['master']}**, communication step {summary['step_s']:g} s, 0 ... {summary['stop_s']:g} s; "
             f"wall time {summary['wall_time_s']:.2f} s.  One FMU (`FreewheelRectifier`) holds the whole chain "
             "(docs/record/decisions.md: why one FMU)."]
    if summary["failure"]:
        interrupted = (summary.get("diagnosis") or {}).get("kind") == "interrupted"
        lines += ["", f"**The run {'was interrupted (Ctrl-C)' if interrupted else 'failed'}:** {summary['failure']}",
                  "", "The traces up to the " + ("interruption" if interrupted else "failure") + " are in traces.csv."]
    if summary.get("unconnected_inputs"):
        lines += ["", f"**Unconnected:** {summary['unconnected_inputs']['note']}."]
    lines += streamed_lines(summary, "the engagement, the energy balance and the plots below use 1 row in {stride}")
    fw = summary.get("freewheel")
    if fw:
        d = fw["derived"]
        z1, z2, z3 = d["gaps_rad"]
        lines += ["", "## Engagement and free-wheeling", "",
                  f"Rocker period {fw['period_s'] * 1e3:.2f} ms; the freewheel was engaged (discs clamped, e > 0) "
                  f"{100 * fw['engaged_fraction']:.1f} % of the time and free-wheeling the rest.", "",
                  "Per rocker cycle, the main engagement (the longest contact on the ramps; before it the "
                  "half-couplings may touch the ramps briefly and bounce back across the gap):", "",
                  "| cycle | engaged from [s] | to [s] | for [ms] | bounces before | rocker angle at engagement [rad] | "
                  "into the forward stroke | peak rocker torque [N*m] | peak torsion torque [N*m] | "
                  "peak torsion twist [rad] | discs slipping [ms] (up to rocker torque [N*m]) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for p in fw["phases"]:
            slip = (f"{1e3 * p['slip_time_s']:.1f} ({p['largest_rocker_torque_while_slipping_Nm']:.1f})"
                    if p["slip_time_s"] else "0")
            lines.append(f"| {p['cycle']}{'' if p['complete'] else ' (cut)'} | {p['start_s']:.4f} | {p['end_s']:.4f} | "
                         f"{1e3 * p['duration_s']:.1f} | {p['bounces_before']} | "
                         f"{p['rocker_angle_at_engagement_rad']:.4f} | {100 * p['rocker_stroke_fraction']:.0f} % | "
                         f"{p['peak_rocker_torque_Nm']:.1f} | {p['peak_torsion_torque_Nm']:.1f} | "
                         f"{p['peak_torsion_twist_rad']:.4f} | {slip} |")
        lines += ["", "## The gaps closing and opening", "",
                  f"z1 = {z1:.4f} rad (axial gap of the freewheel as a rocker angle), z2 = {z2:.4f} rad (torsion "
                  f"splines), z3 = {z3:.4f} rad (gear mesh).  Counted at the recorded resolution; the FMU located "
                  f"{_f(fw['events_located'])} events in all (gap edges and stick/slip changes).", "",
                  "| gap | closed on the drive flank | closed on the back flank | opened | share of time open |",
                  "|---|---|---|---|---|"]
        for label, g in fw["gap_transitions"].items():
            lines.append(f"| {label} | {g['closed_drive_flank']} | {g['closed_back_flank']} | {g['opened']} | "
                         f"{100 * fw['fraction_of_time_gap_open'][label]:.0f} % |")
        eb = fw["energy_balance"]
        lines += ["", "## Energy balance", "",
                  f"input work (rocker) {eb['input_work_J']:.6g} J = output work {eb['output_work_J']:.4g} J + change of "
                  f"stored energy (kinetic + elastic) {eb['stored_change_J']:.6g} J + dissipated {eb['dissipated_J']:.6g} J "
                  f"+ residual {eb['residual_J']:.3g} J.", "",
                  f"The rocker put in up to {eb['largest_input_work_J']:.4g} J within a stroke (most of it comes back "
                  f"when the torsion shaft unwinds); relative to that the residual is "
                  f"**{eb['residual_relative']:.2g}** at the end and at most {eb['worst_residual_relative']:.2g} "
                  "at any recorded time."]
        lines += ["", "## Kinematics beside the source's description", ""] + _comparison(fw)
    lines += reference_error_lines(summary, "Against the monolithic reference",
                                   "speeds relative to the rocker's peak speed, torques to the reference's peak torque")
    if "parameters" in summary:
        lines += identity_lines(summary)
    lines += ["", files_line(summary) + (" (kinematics.png: elements 1-4, as the paper's Figs. 8-11)"
                                         if "kinematics.png" in summary.get("files", []) else "")]
    path.write_text("\n".join(lines) + "\n")


def _comparison(fw: dict) -> list[str]:
    """The source's statements (in our words) beside the numbers of this run."""
    k = fw["kinematics"]
    d = fw["derived"]
    z1, z2, z3 = d["gaps_rad"]
    phases = fw["phases"]
    rows = []
    rocker = k["rocker (1)"]
    rows.append(("Rocker (Fig. 8): harmonic oscillation phi0 (1 - cos(omega t)), phi0 = 0.103 rad, omega = 42.41 rad/s "
                 "(8).",
                 f"angle {rocker['angle_range_rad'][0]:.4f} ... {rocker['angle_range_rad'][1]:.4f} rad, peak speed "
                 f"{rocker['peak_speed_rad_s']:.3f} rad/s (phi0 omega = {d['rocker_peak_speed_rad_s']:.3f}), peak "
                 f"acceleration {rocker['peak_acceleration_rad_s2']:.1f} rad/s^2 (phi0 omega^2 = "
                 f"{d['rocker_peak_acceleration_rad_s2']:.1f}): prescribed, exact."))
    if phases:
        first = phases[0]
        later = [p["rocker_angle_at_engagement_rad"] for p in phases[1:]]
        rows.append(("The torque on the rocker, and its turning relative to the torsion shaft, appear only once the "
                     "axial gap of the freewheel has been taken up.",
                     f"first stroke (from rest, every gap open): first contact of the ramps at rocker angle "
                     f"{first['rocker_angle_at_first_contact_rad']:.4f} rad (z1 = {z1:.4f} rad plus what the free "
                     f"parts moved), sustained torque from {first['rocker_angle_at_engagement_rad']:.4f} rad, after the "
                     f"driven parts crossed z2 = {z2:.4f} and z3 = {z3:.4f} rad; "
                     + (f"later strokes from {min(later):.4f} ... {max(later):.4f} rad (the rocker's stroke is "
                        f"{2 * d['rocker_peak_speed_rad_s'] / (2 * math.pi / fw['period_s']):.3f} rad)"
                        if later else "no later stroke engaged")
                     + "; before that the rocker torque is the return springs' "
                     f"{d['return_spring_torque_Nm']:.3f} N*m."))
    half = k["half-couplings (2)"]
    rows.append(("Half-couplings (Fig. 9): the balls keep them tied to the rocker through the whole cycle (1); they "
                 "follow the rocker, lagging it by the gap.",
                 f"angle {half['angle_range_rad'][0]:.4f} ... {half['angle_range_rad'][1]:.4f} rad (amplitude "
                 f"{half['angle_amplitude_rad']:.4f} against the rocker's {rocker['angle_amplitude_rad']:.4f}), peak speed "
                 f"{half['peak_speed_rad_s']:.3f} rad/s, peak acceleration {half['peak_acceleration_rad_s2']:.0f} "
                 "rad/s^2 (the impacts at the gaps' edges)."))
    driven = k["driven parts, torsion input end (3)"]
    end = k["torsion output end (4)"]
    twist = max((p["peak_torsion_twist_rad"] for p in phases), default=float("nan"))
    rows.append(("Driven parts and torsion shaft (Figs. 10, 11): in the stop mode the output is held, so the torsion's "
                 "input end turns only by the shaft's twist and the gaps, its output end only within the mesh.",
                 f"input end {driven['angle_range_rad'][0]:.4f} ... {driven['angle_range_rad'][1]:.4f} rad, peak twist "
                 f"{twist:.4f} rad; output end {end['angle_range_rad'][0]:.4f} ... {end['angle_range_rad'][1]:.4f} rad "
                 f"(the backlash z3 = {z3:.4f} rad plus the mesh deflection); peak speeds {driven['peak_speed_rad_s']:.2f} "
                 f"and {end['peak_speed_rad_s']:.2f} rad/s."))
    sl = fw["self_locking"]
    slip_torque = max((p["largest_rocker_torque_while_slipping_Nm"] for p in phases), default=0.0)
    peak_torque = max((p["peak_rocker_torque_Nm"] for p in phases), default=0.0)
    rows.append(("Self-locking: the discs hold while tan(alpha) <= n f; with n = 9 and alpha = 17.5 deg the least f is "
                 "0.035.",
                 f"tan(alpha) = {sl['tan_alpha']:.4f}, n f_s = {sl['n_f_s']:.3f}, least f = {sl['f_min']:.4f}: "
                 + (f"while engaged the discs slipped only as the ramps came into contact, at rocker torques up to "
                    f"{slip_torque:.1f} N*m (the clamp force still small, the driven parts hit through the gaps), "
                    f"and held up to the peak of {peak_torque:.0f} N*m" if slip_torque else
                    f"while engaged the discs held up to the peak of {peak_torque:.0f} N*m")
                 + "; in free-wheeling they slip, passing only the drag M_v."))
    if fw["torque_impulses"]:
        durations = [i["duration_s"] for i in fw["torque_impulses"]]
        rows.append(("The torsion shafts stretch the torque impulses in time (that is what gives the transmission "
                     "overlapping, continuous output torque).",
                     f"torque above 5 % of its peak for {1e3 * min(durations):.1f} ... {1e3 * max(durations):.1f} ms per "
                     f"cycle, against a forward stroke of {1e3 * fw['period_s'] / 2:.1f} ms; peaks "
                     + ", ".join(f"{i['peak_Nm']:.0f}" for i in fw["torque_impulses"]) + " N*m."))
    rows.append(("The gaps harm the elements' kinematics; the paper's computed and measured kinematics differ by "
                 "10-15 %.",
                 "the dead stroke above and the impacts at the gaps' edges (accelerations of the half-couplings and "
                 "driven parts far above the rocker's) are the gaps' doing.  The paper's curves themselves are not in "
                 "the text we have, so the comparison stops at these statements."))
    out = ["| the source says (in our words) | this run |", "|---|---|"]
    out += [f"| {a} | {b} |" for a, b in rows]
    return out


def plot(out, result, reference=None):
    plt = plotting.pyplot()

    scene = result.scene
    name = scene_kinds.rectifier(scene)
    t = result.times
    tr = {k.split(".", 1)[1]: v for k, v in result.traces.items() if k.startswith(name + ".")}
    title = title_of(result)
    elements = (("rocker", "1 rocker"), ("half_coupling", "2 half-couplings"), ("driven", "3 driven parts"),
                ("torsion_end", "4 torsion output end"))

    fig, axes = plt.subplots(3, 1, figsize=(11, 9), sharex=True, layout="constrained")
    for ax, (quantity, unit) in zip(axes, (("angle", "rad"), ("speed", "rad/s"), ("acceleration", "rad/s^2"))):
        for prefix, label in elements:
            ax.plot(t, tr[f"{prefix}_{quantity}"], lw=0.8, label=label)
        ax.set_ylabel(f"{quantity} [{unit}]")
        ax.grid(alpha=0.3)
    axes[2].set_yscale("symlog", linthresh=200.0)
    plotting.legend_outside(axes[0])
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}: kinematics of the elements (cf. the paper's Figs. 8-11)")
    save_figure(fig, out / "kinematics.png")

    model = scene_kinds.rectifier_model(scene)
    fig, axes = plt.subplots(4, 1, figsize=(11, 10), sharex=True, layout="constrained")
    for ax, (var, gap, label) in zip(axes, (("msm_deflection", model.z1, "e = phi1 - phi2 (gap z1)"),
                                            ("torsion_twist", model.z2, "phi3 - phi4 (gap z2)"),
                                            ("mesh_deflection", model.z3, "phi4 - phi5 (gap z3)"))):
        ax.axhspan(-gap, 0.0, color="C1", alpha=0.15, label="gap")
        ax.plot(t, tr[var], "k-", lw=0.8, label=label)
        ax.set_ylabel("[rad]")
        ax.grid(alpha=0.3)
        plotting.legend_outside(ax)
    for k, (var, label) in enumerate((("msm_contact", "freewheel"), ("torsion_contact", "torsion splines"),
                                      ("mesh_contact", "gear mesh"), ("disc_slip", "disc slip"))):
        axes[3].plot(t, tr[var] + 3.0 * (3 - k), lw=0.8, label=f"{label} (+{3 * (3 - k)})")
    axes[3].set_ylabel("contact: +1 drive, 0 open, -1 back")
    plotting.legend_outside(axes[3])
    axes[3].grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}: the gaps closing and opening")
    save_figure(fig, out / "gaps.png")

    fig, ax = plt.subplots(1, 1, figsize=(11, 4), layout="constrained")
    for var, label in (("rocker_torque", "T12 rocker -> half-couplings"), ("disc_torque", "through the discs"),
                       ("disc_capacity", "discs' capacity"), ("torsion_torque", "T34 torsion shaft"),
                       ("mesh_torque", "T45 gear mesh")):
        ax.plot(t, tr[var], lw=0.8, label=label, ls="--" if var == "disc_capacity" else "-")
    ax.set_ylabel("torque [N*m]")
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)
    plotting.legend_outside(ax)
    fig.suptitle(f"{title}: torques")
    save_figure(fig, out / "torques.png")

    stored = tr["kinetic_energy"] + tr["elastic_energy"]
    stored = stored - stored[0]
    residual = tr["input_work"] - tr["output_work"] - stored - tr["dissipated_energy"]
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True, layout="constrained")
    axes[0].plot(t, tr["input_work"], lw=0.9, label="input work (rocker)")
    axes[0].plot(t, stored, lw=0.9, label="stored (kinetic + elastic)")
    axes[0].plot(t, tr["dissipated_energy"], lw=0.9, label="dissipated")
    axes[0].plot(t, tr["output_work"], lw=0.9, label="output work")
    axes[0].set_ylabel("energy [J]")
    plotting.legend_outside(axes[0])
    axes[0].grid(alpha=0.3)
    axes[1].plot(t, residual, "k-", lw=0.8)
    axes[1].set_ylabel("residual [J]")
    axes[1].set_xlabel("time [s]")
    axes[1].grid(alpha=0.3)
    fig.suptitle(f"{title}: energy balance, input = stored + dissipated + output + residual")
    save_figure(fig, out / "energy.png")

    if reference is not None:
        n = min(len(t), len(reference.times))
        compared = (("half_coupling_speed", "rad/s"), ("driven_speed", "rad/s"), ("torsion_torque", "N*m"))
        fig, axes = plt.subplots(5, 1, figsize=(11, 12), sharex=True, layout="constrained")
        for ax, (var, unit) in zip(axes, compared):
            ax.plot(reference.times[:n], reference.traces[f"{name}.{var}"][:n], "k-", lw=1.2, label="reference")
            ax.plot(t[:n], tr[var][:n], "C1--", lw=0.8, label=f"FMU ({result.master})")
            ax.set_ylabel(f"{var} [{unit}]")
        # the report states the error against the reference: drawn at its own scale
        for ax, unit in zip(axes[3:], ("rad/s", "N*m")):
            for color, (var, _) in zip(plotting.PAIR_COLOURS, (v for v in compared if v[1] == unit)):
                plotting.trace(ax, t[:n], np.asarray(tr[var][:n]) - np.asarray(reference.traces[f"{name}.{var}"][:n]),
                               color, f"error {var}")
            ax.set_ylabel(f"FMU - reference\n[{unit}]")
        for ax in axes:
            ax.grid(alpha=0.3)
            plotting.legend_outside(ax)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(f"{title}: FMU against the monolithic reference")
        save_figure(fig, out / "vs_reference.png")


def write(out, result, reference=None, plots: bool = True) -> dict:
    return write_run(out, result, reference, summarize, write_report, plot, plots)
