"""The harness from Python: run a scene, validate a result, bench the masters.

What ``lever run``, ``lever validate`` and ``lever bench`` do, as functions that return
their results instead of printing them (the command line calls these)::

    from harness import api

    run = api.run("kavz685", {"coupling.stiffness": 900}, stop=3.0)
    run.array()                  # numpy structured array: 'time' and every recorded signal
    run.summary["statistics"]    # means and amplitudes after the start-up transient
    api.validate("EngineShaft").passed

Bad input (an unknown scene, parameter or master, a value out of its range) raises
``InputError`` with the message the command line prints; nothing is written unless an
output folder is given (``out=``).  Notes the command line prints before a run (the
stability advisor, a shortened run's transient, unconnected inputs) go to ``notify``
(default: Python's ``warnings``) and are kept in ``Run.notes``.
"""
from __future__ import annotations

import importlib.util
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from harness.description import scene as scenes
from harness.paths import BUILD, FMUS

__all__ = ["InputError", "BuildError", "RunNote", "Run", "Validation", "build", "load", "run", "validate", "bench", "scenes_list"]


class InputError(ValueError):
    """Bad input: the message names the parameter and what is allowed (``lever``: exit 2)."""


class BuildError(RuntimeError):
    """The FMUs could not be built (no C compiler, a failed compliance check, ...)."""


class RunNote(UserWarning):
    """A note about a run the command line prints before it (``Run.notes`` keeps them)."""


def _warn(kind: str, message: str):
    warnings.warn(f"{kind}: {message}", RunNote, stacklevel=3)


def _build_module():
    spec = importlib.util.spec_from_file_location("_lever_build_fmus", BUILD / "fmus.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build(force: bool = False, fmu_dir: Path | None = None, log: Callable[[str], None] | None = None) -> Path:
    """Build the FMUs into ``fmu_dir`` (default ``harness.paths.FMUS``) when they are
    missing or older than their sources; return the folder.  BuildError when the build
    fails (no C compiler, ...)."""
    fmu_dir = Path(fmu_dir or FMUS)
    module = _build_module()
    if force or not module.is_current(fmu_dir):
        try:
            module.build(fmu_dir, force=force, log=log or (lambda *_: None))
        except RuntimeError as error:
            raise BuildError(str(error)) from None
    return fmu_dir


def scenes_list() -> dict[str, str]:
    """The committed scenes: name -> description (an unreadable one: its error)."""
    from harness.paths import SCENES

    out = {}
    for path in sorted(SCENES.glob("*.toml")):
        try:
            out[path.stem] = scenes.load(path).description
        except scenes.SceneError as error:
            out[path.stem] = f"(invalid: {error})"
    return out


def _assignments(overrides) -> list[str]:
    """``{"coupling.stiffness": 900}`` or ``["coupling.stiffness=900"]`` as ``--set`` strings."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return [f"{k}={v}" for k, v in overrides.items()]
    if isinstance(overrides, str):
        return [overrides]
    return [str(a) for a in overrides]


def load(scene: str | Path | scenes.Scene = "kavz685", overrides=None, *, stop: float | None = None,
         strict: bool = False) -> scenes.Scene:
    """The scene (a name in resources/scenes, a .toml file, an SSP archive .ssp, or a Scene)
    with ``overrides`` (a dict ``{"component.parameter": value}`` or ``--set`` strings) and
    ``stop``; InputError on bad input."""
    assignments = _assignments(overrides)
    if stop is not None:
        if not (isinstance(stop, (int, float)) and math.isfinite(stop)):
            raise InputError(f"--stop {stop}: expected a time in seconds")
        assignments.append(f"experiment.stop={float(stop)!r}")
    if strict:
        assignments.append("experiment.strict=true")
    try:
        if isinstance(scene, scenes.Scene):
            spec = scene
        elif str(scene).endswith(".ssp"):
            from harness.formats import ssp
            spec = ssp.read_scene(scene)
        else:
            spec = scenes.load(scene)
        return spec.with_overrides(assignments)
    except scenes.SceneError as error:
        raise InputError(str(error)) from None


def check_masters(*names: str):
    """InputError when one of ``names`` is not a master."""
    from harness.engine import masters

    try:
        masters.check(*names)
    except masters.UnknownMaster as error:
        raise InputError(str(error)) from None


@dataclass
class Run:
    """One run: the result (times, traces, failure), the reference and the summary (what
    summary.json holds), and where the files went (``out``; None: none written)."""
    result: object
    reference: object | None
    summary: dict
    out: Path | None = None
    #: the warnings and notes said about this run (also sent to ``notify``)
    notes: list[str] = field(default_factory=list)

    @property
    def scene(self) -> scenes.Scene:
        return self.result.scene

    @property
    def times(self) -> np.ndarray:
        return self.result.times

    @property
    def traces(self) -> dict[str, np.ndarray]:
        return self.result.traces

    @property
    def ok(self) -> bool:
        return self.result.ok

    @property
    def failure(self) -> str | None:
        return self.result.failure

    def array(self, names: Iterable[str] | None = None) -> np.ndarray:
        """The traces as one numpy structured array, ``time`` first (as fmpy's
        ``simulate_fmu`` returns): ``a["time"]``, ``a["coupling.tau2"]``."""
        names = list(self.traces) if names is None else list(names)
        return np.rec.fromarrays([np.asarray(self.times, float)] + [np.asarray(self.traces[n], float) for n in names],
                                 names=["time"] + names)


def _step_problem(step, label="--step"):
    if step is not None and (problem := scenes.step_problem(step, label)):
        raise InputError(problem)


def run(scene: str | Path | scenes.Scene = "kavz685", overrides=None, *, master: str | None = None,
        step: float | None = None, stop: float | None = None, tolerance: float | None = None,
        strict: bool = False, reference: bool = True, out: Path | str | None = None, progress: bool = False,
        stream: bool = False, notify: Callable[[str, str], None] | None = None, claimed: bool = False,
        observer=None) -> Run:
    """Run a scene as ``lever run`` does and return it (``Run``).

    ``overrides``: ``{"coupling.misalignment": "20 deg"}`` or ``["coupling.stiffness=900"]``;
    ``stop``: a shorter (or longer) run; ``reference``: solve the monolithic reference
    (its error is in the summary); ``out``: write the run's files there (report.md,
    summary.json, traces.csv, plots); ``stream``: write traces.csv while running (needs
    ``out``).  ``notify(kind, message)`` hears the warnings and notes ("warning", "note");
    ``observer`` is told of every step (``harness.engine.observers``, e.g. the step timer).
    A failed or interrupted run is returned (``Run.ok`` false, ``Run.failure`` says why);
    bad input raises InputError before anything runs."""
    from harness.engine import masters
    from harness.engine.run import available_memory, simulate, trace_memory
    from harness.engine.system import SceneInvalid, descriptions_for
    from harness.formats import outputs, report
    from harness.judges import monolithic
    from harness.judges.stability import run_advice

    notes: list[str] = []

    def say(kind: str, message: str):
        notes.append(f"{kind}: {message}")
        (notify or _warn)(kind, message)

    spec = load(scene, overrides, stop=stop, strict=strict)
    chosen = master or spec.experiment.master
    check_masters(chosen)
    _step_problem(step)
    options = {}
    if tolerance is not None:
        if "tolerance" not in masters.MASTERS[chosen].options:
            raise InputError(f"--tolerance: master '{chosen}' takes no tolerance (masters that do: "
                             + ", ".join(n for n, m in masters.MASTERS.items() if "tolerance" in m.options) + ")")
        if not (math.isfinite(tolerance) and 0 < tolerance < 1):
            raise InputError(f"--tolerance {tolerance}: must lie in (0, 1)")
        options["tolerance"] = tolerance
    if stream and out is None:
        raise InputError("stream: name the output folder (out=...) the traces are streamed to")
    build()
    fmu_dir = spec.fmu_dir or FMUS
    # the scene's names and values first: the stability advisor reads a sound scene only
    findings = scenes.validate(spec, descriptions_for(spec, fmu_dir))
    if findings:
        raise InputError(str(SceneInvalid(spec.name, findings)))
    if spec.experiment.transient_note:
        say("note", spec.experiment.transient_note)
    advice = run_advice(spec, chosen, step or spec.experiment.step, fmu_dir)
    for warning in advice:
        say("warning", warning)         # before the run, so a long run is not waited for
    if not stream and not scenes.experiment_findings(spec.experiment):
        needed, rows = trace_memory(spec, step)
        free = available_memory()
        if free is not None and needed > 0.8 * free:
            e = spec.experiment
            raise InputError(f"a step of {step or e.step:g} s over {e.stop - e.start:g} s makes {rows:,} rows of "
                             f"traces, about {needed / 2**30:.1f} GiB in memory, more than this machine has free "
                             f"({free / 2**30:.1f} GiB): use --stream (writes traces.csv while running, keeps 1 row "
                             "in k in memory), a larger --step or a shorter experiment.stop")
    if out is not None and not claimed:
        try:
            out = outputs.claim(Path(out))       # before the run: a bad or busy folder is said at once
        except outputs.OutputError as error:
            raise InputError(str(error)) from None
    try:
        result = simulate(spec, master, step, fmu_dir=fmu_dir, progress=progress, options=options,
                          stream=Path(out) / "traces.csv" if stream else None, keep_partial=True,
                          observer=observer)
    except SceneInvalid as error:
        if out is not None:
            outputs.abandon(Path(out))           # refused before the run: no empty folder left
        raise InputError(str(error)) from None
    result.warnings = advice
    if result.unconnected_inputs:
        say("warning", scenes.unconnected_message(result.unconnected_inputs))
    solution = None
    try:
        if "reference" in spec.features and reference and not stream and result.ok:
            try:
                solution = monolithic.solve(spec, result.times)
            except monolithic.ReferenceUnavailable as error:
                say("note", f"no reference for this scene: {error}")
    except KeyboardInterrupt:
        say("note", "interrupted while solving the reference: the run's results are written without it")
        result.failure_stage, result.failure = "interrupted", f"interrupted after the run, at t = {result.times[-1]:.6g} s"
        result.diagnosis = {"kind": "interrupted", "time": float(result.times[-1]), "message": result.failure}
    if out is not None:
        summary = report.write(Path(out), result, solution)
    else:
        summary = report.summarize(result, solution)
    return Run(result, solution, summary, Path(out) if out is not None else None, notes)


@dataclass
class Validation:
    """The verdict on one NAME (``lever validate NAME``): per signal (``findings.signals``),
    the problems that fail it, the span judged, and the result that was judged."""
    name: str
    findings: object
    bands: dict
    result: object
    reference: object
    out: Path | None = None

    @property
    def passed(self) -> bool:
        return self.findings.passed


def fmu_start_values(model: str, assignments, fmu_dir: Path | None = None) -> dict:
    """``name=value`` settings for an FMU run stand-alone: its parameters (and inputs not in
    the ``_in.csv``), checked against the model description; InputError otherwise."""
    from fmpy import read_model_description

    from harness.engine.system import converted

    variables = {v.name: v for v in read_model_description(str(Path(fmu_dir or FMUS) / f"{model}.fmu")).modelVariables}
    values = {}
    for assignment in _assignments(assignments):
        if "=" not in assignment:
            raise InputError(f"--set {assignment!r}: expected name=value")
        key, raw = (x.strip() for x in assignment.split("=", 1))
        name = key.split(".", 1)[1] if key.startswith(model + ".") else key
        var = variables.get(name)
        if var is None or var.causality not in ("parameter", "input"):
            known = [v.name for v in variables.values() if v.causality == "parameter"]
            raise InputError(f"--set {key}: {model} has no parameter '{name}'{scenes.did_you_mean(name, known)} "
                             f"(parameters: {', '.join(known)})")
        value = scenes.coerce(raw)
        problems = scenes.value_findings(f"{model}.{name}", var, value)     # type, unit's dimension, range
        if problems:
            raise InputError("; ".join(problems))
        values[name] = converted(var, value, key)
    return values


def parse_window(text: str | None) -> tuple[float | None, float | None] | None:
    """``--window START:STOP`` (either side may be left empty: the reference's own end)."""
    if text is None:
        return None
    parts = str(text).split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        low, high = (float(p) if p.strip() else None for p in parts)
    except ValueError:
        raise InputError(f"--window {text}: expected START:STOP in seconds, e.g. 2:10 or 0:1 (an empty side: "
                         "the reference's own start or stop)") from None
    for v in (low, high):
        if v is not None and not math.isfinite(v):
            raise InputError(f"--window {text}: the times must be finite")
    if low is not None and high is not None and not high > low:
        raise InputError(f"--window {text}: STOP must be > START")
    return low, high


def validate(name: str, *, overrides=None, master: str | None = None, step: float | None = None,
             result: Path | str | tuple | None = None, tolerance: str = "lever",
             window: tuple[float | None, float | None] | str | None = None, out: Path | str | None = None) -> Validation:
    """Judge NAME against its committed reference traces, as ``lever validate NAME``: run
    the FMU stand-alone or the scene (with ``overrides``, ``master``, ``step``), or judge
    ``result`` instead - a CSV another tool wrote, or ``(times, {signal: values})``.
    ``window``: judge only ``(start, stop)`` [s] of the reference's span (e.g. a shorter
    run); ``out``: write validation.json, the result and a plot per failing signal there."""
    from harness.engine.system import SceneInvalid
    from harness.formats import reference_traces
    from harness.judges import validation

    known = reference_traces.all_names()
    if name not in known:
        raise InputError(f"no reference '{name}'{scenes.did_you_mean(name, known)} (known: {', '.join(known)})")
    if tolerance not in validation.TOLERANCES:
        raise InputError(f"tolerance {tolerance!r}: one of {', '.join(validation.TOLERANCES)}")
    _step_problem(step)
    if isinstance(window, str):
        window = parse_window(window)
    try:
        ref = reference_traces.read(name)
    except reference_traces.TraceFileError as error:
        raise InputError(str(error)) from None
    if isinstance(result, (str, Path)):
        try:
            other = reference_traces.read_csv(Path(result))
        except reference_traces.TraceFileError as error:
            raise InputError(str(error)) from None
        judged = reference_traces.Result(other.times, other.signals, f"from {result}")
    elif result is not None:
        times, traces = result
        judged = reference_traces.Result(np.asarray(times, float), {k: np.asarray(v, float) for k, v in traces.items()},
                                   "given")
    else:
        build()
        if ref.kind == "fmu":
            if master or step:
                raise InputError(f"--master/--step: {name} is an FMU run stand-alone at its _ref.opt step")
            judged = reference_traces.run_fmu(name, ref, fmu_start_values(name, overrides))
        else:
            spec = load(name, overrides)
            if master:
                check_masters(master)
            try:
                judged = reference_traces.run_scene(spec, master, step)
            except SceneInvalid as error:
                raise InputError(str(error)) from None
    start, stop = ref.opt.start, ref.opt.stop
    if window is not None:
        low, high = window
        start = start if low is None else low
        stop = stop if high is None else high
        if not (ref.opt.start <= start < stop <= ref.opt.stop):
            raise InputError(f"--window {window[0] if window[0] is not None else ''}:"
                             f"{window[1] if window[1] is not None else ''}: must lie in the reference's span, "
                             f"{ref.opt.start:g} ... {ref.opt.stop:g} s, with START < STOP")
    findings, bands = validation.compare_span(name, judged.times, judged.traces, ref.outputs.times, ref.outputs.signals,
                                         validation.TOLERANCES[tolerance], start, stop, (ref.opt.start, ref.opt.stop))
    if judged.failure:
        findings.problems.append(f"the run failed: {judged.failure}")
    if out is not None:
        reference_traces.write_validation(Path(out), findings, bands, judged, ref, write_result=result is None)
    return Validation(name, findings, bands, judged, ref, Path(out) if out is not None else None)


def bench(scene: str | Path | scenes.Scene = "kavz685", *, repeats: int = 3, only: Iterable[str] = (),
          peers: bool = True, monolithic: bool = True, out: Path | str | None = None, resume: bool = True,
          progress: Callable[[str], None] | None = None, claimed: bool = False) -> dict:
    """The work-precision benchmark of ``lever bench``: every master (``only``: these), the
    peers and the monolithic solutions over a range of steps; returns the result (its
    ``claims``: time at the target error, best master, ...) and writes bench.csv, bench.md,
    bench.json and work_precision.png to ``out`` (default results/bench/<scene>), resuming
    from its cases.jsonl unless ``resume`` is false."""
    from harness.formats import outputs
    from harness.studies import bench as benchmark

    spec = load(scene)
    try:
        benchmark.plan(spec, list(only))      # refuses unknown masters before anything runs
    except ValueError as error:
        raise InputError(str(error)) from None
    build()
    out = Path(out) if out is not None else benchmark.default_out(spec)
    if not claimed:
        try:
            out = outputs.claim(out)
        except outputs.OutputError as error:
            raise InputError(str(error)) from None
    result = benchmark.bench(spec, repeats, only=list(only), peers=peers, monolithic=monolithic,
                             progress=progress or (lambda *_: None), out=out, resume=resume)
    result["written"] = benchmark.write(out, result)
    return result
