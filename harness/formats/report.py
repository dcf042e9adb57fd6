"""Writing a run's results: traces (CSV), plots (PNG), ``summary.json`` and ``report.md``
in ``results/<scene>/``."""
from __future__ import annotations

import platform
from pathlib import Path

from harness.description import kinds
from harness.description import scene as scenes
from harness.judges import metrics
from harness.engine.run import RunResult
from harness.formats import rectifier_report
from harness.formats.run_files import fmt, reference_error_lines, write_run


def summarize(result: RunResult, reference=None) -> dict:
    scene = result.scene
    names = metrics.signals(result.scene)
    summary = {
        "scene": scene.name,
        "description": scene.description,
        "master": result.master,
        "step_s": result.step,
        "stop_s": scene.experiment.stop,
        "transient_s": scene.experiment.transient,
        "ok": result.ok,
        "failure": result.failure,
        "diagnosis": getattr(result, "diagnosis", None),
        "wall_time_s": result.wall_time,
        "counters": result.counters,
        "python": platform.python_version(),
    }
    if result.stream:
        summary["stream"] = result.stream
    if result.unconnected_inputs:
        summary["unconnected_inputs"] = {"inputs": list(result.unconnected_inputs),
                                         "note": scenes.unconnected_message(result.unconnected_inputs)}
    if len(result.times) > 1:
        summary["statistics"] = {short: metrics.statistics(result.times, result.traces, [full],
                                                           scene.experiment.transient).get(full)
                                 for short, full in names.items() if full in result.traces}
    if "energy_balance" in scene.features and result.ok:
        if (problem := kinds.driveline_problem(scene)) is None:
            summary["energy_balance"] = metrics.energy_balance(scene, result.times, result.traces)
        else:       # the balance books the driveline's works and energies: not this system's
            summary["energy_balance_unavailable"] = f"{problem}: the driveline's energy balance does not apply"
    if reference is not None and len(result.times):
        summary["error_vs_reference"] = metrics.driveline_errors(scene, result.times, result.traces,
                                                                 reference.times, reference.traces)
        summary["reference"] = {"method": reference.method, "wall_time_s": reference.wall_time,
                                "rhs_evaluations": reference.n_rhs,
                                "energy_balance": metrics.energy_balance(
                                    scene, reference.times, reference.traces,
                                    reference.traces[f"{kinds.roles(scene)[1]}.dissipated_energy"])}
    return summary


def write_report(path: Path, summary: dict):
    lines = [f"# {summary['scene']}: {summary['description']}", ""]
    lines.append(f"Master **{summary['master']}**, communication step {summary['step_s']:g} s, "
                 f"0 ... {summary['stop_s']:g} s; wall time {summary['wall_time_s']:.2f} s "
                 f"({summary['counters'].get('fmu_calls', 0)} FMI calls).")
    if summary["failure"]:
        lines += ["", f"**The run failed:** {summary['failure']}", "",
                  "The traces up to the failure are in traces.csv."]
    if summary.get("unconnected_inputs"):
        lines += ["", f"**Unconnected:** {summary['unconnected_inputs']['note']}."]
    if summary.get("stream"):
        st = summary["stream"]
        lines += ["", f"Traces streamed while running: {st['rows_written']} rows in traces.csv; the statistics and "
                  f"plots below use 1 row in {st['stride']}, the energy balance every row."]
    stats = summary.get("statistics")
    if stats:
        lines += ["", f"## Motion after the start-up transient (t >= {summary['transient_s']:g} s)", "",
                  "| signal | mean | amplitude A = (max-min)/2 | unevenness (w_max-w_min)/w_mean |",
                  "|---|---|---|---|"]
        for short, s in stats.items():
            if s:
                lines.append(f"| {short} | {fmt(s['mean'])} | {fmt(s['amplitude'])} | "
                             f"{fmt(s.get('unevenness'))} |")
        lines += ["", "Units: w [rad/s], a [rad/s^2], tau [N*m]; tau1 is the torque on the drive shaft "
                  "(negative: it brakes the engine), tau2 the torque on the driven shaft."]
    lines += reference_error_lines(summary, "Error against the monolithic reference",
                                   "torques relative to the mean transmitted torque, speeds to the mean speed")
    if summary.get("energy_balance_unavailable"):
        lines += ["", "## Energy balance", "", f"Not computed: {summary['energy_balance_unavailable']}."]
    eb = summary.get("energy_balance")
    if eb:
        lines += ["", "## Energy balance", "",
                  f"work in {eb['work_in_J']:.6g} J - work out {eb['work_out_J']:.6g} J - kinetic change "
                  f"{eb['kinetic_change_J']:.4g} J - elastic change {eb['elastic_change_J']:.4g} J - dissipated "
                  f"{eb['dissipated_J']:.4g} J = residual {eb['residual_J']:.4g} J "
                  f"(**{100 * eb['residual_relative']:.2g} %** of the work in)."]
    lines += ["", "Plots: speeds.png, torques.png, accelerations.png, transfer_function.png, "
              "vs_reference.png.  Traces: traces.csv (and reference.csv)."]
    path.write_text("\n".join(lines) + "\n")


def plot(out: Path, result: RunResult, reference=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = metrics.signals(result.scene)
    t = result.times
    tr = result.traces

    def figure(filename, panels, title):
        fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.6 * len(panels)), sharex=True, squeeze=False)
        for ax, (label, series) in zip(axes[:, 0], panels):
            for name, legend, style, *sign in series:
                if name in tr:
                    ax.plot(t, (sign[0] if sign else 1.0) * tr[name], style, lw=0.8, label=legend)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(title)
        fig.tight_layout()
        fig.savefig(out / filename, dpi=110)
        plt.close(fig)

    title = f"{result.scene.name} - {result.master}, h = {result.step:g} s"
    figure("speeds.png", [("speed [rad/s]", [(names["w1"], "w1 drive", "-"), (names["w2"], "w2 driven", "-")])], title)
    # The drive side is plotted as the torque it transmits, -tau1, so both curves share a sign.
    figure("torques.png", [("torque [N*m]", [(names["tau1"], "-tau1 (drive)", "-", -1.0),
                                             (names["tau2"], "tau2 (driven)", "-")])], title)
    figure("accelerations.png", [("acceleration [rad/s^2]", [(names["a1"], "a1 drive", "-"),
                                                             (names["a2"], "a2 driven", "-")])], title)
    figure("transfer_function.png", [("U12 [1]", [(names["U12"], "U12", "-")])], title)
    if reference is not None:
        fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
        n = min(len(t), len(reference.times))
        for ax, key, unit in zip(axes, ("w1", "w2", "tau2"), ("rad/s", "rad/s", "N*m")):
            name = names[key]
            ax.plot(reference.times[:n], reference.traces[name][:n], "k-", lw=1.2, label="reference (monolithic)")
            ax.plot(t[:n], tr[name][:n], "C1--", lw=0.8, label=f"co-simulation ({result.master})")
            ax.set_ylabel(f"{key} [{unit}]")
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        for key, style in (("w1", "C0-"), ("w2", "C2-")):
            name = names[key]
            axes[3].plot(t[:n], tr[name][:n] - reference.traces[name][:n], style, lw=0.7, label=f"error {key}")
        axes[3].set_ylabel("error [rad/s]")
        axes[3].set_xlabel("time [s]")
        axes[3].grid(alpha=0.3)
        axes[3].legend(loc="upper right", fontsize=8)
        fig.suptitle(f"{title}: co-simulation vs reference")
        fig.tight_layout()
        fig.savefig(out / "vs_reference.png", dpi=110)
        plt.close(fig)


def write_driveline(out: Path, result: RunResult, reference=None) -> dict:
    return write_run(out, result, reference, summarize, write_report, plot)


#: the run files' writer of each kind of scene (harness.description.kinds)
WRITERS = {"driveline": write_driveline, "rectifier": rectifier_report.write}


def write(out: Path, result: RunResult, reference=None) -> dict:
    """A run's files in ``out`` (see ``harness.formats.run_files.write_run``), written by
    its kind of scene's writer; a scene of no known kind gets the driveline's."""
    return WRITERS.get(kinds.kind_of(result.scene), write_driveline)(out, result, reference)
