"""Traces a user hands ``lever validate``: a CSV (a time column and named columns) or a
lever results folder (its traces.csv as a result, its reference.csv - the reference made for
that run's parameters - as a reference), and what a result was made with against what its
reference was made with."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from harness.description import scene as scenes
from harness.description import units
from harness.description.arguments import Argument
from harness.formats.reference_traces import ReferenceTraces, TraceFileError, Traces, read_csv


@dataclass
class Given:
    """Traces read from what the user named: the traces, the file they came from, the lever
    run's summary.json beside it (None: not a lever run's)."""
    traces: Traces
    path: Path
    summary: dict | None = None


def _summary(folder: Path) -> dict | None:
    try:
        return json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return None


def read_given(path, role: str, argument: Argument | None = None) -> Given:
    """``path`` as a ``role`` ("result" or "reference"): a CSV, or a lever results folder
    (its traces.csv for a result, its reference.csv for a reference); TraceFileError with a
    sentence naming ``argument`` (default the option ``--<role>``) otherwise."""
    argument = argument or Argument(f"--{role}")
    path = Path(path)
    if path.is_dir():
        name = "traces.csv" if role == "result" else "reference.csv"
        file = path / name
        if not file.is_file():
            raise TraceFileError(f"{argument.typed(str(path))}: a folder without {name} (a lever run's results folder holds "
                                 f"traces.csv and, when the run had a reference, reference.csv)")
        return Given(read_csv(file), file, _summary(path))
    if not path.is_file():
        raise TraceFileError(f"{argument.typed(str(path))}: no such file or folder")
    return Given(read_csv(path), path, _summary(path.parent))


def sorted_reference(given: Given, argument: Argument = Argument("--reference")) -> Traces:
    """A reference's traces checked for judging: times sorted (a time repeated at an event is
    kept, its later row counts) and at least 2 samples; TraceFileError naming ``argument``
    otherwise."""
    from harness.judges import sampled

    t, signals, _ = sampled.repeated_rows_dropped(given.traces.times, given.traces.signals)
    if len(t) < 2:
        raise TraceFileError(f"{argument.typed(str(given.path))}: {len(t)} row(s); a reference needs at least two")
    problem = sampled.times_problem(t, "its")
    if problem:
        raise TraceFileError(f"{argument.typed(str(given.path))}: {problem}")
    return Traces(t, signals)


def provenance_notes(reference: ReferenceTraces, result, overrides, master: str | None, step: float | None) -> list[str]:
    """Sentences saying when the judged result was made with other values than its
    reference (a scene's reference is made at the scene file's values, by the monolithic
    solver): a run ``lever validate`` made with ``--set``, or a ``--result`` CSV with a
    lever run's summary.json beside it (what it ran), or a ``Run``'s summary (a dict); a CSV
    without one is said to be of unknown making.  Values are compared as quantities
    (``units.same_value``: "15.0 deg" is "15 deg"), not as text."""
    import json

    from harness.description import plan

    if reference.kind != "scene":
        changed = {k: v for k, v in (a.split("=", 1) for a in overrides or () if "=" in a)}
        return ([f"the run under test was made with other values than its reference (the FMU's defaults and the "
                 f"reference's inputs): {', '.join(f'{k} = {v.strip()}' for k, v in changed.items())} (--set)"]
                if changed else [])
    made = plan.parameter_record(scenes.load(reference.name))
    if isinstance(result, (str, Path)):
        summary_path = Path(result).parent / "summary.json"
        try:
            summary = json.loads(summary_path.read_text())
            used = summary["parameters"]
        except (OSError, ValueError, KeyError, TypeError):
            return [f"what the result was made with is not known (no summary.json of a lever run with its parameters "
                    f"beside {Path(result).name}): it is judged as traces only"]
        said = f"{summary_path} (master {summary.get('master')}, step {summary.get('step_s')} s, lever " \
               f"{summary.get('lever_version')})"
    elif isinstance(result, dict) and isinstance(result.get("parameters"), dict):     # a Run's summary
        used = result["parameters"]
        said = f"the Run given (master {result.get('master')}, step {result.get('step_s')} s)"
    elif result is None and overrides:
        used = plan.parameter_record(scenes.load(reference.name).with_overrides(list(overrides)))
        said = "this run (--set)"
    else:
        return []
    differ = [f"{k} = {v['value']} ({v['source']}; the reference: {made[k]['value'] if k in made else 'not set'})"
              for k, v in used.items() if not k.startswith("experiment.")
              and (k not in made or not units.same_value(v["value"], made[k]["value"]))]
    if not differ:
        return [f"the result was made with its reference's parameter values ({said})"]
    return [f"the result was made with other values than its reference ({said}): " + "; ".join(differ)]
