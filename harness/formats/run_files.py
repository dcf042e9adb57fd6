"""The files of a run, whatever its kind of scene: traces.csv, reference.csv,
summary.json, report.md and the plots (``write_run``), and the parts of a report every
kind shares."""
from __future__ import annotations

import json
import math
import platform
from pathlib import Path

import numpy as np

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine.run import RunResult
from harness.paths import FMUS
from harness.engine import interrupt, masters
from harness.formats import plotting
from harness.engine.traces import replaced as write_whole
from harness.engine.traces import write as write_traces     # one writer: a streamed and a plain run write the same file


#: the files any kind of run may write (the plots of every kind of scene): an earlier run's
#: that this run does not write again are removed, so a folder never mixes two runs
RUN_FILES = ("traces.csv", "reference.csv", "summary.json", "report.md", "speeds.png", "torques.png",
             "accelerations.png", "transfer_function.png", "vs_reference.png", "kinematics.png", "gaps.png",
             "energy.png", "revolution.png", "revolutions.png", "spectrum.png", "u12_over_angle.png")


def earlier_run_files(out: Path) -> list[Path]:
    """The files of an earlier run in ``out``: those its summary.json lists, and the
    names in ``RUN_FILES`` (a run from before summaries listed their files)."""
    names = set(RUN_FILES)
    try:
        names |= {Path(n).name for n in json.loads((out / "summary.json").read_text()).get("files", [])}
    except (OSError, ValueError, AttributeError):
        pass
    return [out / n for n in sorted(names) if (out / n).is_file()]


class WritingInterrupted(KeyboardInterrupt):
    """Ctrl-C while a run's files were written: ``missing`` names the files it left out
    (empty: every file was written whole).  A KeyboardInterrupt, as Ctrl-C is."""

    def __init__(self, out: Path, missing: list[str]):
        self.out, self.missing = Path(out), list(missing)
        said = (f"not written: {', '.join(self.missing)}; every file there is whole" if self.missing
                else "every file was written whole")
        super().__init__(f"interrupted while writing the run's files to {self.out}/: {said}")


#: plots ``save_figure`` left undrawn because Ctrl-C was pressed (``write_run`` resets it)
_not_drawn: list[str] = []


def save_figure(fig, path: Path, dpi: int = 110):
    """Save a run's plot whole or not at all; after Ctrl-C (taken by ``write_run``) the
    plot is not drawn but named as missing, so the run's files are written at once."""
    import matplotlib.pyplot as plt

    path = Path(path)
    interrupt.phase(f"plotting {path.name}")
    try:
        if interrupt.requested():
            _not_drawn.append(path.name)
            return
        with write_whole(path) as temporary:
            plotting.save_png(fig, temporary, dpi)
    finally:
        plt.close(fig)


def write_run(out: Path, result: RunResult, reference, summary_of, write_markdown, make_plots,
              plots: bool = True) -> dict:
    """A run's files in ``out``, with the summary, report and plots of its kind of scene
    (``summary_of(result, reference)``, ``write_markdown(path, summary)``,
    ``make_plots(out, result, reference)``): traces.csv (unless the run streamed it while
    running), reference.csv, the plots (scene feature ``plots``; none when ``plots`` is
    false), summary.json and
    report.md, which list the files written (``summary["files"]``).  An earlier run's
    files are removed first.  Returns the summary.

    Each file is written whole or not at all (``write_whole``).  Ctrl-C while writing
    (``interrupt.deferred``) lets the files under way finish, leaves the plots not drawn
    yet undrawn, marks summary.json and report.md with what is missing and then raises
    ``WritingInterrupted``; a second Ctrl-C stops at once, naming the files not written."""
    out.mkdir(parents=True, exist_ok=True)
    streamed = out / "traces.csv" if result.stream is not None else None
    for path in earlier_run_files(out):
        if path != streamed:               # a streamed run wrote its traces while it ran
            path.unlink()
    planned = (["traces.csv"] if result.stream is None else []) + (["reference.csv"] if reference is not None
                                                                     else [])
    plots = plots and "plots" in result.scene.features and len(result.times) > 1
    _not_drawn.clear()
    done: list[str] = []
    try:
        with interrupt.deferred():
            for name in planned:
                interrupt.phase(f"writing {name}")
                source = result if name == "traces.csv" else reference
                write_traces(out / name, source.times, source.traces)
                done.append(name)
            if plots:
                make_plots(out, result, reference)
                done.append("plots")
            summary = summary_of(result, reference)
            summary["files"] = [p.name for p in earlier_run_files(out) if p.name not in ("summary.json", "report.md")] \
                + ["summary.json", "report.md"]
            if interrupt.requested() and _not_drawn:
                summary["interrupted_while_writing"] = {"not_drawn": list(_not_drawn),
                                                        "note": "Ctrl-C while the files were written: the plots "
                                                                "named were not drawn; every file written is whole"}
            interrupt.phase("writing summary.json")
            with write_whole(out / "summary.json") as temporary:
                temporary.write_text(json.dumps(summary, indent=2, default=_json_default))
            done.append("summary.json")
            interrupt.phase("writing report.md")
            with write_whole(out / "report.md") as temporary:
                write_markdown(temporary, summary)
            done.append("report.md")
            interrupted = interrupt.requested()
    except KeyboardInterrupt as error:       # the second Ctrl-C: stopped where it was
        if isinstance(error, WritingInterrupted):
            raise
        steps = planned + (["plots"] if plots else []) + ["summary.json", "report.md"]
        left = [("the plots not drawn yet" if n == "plots" else n) for n in steps if n not in done]
        raise WritingInterrupted(out, left) from None
    if interrupted:
        raise WritingInterrupted(out, list(_not_drawn))
    return summary


def files_line(summary: dict) -> str:
    """The report's line naming the run's plots and traces: only files it wrote."""
    files = summary.get("files") or []
    plots = [f for f in files if f.endswith(".png")]
    traces = [f for f in files if f.endswith(".csv")]
    parts = ([f"Plots: {', '.join(plots)}."] if plots else []) + ([f"Traces: {' and '.join(traces)}."] if traces
                                                                    else [])
    missing = (summary.get("interrupted_while_writing") or {}).get("not_drawn")
    if missing:
        parts.append(f"Not drawn (Ctrl-C while the files were written): {', '.join(missing)}.")
    return "  ".join(parts) or "No traces were written."


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return str(x)


def reference_error_lines(summary: dict, title: str, scales: str) -> list[str]:
    """The report's section on the error against the monolithic reference (none without one)."""
    errs = summary.get("error_vs_reference")
    if not errs:
        return []
    ref = summary["reference"]
    if "energy_balance" in ref:
        said = (f"Reference: {ref['method']} ({ref['rhs_evaluations']} right-hand-side evaluations, "
                f"{ref['wall_time_s']:.2f} s; its own energy residual {ref['energy_balance']['residual_relative']:.1e}).")
    else:       # made from the scene's FMUs (harness.judges.fmu_reference): no equations to balance
        said = (f"Reference: {ref['source']}, made from the scene's FMUs because {ref['why_not_monolithic']}: "
                f"{ref['quality']}.")
    lines = ["", f"## {title}", "", said, "",
             "| signal | RMS error | max error | RMS / scale | max / scale | scale |", "|---|---|---|---|---|---|"]
    for signal, e in errs.items():
        lines.append(f"| {signal} | {fmt(e['rms'])} | {fmt(e['max'])} | {100 * e['rms_relative']:.3g} % | "
                     f"{100 * e['max_relative']:.3g} % | {fmt(e['scale'])} |")
    return lines + ["", f"Scales: {scales}."]


def fmt(x, digits=4):
    if x is None:
        return "-"
    if isinstance(x, float) and (abs(x) >= 1e4 or (0 < abs(x) < 1e-3)):
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def summary_head(result: RunResult) -> dict:
    """What every kind of scene's summary.json starts with: the scene, the master and step,
    the times, how the run ended and what it cost, what it ran (``run_identity``), and where
    they apply, how its traces were streamed and which inputs were left unconnected or
    connected without a unit check."""
    scene = result.scene
    head = {
        "scene": scene.name, "description": description_of(scene), "master": result.master, "step_s": result.step,
        "stop_s": scene.experiment.stop, "transient_s": scene.experiment.transient,
        "transient_note": getattr(scene.experiment, "transient_note", None), "ok": result.ok,
        "failure": result.failure, "diagnosis": getattr(result, "diagnosis", None), "wall_time_s": result.wall_time,
        "counters": result.counters, "python": platform.python_version(),
    }
    head.update(run_identity(result))
    if result.stream:
        head["stream"] = result.stream
    if result.unconnected_inputs:
        head["unconnected_inputs"] = {"inputs": list(result.unconnected_inputs),
                                      "note": scenes.unconnected_message(result.unconnected_inputs)}
    if result.unchecked_connections:
        head["unchecked_connections"] = {"connections": list(result.unchecked_connections),
                                         "note": scenes.unchecked_message(result.unchecked_connections)}
    return head


def streamed_lines(summary: dict, uses: str) -> list[str]:
    """report.md's lines on traces streamed while running (none for a run that was not):
    ``uses`` says what the report computed from the rows it kept (``{stride}``: 1 in so many)."""
    if not summary.get("stream"):
        return []
    st = summary["stream"]
    return ["", f"Traces streamed while running: {st['rows_written']} rows in traces.csv; "
            f"{uses.format(stride=st['stride'])}."]


def run_identity(result: RunResult) -> dict:
    """What a run ran, for its summary.json, report and plots: every parameter with where its
    value came from, the ``--set`` overrides, the master and its options in effect (the
    tolerance of one that has one), the FMI edition and the project's version."""
    scene = result.scene
    record = plans.parameter_record(scene, scene.fmu_dir or FMUS)
    return {"parameters": record, "overrides": plans.overridden(record),
            "master_options": {k: v for k, v in (getattr(result, "options", None) or {}).items()},
            "tolerance": (getattr(result, "options", None) or {}).get("tolerance"),
            "fmi_edition": scene.experiment.fmi, "lever_version": _project_version()}


def _project_version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("lever-cosim")
    except PackageNotFoundError:
        return "unknown (not installed)"


def run_title(summary: dict) -> str:
    """A plot's title: scene, master, step (an adaptive master's first step) and the
    tolerance of a master that has one, and, on a second line, the values the run changed
    (``--set``), so that no plot of a changed run reads as the scene file's."""
    changed = "; ".join(f"{k} = {v}" for k, v in (summary.get("overrides") or {}).items())
    adaptive = summary["master"] in masters.MASTERS and masters.MASTERS[summary["master"]].adaptive
    tolerance = summary.get("tolerance")
    return (f"{summary['scene']} - {summary['master']}, {'first ' if adaptive else ''}h = {summary['step_s']:g} s"
            + (f", tolerance {tolerance:g}" if tolerance is not None else "")
            + (f"\n--set {changed}" if changed else ""))


def title_of(result: RunResult) -> str:
    """``run_title`` of a run's result."""
    return run_title({"scene": result.scene.name, "master": result.master, "step_s": result.step,
                      "overrides": result.scene.overrides,
                      "tolerance": (getattr(result, "options", None) or {}).get("tolerance")})


def identity_lines(summary: dict) -> list[str]:
    """The report's account of what the run ran: the overrides first, then every parameter
    with its source (scene file, --set, the FMU's default)."""
    options = ", ".join(f"{k} {v}" for k, v in (summary.get("master_options") or {}).items())
    lines = ["", "## What this run ran", "",
             f"lever {summary.get('lever_version')}, FMI {summary.get('fmi_edition')}.0 FMUs, master "
             f"{summary['master']} ({options or 'no options'}), step {summary['step_s']:g} s.", ""]
    overrides = summary.get("overrides") or {}
    lines.append("Changed with --set: " + (", ".join(f"**{k} = {v}**" for k, v in overrides.items())
                                           if overrides else "nothing (the scene file's values)") + ".")
    lines += ["", "| parameter | value | from |", "|---|---|---|"]
    for name, entry in (summary.get("parameters") or {}).items():
        lines.append(f"| {name} | {entry['value'] or '(empty)'} | {entry['source']} |")
    return lines


def report_heading(summary: dict) -> list[str]:
    """A report's title: the scene and its file's description, or, when the run changed a
    parameter with ``--set``, the scene and the changed values (the description quotes the
    scene file's own values, which this run did not use)."""
    overrides = summary.get("overrides") or {}
    changed = [k for k in overrides if not k.startswith("experiment.")]
    if not changed:
        return [f"# {summary['scene']}: {summary['description']}", ""]
    return [f"# {summary['scene']} with " + ", ".join(f"{k} = {overrides[k]}" for k in changed), "",
            "(The scene file's description is of its own values, not this run's: see "
            "[What this run ran](#what-this-run-ran).)", ""]


def description_of(scene) -> str:
    """The scene's description for a run's summary: the scene file's, unless the run changed a
    component's parameter with ``--set`` - the description quotes the scene's own values."""
    changed = [k for k in scene.overrides if k.split(".", 1)[0] in scene.components]
    if not changed:
        return scene.description
    return (f"{scene.name} with " + ", ".join(f"{k} = {scene.overrides[k]}" for k in changed)
            + " (the scene file's description is of its own values, not shown)")
