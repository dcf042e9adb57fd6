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

import contextlib
import importlib.util
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping

import numpy as np

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.paths import BUILD, FMUS

__all__ = ["InputError", "BuildError", "StudyInterrupted", "RunNote", "Run", "Validation", "ReferenceCheck", "build",
           "load", "run", "validate", "validate_each", "bench", "scenes_list", "stability_map", "sweep", "study",
           "measured", "engines", "hosts", "export", "compliance", "references", "fingerprints", "bad_inputs"]


class InputError(ValueError):
    """Bad input: the message names the parameter and what is allowed (``lever``: exit 2)."""


class BuildError(RuntimeError):
    """The FMUs could not be built (no C compiler, a failed compliance check, ...)."""


class StudyInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a study that resumes from its case log; the message says what was
    kept (``lever``: exit status 130)."""


@contextlib.contextmanager
def _resumable(out: Path):
    try:
        yield
    except KeyboardInterrupt:
        raise StudyInterrupted(f"interrupted: the finished cases are kept in {Path(out) / 'cases.jsonl'} (the ones "
                               "under way are logged as interrupted); run the same command again to resume") from None


#: what to do without a C compiler (the FMUs' native entry is compiled when they are built)
NO_COMPILER = ("the FMUs' native entry is C, compiled when they are built: install a C compiler "
               "(Debian/Ubuntu: sudo apt install gcc; Fedora: sudo dnf install gcc; macOS: xcode-select --install) "
               "or name one with CC (e.g. CC=clang lever build)")


def _with_compiler_hint(error: Exception) -> str:
    """The build's message, with what to do when no C compiler could be run."""
    return f"{error}; {NO_COMPILER}" if "cannot run" in str(error) and NO_COMPILER not in str(error) else str(error)


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
    fails (no C compiler: the message says what to install)."""
    fmu_dir = Path(fmu_dir or FMUS)
    module = _build_module()
    if force or not module.is_current(fmu_dir):
        try:
            module.build(fmu_dir, force=force, log=log or (lambda *_: None))
        except RuntimeError as error:
            raise BuildError(_with_compiler_hint(error)) from None
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
    #: the step latency's summary (``latency=True``; the tables are in ``out``)
    latency: list[str] | None = None

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

    @property
    def outcome(self) -> str:
        """How the run ended: "ok"; "interrupted" (Ctrl-C: what was computed is kept, marked
        so); "refused" (the FMUs refused the scene's values before the first step: the input
        is at fault, not the run); "failed" (part-way: the traces before the failure are kept)."""
        if self.result.interrupted:
            return "interrupted"
        if self.result.ok:
            return "ok"
        return "refused" if self.result.failure_stage == "initialisation" else "failed"

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
        observer=None, latency: bool = False, plots: bool = True) -> Run:
    """Run a scene as ``lever run`` does and return it (``Run``).

    ``overrides``: ``{"coupling.misalignment": "20 deg"}`` or ``["coupling.stiffness=900"]``;
    ``stop``: a shorter (or longer) run; ``reference``: solve the monolithic reference
    (its error is in the summary); ``out``: write the run's files there (report.md,
    summary.json, traces.csv, plots); ``stream``: write traces.csv while running (needs
    ``out``).  ``notify(kind, message)`` hears the warnings and notes ("warning", "note");
    ``observer`` is told of every step (``harness.engine.observers``); ``latency``: time every
    step and write latency.md and latency.json to ``out`` (``Run.latency`` summarises them);
    ``plots``: false writes the traces, summary and report without drawing the plots.
    A failed or interrupted run is returned (``Run.ok`` false, ``Run.failure`` says why);
    bad input raises InputError before anything runs."""
    from harness.engine import masters
    from harness.engine.component import FmuUnusable
    from harness.engine.me_component import NoModelExchange
    from harness.engine.run import available_memory, simulate, trace_memory
    from harness.engine.system import SceneInvalid
    from harness.formats import outputs, report
    from harness.judges import monolithic
    from harness.judges.stability import run_advice, run_method

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
    if latency and out is None:
        raise InputError("latency: name the output folder (out=...) the latency tables are written to")
    if latency:
        from harness.studies import latency as step_latency
        if observer is not None:
            raise InputError("latency: it times the steps with its own observer; give no other observer")
        observer = timer = step_latency.StepTimer()
    build()
    fmu_dir = spec.fmu_dir or FMUS
    # the scene's names and values first: the stability advisor reads a sound scene only
    plan = plans.check(spec, fmu_dir=fmu_dir)
    if plan.refusals:
        raise InputError(str(SceneInvalid(spec.name, list(plan.refusals))))
    if spec.experiment.transient_note:
        say("note", spec.experiment.transient_note)
    advice = run_advice(spec, chosen, step or spec.experiment.step, fmu_dir)
    for warning in advice:
        say("warning", warning)         # before the run, so a long run is not waited for
    if (method_note := run_method(spec, chosen, options)) is not None:
        say("note", method_note)
    if not stream:      # (the experiment's times are sound: no refusal)
        needed, rows = trace_memory(plan, step)
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
        result = simulate(plan, master, step, progress=progress, options=options,
                          stream=Path(out) / "traces.csv" if stream else None, keep_partial=True,
                          observer=observer)
    except (SceneInvalid, NoModelExchange, FmuUnusable) as error:
        # FmuUnusable: an FMU file without its binary here, or of another build
        if out is not None:
            outputs.abandon(Path(out))           # refused before the run: no empty folder left
        raise InputError(f"{error}: run it with a co-simulation master (e.g. jacobi-quadratic)"
                         if isinstance(error, NoModelExchange) else str(error)) from None
    result.warnings = advice
    if result.unconnected_inputs:
        say("warning", scenes.unconnected_message(result.unconnected_inputs))
    solution = None
    try:
        if "reference" in spec.features and reference and not stream and result.ok:
            try:
                solution = monolithic.solve(plan, result.times)
            except monolithic.ReferenceUnavailable as error:
                say("note", f"no reference for this scene: {error}")
    except KeyboardInterrupt:
        say("note", "interrupted while solving the reference: the run's results are written without it")
        result.failure_stage, result.failure = "interrupted", f"interrupted after the run, at t = {result.times[-1]:.6g} s"
        result.diagnosis = {"kind": "interrupted", "time": float(result.times[-1]), "message": result.failure}
    if out is not None:
        summary = report.write(Path(out), result, solution, plots=plots)
    else:
        summary = report.summarize(result, solution)
    done = Run(result, solution, summary, Path(out) if out is not None else None, notes)
    if latency:
        done.latency = step_latency.report(Path(out), timer, result)
    return done


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


def fmu_start_values(model: str, assignments, fmu_path: Path | None = None) -> dict:
    """``name=value`` settings for an FMU run stand-alone: its parameters (and inputs not in
    the ``_in.csv``), checked against the model description (of the FMU file ``fmu_path``,
    default ``model``'s in build/fmus); InputError otherwise."""
    from fmpy import read_model_description

    from harness.description.plan import converted

    path = fmu_path if fmu_path is not None else FMUS / f"{model}.fmu"
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
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


def _fmu_file(name) -> Path | None:
    """NAME as an FMU file (``lever validate path/Model.fmu``), or None for a name."""
    return Path(name) if scenes.is_fmu_path(name) else None


def fmu_file_model(path: Path) -> tuple[str, str]:
    """(model, FMI version) of the FMU file ``path`` to validate stand-alone: a Co-Simulation
    FMU, FMI 2.0 or 3.0, of a model with a stand-alone reference (its ``modelName``), which
    judges it; InputError otherwise."""
    from fmpy import read_model_description

    from harness.formats import reference_traces

    if not Path(path).is_file():
        raise InputError(f"{path}: no such FMU file")
    try:
        description = read_model_description(str(path))
    except Exception as error:   # fmpy raises what zipfile and its XML reader raise
        raise InputError(f"{path}: not an FMU whose model description can be read ({error})") from None
    model, version = description.modelName, description.fmiVersion
    if version != "2.0" and not version.startswith("3."):
        raise InputError(f"{path}: FMI {version}; lever runs FMI 2.0 and 3.0 FMUs")
    if description.coSimulation is None:
        raise InputError(f"{path}: FMI {version} without Co-Simulation; a stand-alone run steps the FMU")
    if model not in reference_traces.FMU_CASES:
        why = reference_traces.why_no_reference(model)
        raise InputError(f"{path}: {why}; that scene runs the built FMUs (`--set experiment.fmi=3`: their FMI 3.0 "
                         f"editions), not this file" if why else
                         f"{path}: its model '{model}' has no stand-alone reference (FMUs with one: "
                         f"{', '.join(reference_traces.FMU_CASES)})")
    return model, version


def validate(name: str, *, overrides=None, master: str | None = None, step: float | None = None,
             result: Path | str | tuple | None = None, tolerance: str = "lever",
             window: tuple[float | None, float | None] | str | None = None, out: Path | str | None = None) -> Validation:
    """Judge NAME against its committed reference traces, as ``lever validate NAME``: run
    the FMU stand-alone or the scene (with ``overrides``, ``master``, ``step``), or judge
    ``result`` instead - a CSV another tool wrote, or ``(times, {signal: values})``.  NAME
    may be an FMU file (``.fmu``, FMI 2.0 or 3.0, such as an FMI 3.0 edition in
    build/fmus3): it runs stand-alone as its model's name does, judged by that model's
    reference.  ``window``: judge only ``(start, stop)`` [s] of the reference's span (e.g. a
    shorter run); ``out``: write validation.json, the result and a plot per failing signal
    there."""
    from harness.engine.component import FmuUnusable
    from harness.engine.me_component import NoModelExchange
    from harness.engine.system import SceneInvalid
    from harness.formats import reference_traces
    from harness.judges import validation

    fmu_file = _fmu_file(name)
    label, name = (str(name), fmu_file_model(fmu_file)[0]) if fmu_file is not None else (name, name)
    known = reference_traces.all_names()
    if name not in known:
        raise InputError(reference_traces.why_no_reference(name)
                         or f"no reference '{name}'{scenes.did_you_mean(name, known)} (known: {', '.join(known)})")
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
        if fmu_file is None:
            build()
        if ref.kind == "fmu":
            if master or step:
                raise InputError(f"--master/--step: {label} is an FMU run stand-alone at its _ref.opt step")
            try:
                judged = reference_traces.run_fmu(name, ref, fmu_start_values(name, overrides, fmu_path=fmu_file),
                                                  fmu_path=fmu_file)
            except FmuUnusable as error:     # no binary here, or it refused to instantiate: bad input
                raise InputError(f"{label}: {error}") from None
        else:
            spec = load(name, overrides)
            if master:
                check_masters(master)
            try:
                judged = reference_traces.run_scene(spec, master, step)
            except (SceneInvalid, NoModelExchange) as error:
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
    findings, bands = validation.compare_span(label, judged.times, judged.traces, ref.outputs.times,
                                              ref.outputs.signals, validation.TOLERANCES[tolerance], start, stop,
                                              (ref.opt.start, ref.opt.stop))
    if judged.failure:
        findings.problems.append(f"the run failed: {judged.failure}")
    if out is not None:
        reference_traces.write_validation(Path(out), findings, bands, judged, ref, write_result=result is None)
    return Validation(label, findings, bands, judged, ref, Path(out) if out is not None else None)


def reference_names(names: Iterable[str] = ()) -> list[str]:
    """``names`` checked against the committed reference traces (none: all of them); an
    FMU file (``.fmu``) is checked as ``validate`` runs it."""
    from harness.formats import reference_traces

    known = reference_traces.all_names()
    for name in names:
        if _fmu_file(name) is not None:
            fmu_file_model(_fmu_file(name))
    unknown = [n for n in names if n not in known and _fmu_file(n) is None]
    if unknown:
        said = "; ".join(filter(None, map(reference_traces.why_no_reference, unknown)))
        raise InputError(said or f"no reference '{', '.join(unknown)}' (known: {', '.join(known)})")
    return list(names) or known


def validate_each(names: Iterable[str] = (), *, overrides=None, master: str | None = None, step: float | None = None,
                  result: Path | str | None = None, tolerance: str = "lever", window: str | None = None,
                  out: Path | str | None = None) -> Iterator[Validation]:
    """``lever validate NAMES``: ``validate`` for each name (none: every reference), in
    ``out`` (one name) or ``out/<name>`` (default results/validate/<name>); input checked
    and the FMUs built before the first."""
    from harness.paths import RESULTS

    chosen = reference_names(names)
    if result is not None and len(chosen) != 1:
        raise InputError("--result: name exactly one reference the CSV is to be compared with "
                         "(e.g. lever validate --result run.csv kavz685)")
    span = parse_window(window)
    if step is not None and (problem := scenes.step_problem(step, "--step")):
        raise InputError(problem)
    if result is None and any(_fmu_file(name) is None for name in chosen):
        build()
    for name in chosen:
        folder = name
        if _fmu_file(name) is not None:       # results/validate/<Model>-fmi<major version>
            model, version = fmu_file_model(_fmu_file(name))
            folder = f"{model}-fmi{version.split('.')[0]}"
        target = out if (out and len(chosen) == 1) else Path(out or RESULTS / "validate") / folder
        yield validate(name, overrides=_assignments(overrides), master=master, step=step, result=result,
                       tolerance=tolerance, window=span, out=target)


@dataclass
class ReferenceCheck:
    """One committed reference trace against what the project computes now."""
    name: str
    #: "current", "stale" (not current, left), "updated" (not current, rewritten) or
    #: "unavailable" (no reference can be computed: ``reason``)
    status: str
    problems: list[str] = field(default_factory=list)
    #: per signal: ``signal``, ``max_change``, ``relative``, ``at_time``
    changes: list = field(default_factory=list)
    reason: str = ""
    folder: Path | None = None


def references(names: Iterable[str] = (), update: bool = False) -> Iterator[ReferenceCheck]:
    """``lever reference``: regenerate each reference trace (``names``: FMUs or scenes; none:
    all) and compare it with the committed one; ``update``: write the stale ones."""
    from harness.formats import reference_traces
    from harness.judges.monolithic import ReferenceUnavailable

    for name in reference_names(names):
        try:
            fresh = reference_traces.generate(name)
        except (ReferenceUnavailable, scenes.SceneError) as error:
            yield ReferenceCheck(name, "unavailable", reason=str(error))
            continue
        try:
            committed = reference_traces.read(name)
        except reference_traces.TraceFileError:
            committed = None
        diff = reference_traces.difference(committed, fresh)
        if diff.current:
            yield ReferenceCheck(name, "current")
            continue
        if update:
            reference_traces.write(fresh)
        yield ReferenceCheck(name, "updated" if update else "stale", list(diff.problems), list(diff.changes),
                             folder=reference_traces.paths(name)["ref"].parent)


def bench(scene: str | Path | scenes.Scene = "kavz685", *, repeats: int = 3, only: Iterable[str] = (),
          peers: bool = True, monolithic: bool = True, out: Path | str | None = None, resume: bool = True,
          progress: Callable[[str], None] | None = None, claimed: bool = False, fmi_editions: bool = True) -> dict:
    """The work-precision benchmark of ``lever bench``: every master (``only``: these), the
    peers and the monolithic solutions over a range of steps, and (``fmi_editions``) the
    FMUs' FMI 2.0 and FMI 3.0 editions side by side; returns the result (its ``claims``:
    time at the target error, best master, ...; ``fmi_editions``) and writes bench.csv,
    bench.md, bench.json and work_precision.png to ``out`` (default results/bench/<scene>),
    resuming from its cases.jsonl unless ``resume`` is false."""
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
    with _resumable(out):
        result = benchmark.bench(spec, repeats, only=list(only), peers=peers, monolithic=monolithic,
                                 progress=progress or (lambda *_: None), out=out, resume=resume,
                                 fmi_editions=fmi_editions)
        result["written"] = benchmark.write(out, result)
    result["summary"] = benchmark.summary_lines(result)
    return result


def _claim(out: Path) -> Path:
    """``out`` made, proven writable and locked for this process (InputError when it cannot
    be, or another lever is writing there)."""
    from harness.formats import outputs

    try:
        return outputs.claim(Path(out))
    except outputs.OutputError as error:
        raise InputError(str(error)) from None


def stability_map(scene: str | Path | scenes.Scene = "kavz685", *, stiffnesses: Iterable[float] = (),
                  dampings: Iterable[float] = (), h_omegas: Iterable[float] = (), masters: Iterable[str] = (),
                  dense: bool = False, min_steps: int = 500, refine: bool = True, jobs: int = 1,
                  resume: bool = True, out: Path | str | None = None,
                  progress: Callable[[str], None] | None = None) -> dict:
    """``lever stability``: every case of the map classified against the edges the linear
    analysis predicts (empty sequences: the default plan's, ``dense``: denser); writes
    stability.md, stability.csv, stability_map.png and cases.jsonl to ``out`` (default
    results/stability/<scene>), resuming from the case log unless ``resume`` is false.
    Returns ``result``, ``agreement`` and ``written``."""
    from harness.description import scene_kinds
    from harness.studies import stabilitymap

    try:
        spec = load(scene)
        plan = stabilitymap.default_plan(spec, dense)
    except (scenes.SceneError, scene_kinds.NotADriveline, ValueError) as error:
        raise InputError(str(error)) from None
    stiffnesses, dampings, h_omegas, masters = list(stiffnesses), list(dampings), list(h_omegas), list(masters)
    unknown = [m for m in masters if m not in stabilitymap.FIXED_STEP_MASTERS]
    if unknown:
        raise InputError(f"--master {', '.join(unknown)}: not a fixed-step master (known: "
                         f"{', '.join(stabilitymap.FIXED_STEP_MASTERS)})")
    for name, values, low in (("--stiffness", stiffnesses, 0.0), ("--h-omega", h_omegas, 0.0)):
        if any(not (math.isfinite(v) and v > low) for v in values):
            raise InputError(f"{name}: values must be finite and > {low:g}")
    if any(not (math.isfinite(v) and v >= 0) for v in dampings):
        raise InputError("--damping: values must be finite and >= 0")
    plan.stiffnesses = sorted(set(stiffnesses)) or plan.stiffnesses
    plan.dampings = sorted(set(dampings), reverse=True) or plan.dampings
    plan.h_omegas = sorted(set(h_omegas)) or plan.h_omegas
    plan.masters = list(dict.fromkeys(masters)) or plan.masters
    plan.min_steps = min_steps
    plan.refine = refine
    build()
    out = _claim(out or stabilitymap.default_out(spec))
    with _resumable(out):
        result = stabilitymap.sweep(spec, plan, out, jobs=jobs, resume=resume, progress=progress)
    written = stabilitymap.write(out, result)
    return {"result": result, "agreement": stabilitymap.agreement(result), "written": written}


def sweep(axes: Iterable[str] = (), *, scene: str = "kavz685", overrides=None, stop: float | None = None,
          thin: int = 1, workers: int | None = None, dask: str | None = None, resume: bool = True,
          out: Path | str | None = None, progress: bool = False) -> dict:
    """``lever sweep``: the monograph's parameter studies on ``axes`` (none: all; ``thin``:
    every n-th value), each case run for ``stop`` seconds (default: the scene's), locally
    (``workers`` processes) or on the Dask cluster at ``dask``; writes sweep.md, sweep.json
    and a plot an axis to ``out`` (default results/sweep), resuming from its case log.
    Returns the report (``cases``, ``trends``).  OSError when the cases cannot be run
    (e.g. no Dask scheduler at the address)."""
    from harness.paths import RESULTS
    from harness.studies import sweep as sweeps

    extra = _assignments(overrides)
    try:
        chosen = sweeps.thin(sweeps.select(list(axes)), thin)
        load(scene).with_overrides(extra)
    except (ValueError, scenes.SceneError) as error:
        raise InputError(str(error)) from None
    if stop is not None and not (math.isfinite(stop) and stop > 0):
        raise InputError(f"--stop {stop}: must be > 0 s")
    try:
        sweeps.check(chosen, scene, stop, extra)
    except scenes.SceneError as error:
        raise InputError(str(error)) from None
    build()
    out = Path(out or RESULTS / "sweep")
    _claim(out)
    try:
        with _resumable(out):
            return sweeps.sweep(chosen, out, scene=scene, stop=stop, extra=extra, workers=workers, dask=dask,
                                progress=progress, resume=resume)
    except scenes.SceneError as error:
        raise InputError(str(error)) from None


def sweep_verdict(trend: dict) -> str:
    """A trend's verdict as ``lever sweep`` prints it."""
    from harness.studies.sweep import NOT_JUDGED

    return {"yes": "reproduced", "partly": "partly", "no": "NOT reproduced", NOT_JUDGED: NOT_JUDGED}[trend["reproduced"]]


def study(name: str, out: Path | str | None = None, lags: Iterable[float] = ()) -> tuple[str, Path]:
    """``lever study NAME``: the numbers behind a documented decision ("transfer-modes") or
    statement ("runup"; ``lags``: scan these engine torque lags [s]); returns the table and
    the file it was written to in ``out`` (default results/studies)."""
    from harness.paths import RESULTS

    out = Path(out or RESULTS / "studies")
    lags = list(lags)
    if name == "runup":
        from harness.studies import runup

        for lag in lags:
            if not (math.isfinite(lag) and 0.0 <= lag <= 100.0):
                raise InputError(f"--scan {lag}: engine.torque_lag must be in [0, 100] s")
        text = runup.scan(lags) if lags else runup.markdown(runup.table())
        out.mkdir(parents=True, exist_ok=True)
        (out / "runup.md").write_text(text + "\n")
        return text, out / "runup.md"
    if name != "transfer-modes":
        raise InputError(f"no study '{name}' (known: transfer-modes, runup)")
    if lags:
        raise InputError("--scan applies to the runup study only")
    from harness.studies import decisions

    build()
    return decisions.transfer_modes(out), out / "transfer_modes.md"


def measured(files: Iterable[Path | str] = (), out: Path | str | None = None, stiffness: float | None = None,
             cycles: bool = True) -> dict:
    """``lever measured``: the model against measured torque tables (``files``: tables or
    folders; none: the monograph's data), written to ``out`` (default results/measured).
    Returns ``grades`` (per grade: conditions, errors, amplitudes, ``within_target``),
    ``findings`` (empty: every grade within the monograph's stated difference) and ``report``."""
    import json

    from harness.paths import RESULTS
    from harness.studies import measured as measurement

    out = Path(out or RESULTS / "measured")
    if stiffness is not None and not (math.isfinite(stiffness) and stiffness > 0):
        raise InputError(f"--stiffness {stiffness}: must be > 0 N*m/rad")
    files = list(files) or measurement.default_files()
    _, unusable = measurement.pair_tables(files)
    if unusable:       # the files are at fault, not the model: bad input
        raise InputError("the measurement files cannot be used:\n  - " + "\n  - ".join(unusable))
    build()
    findings = measurement.validate_measured(files, out, stiffness=stiffness, cycles=cycles)
    grades = json.loads((out / "measured.json").read_text())["grades"]
    return {"grades": grades, "findings": findings, "report": out / "measured.md"}


def engines(scene: str | Path | scenes.Scene = "kavz685", overrides=None, *, engines: Iterable[str] = (),
            step: float | None = None, repeats: int = 3, out: Path | str | None = None,
            progress: Callable[[str], None] | None = None) -> list[Path]:
    """``lever engines``: the scene in every engine that runs our FMUs (``engines``: these),
    error against the monolithic reference and run time; writes engines.md and engines.json
    to ``out`` (default results/engines/<scene>) and returns their paths."""
    from harness import peers
    from harness.studies import engines as comparison

    spec = load(scene, overrides)
    chosen = list(engines) or list(comparison.ENGINES)
    unknown = [n for n in chosen if n not in comparison.ENGINES]
    if unknown:
        raise InputError(f"unknown engine {', '.join(unknown)} (known: {', '.join(comparison.ENGINES)})")
    build()
    if refused := [said for name in chosen if (said := peers.problem(name, spec, spec.fmu_dir or FMUS))]:
        raise InputError("; ".join(refused) + " (--engine chooses the engines)")
    rows = comparison.compare(spec, chosen, step, repeats, spec.fmu_dir or FMUS, progress=progress)
    return comparison.write(Path(out) if out else comparison.default_out(spec), spec, rows)


def hosts(scene: str | Path | scenes.Scene = "kavz685", overrides=None, *, hosts: Iterable[str] = (),
          step: float = 1e-3, repeats: int = 3, fmu_dir: Path | None = None, native_env: str = "bare",
          out: Path | str | None = None, log: Callable[[str], None] | None = None) -> dict:
    """``lever hosts``: the scene in hosts we did not write and in our harness at one fixed
    step (``hosts``: these; ``fmu_dir``: time these FMUs instead of the built ones;
    ``native_env`` "set-up": ecos and the C importer get this Python's environment); writes
    hosts.md and hosts.json to ``out`` (default results/hosts/<scene>).  Returns ``report``,
    ``table`` (the markdown) and ``written``."""
    import json

    from harness.studies import hosts as comparison

    spec = load(scene, overrides)
    chosen = tuple(hosts) or comparison.HOSTS
    unknown = [n for n in chosen if n not in comparison.HOSTS]
    if unknown:
        raise InputError(f"unknown host {', '.join(unknown)} (known: {', '.join(comparison.HOSTS)})")
    if native_env not in ("bare", "set-up"):
        raise InputError(f"native_env {native_env!r}: bare or set-up")
    if fmu_dir is None:
        build()
    environment = comparison.set_up_environment() if native_env == "set-up" else None
    if refused := comparison.problems(spec, chosen, fmu_dir or spec.fmu_dir or FMUS):
        raise InputError("; ".join(refused) + " (--host chooses the hosts)")
    report = comparison.time_hosts(spec, step, repeats, fmu_dir or spec.fmu_dir or FMUS, chosen, environment,
                                   log=log or (lambda *_: None))
    folder = Path(out) if out else comparison.default_out(spec)
    folder.mkdir(parents=True, exist_ok=True)
    table = comparison.table(report)
    (folder / "hosts.json").write_text(json.dumps(report, indent=1))
    (folder / "hosts.md").write_text(table)
    return {"report": report, "table": table, "written": [folder / "hosts.md", folder / "hosts.json"]}


def export(scene: str | Path | scenes.Scene = "kavz685", to: str = "ssp", overrides=None, *,
           out: Path | str | None = None) -> tuple[Path, dict[str, str]]:
    """``lever export-ssp`` (``to="ssp"``: an SSP archive) and ``lever export-container``
    (``to="container"``: one FMU holding the scene's FMUs): the scene with ``overrides``
    written to ``out`` (default results/<to>/<scene>.<suffix>).  Returns the file and what
    each engine needs to run it with its values (engine -> how)."""
    from harness.engine.system import SceneInvalid
    from harness.paths import RESULTS

    if to == "ssp":
        from harness.formats import ssp
        write, suffix, how_to_run = ssp.export, "ssp", ssp.HOW_TO_RUN
    elif to == "container":
        from harness.formats import container
        write, suffix, how_to_run = container.build_container, "fmu", {}
    else:
        raise InputError(f"export to {to!r}: ssp or container")
    spec = load(scene, overrides)
    build()
    out = Path(out) if out else RESULTS / to / f"{spec.name}.{suffix}"
    try:
        path = write(spec, out, spec.fmu_dir or FMUS)
    except SceneInvalid as error:
        raise InputError(str(error)) from None
    return path, {engine: how.replace("ARCHIVE", str(path)) for engine, how in how_to_run.items()}


def compliance(fmus: Iterable[Path | str] = ()) -> Iterator[tuple[Path, list[str]]]:
    """``lever compliance``: fmpy's validation and ours on each FMU file, or on the FMU
    files in a folder (none: the built ones, built first: the FMI 2.0 editions, then the
    FMI 3.0 ones); ``(file, findings)`` one file at a time (empty: none)."""
    from harness.compliance import check_fmu
    from harness.paths import fmi3_dir

    fmus = [Path(f) for f in fmus]
    if not fmus:
        built = build()
        fmus = sorted(built.glob("*.fmu")) + sorted(fmi3_dir(built).glob("*.fmu"))
    for path in fmus:
        if path.is_dir():
            inside = sorted(path.glob("*.fmu"))
            if not inside:
                yield path, [f"{path}: a folder without FMU files (*.fmu)"]
            for fmu in inside:
                yield fmu, check_fmu(fmu)
        else:
            yield path, check_fmu(path)


def fingerprints(names: Iterable[str] = (), masters: Iterable[str] = (), stop: float | None = 0.2
                 ) -> Iterator[tuple[str, str, int, str]]:
    """``lever fingerprint``: ``(scene, master, rows, SHA-256 of the traces)`` for every
    committed scene (or ``names``) and master (or ``masters``), each run for at most
    ``stop`` seconds (0 or None: its own length)."""
    from harness.studies import fingerprint

    masters = list(masters)
    check_masters(*masters)
    if stop is not None and not (math.isfinite(stop) and stop >= 0):
        raise InputError(f"--stop {stop}: must be >= 0 s (0: each scene's own length)")
    build()
    try:
        yield from fingerprint.fingerprints(list(names) or None, masters or None, stop or None)
    except scenes.SceneError as error:
        raise InputError(str(error)) from None


def bad_inputs() -> tuple[list, str]:
    """``lever badinputs``: the bad-input corpus through fmpy's FMU2Slave on the built FMUs;
    the outcomes (``passed``, ``case.name``, ``messages``) and their summary."""
    from harness.formats import badinputs

    build()
    outcomes = badinputs.run()
    return outcomes, badinputs.summary(outcomes)

