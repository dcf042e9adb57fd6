"""The files of a run, whatever its kind of scene: traces.csv, reference.csv,
summary.json, report.md and the plots (``write_run``), and the parts of a report every
kind shares."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.engine.run import RunResult
from harness.engine.traces import write as write_traces     # one writer: a streamed and a plain run write the same file


def write_run(out: Path, result: RunResult, reference, summary_of, write_markdown, make_plots) -> dict:
    """A run's files in ``out``, with the summary, report and plots of its kind of scene
    (``summary_of(result, reference)``, ``write_markdown(path, summary)``,
    ``make_plots(out, result, reference)``): traces.csv (unless the run streamed it while
    running), reference.csv, summary.json, report.md, the plots (scene feature ``plots``).
    Returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    if result.stream is None:             # a streamed run wrote its traces while it ran
        write_traces(out / "traces.csv", result.times, result.traces)
    if reference is not None:
        write_traces(out / "reference.csv", reference.times, reference.traces)
    summary = summary_of(result, reference)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_json_default))
    write_markdown(out / "report.md", summary)
    if "plots" in result.scene.features and len(result.times) > 1:
        make_plots(out, result, reference)
    return summary


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
    lines = ["", f"## {title}", "",
             f"Reference: {ref['method']} ({ref['rhs_evaluations']} right-hand-side evaluations, "
             f"{ref['wall_time_s']:.2f} s; its own energy residual "
             f"{ref['energy_balance']['residual_relative']:.1e}).", "",
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
