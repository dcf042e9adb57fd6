"""The harness from Python: run a scene, validate a result, bench the masters.

What ``lever run``, ``lever validate`` and ``lever bench`` do, as functions that return
their results instead of printing them (the command line calls these)::

    from harness import api

    api.scenes()                         # the committed scenes: name -> description
    run = api.run("kavz685", {"coupling.stiffness": 900}, stop="3 s")
    run                                  # Run(kavz685, master ..., ok, ...): one screen
    run.array(["coupling.tau2"])         # numpy structured array, 'time' first, as fmpy's
    run.summary["statistics"]["coupling.tau2"]   # mean and amplitude after the transient
    api.validate("kavz685", result=run, window=("0 s", "3 s")).passed

Signals are named as the traces name them, ``component.variable`` (``coupling.tau2``),
everywhere: traces, arrays, summary statistics, validation; a short name is taken where
only one signal ends with it (``tau2``).  Times take units as scene overrides do
(``step="1 ms"``), numbers may be numpy scalars.  Bad input (an unknown scene, parameter
or master, a value out of its range, an argument of the wrong type) raises
``InputError`` naming the argument, with the message the command line prints; nothing is
written unless an output folder is given (``out=``).  Notes the command line prints
before a run (the stability advisor, a shortened run's transient, unconnected inputs) go
to ``notify`` (default: Python's ``warnings``, shown at the caller's line) and are kept in
``Run.notes``.
"""
from __future__ import annotations

import contextlib as _contextlib
import importlib.util as _importlib_util
import math as _math
import os as _os
import warnings as _warnings
from dataclasses import dataclass as _dataclass, field as _field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping

import numpy as _np

from harness import api_inputs as _inputs
from harness.api_inputs import InputError, Signals, UnknownSignal
from harness.description import plan as _plans
from harness.description import scene as scene_files
from harness.paths import BUILD, FMUS

__all__ = ["InputError", "UnknownSignal", "BuildError", "StudyInterrupted", "RunNote", "Run", "Validation",
           "BenchResult", "ReferenceCheck", "Signals", "build", "fmu_path", "scenes", "masters", "load", "run",
           "validate",
           "validate_each", "bench", "stability_map", "sweep", "study", "measured", "engines", "hosts", "export",
           "compliance", "references", "fingerprints", "bad_inputs", "scenes_list"]


def __dir__():
    """``dir(api)``: the public names, not the modules it uses."""
    return sorted(__all__)


class BuildError(RuntimeError):
    """The FMUs could not be built (no C compiler, a failed compliance check, ...)."""


class StudyInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a study that resumes from its case log; the message says what was
    kept (``lever``: exit status 130)."""


@_contextlib.contextmanager
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
    _warnings.warn(f"{kind}: {message}", RunNote, stacklevel=_inputs.user_stacklevel())


def _build_module():
    spec = _importlib_util.spec_from_file_location("_lever_build_fmus", BUILD / "fmus.py")
    module = _importlib_util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build(force: bool = False, fmu_dir: Path | None = None, log: Callable[[str], None] | None = None) -> Path:
    """Build the FMUs into ``fmu_dir`` (default ``harness.paths.FMUS``) when they are
    missing or older than their sources; return the folder.  BuildError when the build
    fails (no C compiler: the message says what to install)."""
    fmu_dir = _inputs.folder(fmu_dir, "fmu_dir") or Path(FMUS)
    module = _build_module()
    if force or not module.is_current(fmu_dir):
        try:
            module.build(fmu_dir, force=force, log=log or (lambda *_: None))
        except RuntimeError as error:
            raise BuildError(_with_compiler_hint(error)) from None
    return fmu_dir


def fmu_path(model: str, fmi: int = 2) -> Path:
    """The built FMU file of ``model`` (``"EngineShaft"``, ``"LeverCoupling"``, ...), built
    first when missing or stale: what fmpy's ``simulate_fmu`` or another host takes, in a
    checkout (build/fmus) and in a pip installation (the user's cache folder) alike.
    ``fmi=3``: its FMI 3.0 edition."""
    from harness.paths import fmi3_dir

    if fmi not in (2, 3) or isinstance(fmi, bool):
        raise InputError(f"fmi={fmi!r}: 2 or 3 (the FMI edition)")
    folder = build()
    folder = folder if fmi == 2 else fmi3_dir(folder)
    known = sorted(p.stem for p in folder.glob("*.fmu"))
    if model not in known:
        hint = scene_files.did_you_mean(model, known) if isinstance(model, str) else ""
        raise InputError(f"model={model!r}{hint}: one of {', '.join(known)}")
    return folder / f"{model}.fmu"


def scenes() -> dict[str, str]:
    """The committed scenes (resources/scenes): name -> description (an unreadable one:
    its error), as ``lever scenes`` lists them."""
    from harness.paths import SCENES

    out = {}
    for path in sorted(SCENES.glob("*.toml")):
        try:
            out[path.stem] = scene_files.load(path).description
        except scene_files.SceneError as error:
            out[path.stem] = f"(invalid: {error})"
    return out


#: the former name of ``scenes()``
scenes_list = scenes


def _assignments(overrides) -> list[str]:
    """``{"coupling.stiffness": 900}`` or ``["coupling.stiffness=900"]`` as ``--set`` strings."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return [f"{k}={_plain(v)}" for k, v in overrides.items()]
    if isinstance(overrides, str):
        return [overrides]
    return _inputs.names(overrides, "overrides")


def _plain(value):
    """A numpy scalar as the Python number it is (``--set`` reads its text)."""
    return value.item() if isinstance(value, _np.generic) else value


def load(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, stop: float | None = None,
         strict: bool = False) -> scene_files.Scene:
    """The scene (a name in resources/scenes, a .toml file, an SSP archive .ssp, or a Scene)
    with ``overrides`` (a dict ``{"component.parameter": value}`` or ``--set`` strings) and
    ``stop``; InputError on bad input."""
    scene = _inputs.scene_argument(scene)
    assignments = _assignments(overrides)
    stop = _inputs.seconds(stop, "stop")
    if stop is not None:
        assignments.append(f"experiment.stop={stop!r}")
    if strict:
        assignments.append("experiment.strict=true")
    try:
        if isinstance(scene, scene_files.Scene):
            spec = scene
        elif str(scene).endswith(".ssp"):
            from harness.formats import ssp
            spec = ssp.read_scene(scene)
        else:
            spec = scene_files.load(scene)
        return spec.with_overrides(assignments)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def masters(fixed_step: bool = False) -> dict[str, str]:
    """The co-simulation masters: name -> what it does (docs/reference/masters.md);
    ``fixed_step``: only those ``stability_map`` sweeps (no adaptive step, no Model Exchange)."""
    from harness.engine.masters import MASTERS

    if fixed_step:
        from harness.studies.stabilitymap import FIXED_STEP_MASTERS
        return {name: MASTERS[name].description for name in FIXED_STEP_MASTERS}
    return {name: cls.description for name, cls in MASTERS.items()}


def check_masters(*names: str):
    """InputError when one of ``names`` is not a master."""
    from harness.engine import masters

    _inputs.names(names, "master")
    try:
        masters.check(*names)
    except masters.UnknownMaster as error:
        raise InputError(str(error)) from None


@_dataclass
class Run:
    """One run: the result (times, traces, failure), the reference and the summary (what
    summary.json holds), and where the files went (``out``; None: none written).
    ``repr(run)`` (a notebook cell's output) says in a few lines how it ended and its
    main figures."""
    #: what the engine returned (``harness.engine.run.RunResult``)
    result: object
    #: the monolithic reference solution (None: not solved, ``reference=False``)
    reference: object | None
    #: what summary.json holds: statistics, error against the reference, energy balance
    #: (signals by their full names; a short one is taken where unambiguous)
    summary: dict
    #: where the files went (None: none written)
    out: Path | None = None
    #: the warnings and notes said about this run (also sent to ``notify``)
    notes: list[str] = _field(default_factory=list)
    #: the step latency's summary (``latency=True``; the tables are in ``out``)
    latency: list[str] | None = None

    def __post_init__(self):
        aliases = _driveline_aliases(self.result.scene)
        if isinstance(getattr(self.result, "traces", None), dict) and not isinstance(self.result.traces, Signals):
            self.result.traces = Signals(self.result.traces, aliases)
        for key in ("statistics", "error_vs_reference"):
            if isinstance(self.summary.get(key), dict):
                self.summary[key] = Signals(self.summary[key], aliases)

    @property
    def scene(self) -> scene_files.Scene:
        """The scene as run (with the overrides)."""
        return self.result.scene

    @property
    def times(self) -> _np.ndarray:
        """The communication points [s], one per row of the traces."""
        return self.result.times

    @property
    def traces(self) -> Signals:
        """The recorded signals by their names, ``component.variable`` (``coupling.tau2``):
        one array a signal, a value per time; a short name (``tau2``) is taken where only
        one signal ends with it."""
        return self.result.traces

    @property
    def ok(self) -> bool:
        """Whether the run reached its stop time without a failure."""
        return self.result.ok

    @property
    def failure(self) -> str | None:
        """Why the run failed or was interrupted, in a sentence (None: it did not)."""
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

    def array(self, names: Iterable[str] | str | None = None) -> _np.ndarray:
        """The traces as one numpy structured array, ``time`` first (as fmpy's
        ``simulate_fmu`` returns): ``a["time"]``, ``a["coupling.tau2"]``; ``names``: only
        these signals (full or unambiguous short names; the fields are the full names)."""
        chosen = list(self.traces) if names is None else [self.traces.full_name(n)
                                                           for n in _inputs.names(names, "names")]
        return _np.rec.fromarrays([_np.asarray(self.times, float)]
                                  + [_np.asarray(self.traces[n], float) for n in chosen], names=["time"] + chosen)

    def __repr__(self) -> str:
        s = self.summary
        span = f"{self.times[0]:g} ... {self.times[-1]:g} s" if len(self.times) else "no rows"
        head = (f"Run({s.get('scene')}: {self.outcome.upper() if self.outcome != 'ok' else 'ok'}, master "
                f"{s.get('master')}, step {s.get('step_s', 0):g} s, {span}, {len(self.times)} rows x "
                f"{len(self.traces)} signals, wall time {s.get('wall_time_s') or 0:.2f} s")
        lines = [head]
        if self.failure:
            lines.append(f"  failure: {self.failure}")
        errors = s.get("error_vs_reference") or {}
        for name, stats in list((s.get("statistics") or {}).items())[:6]:
            if stats:
                error = errors.get(name)
                lines.append(f"  {name:16s} mean {stats['mean']:11.5g}  amplitude {stats['amplitude']:10.4g}"
                             + (f"  error vs reference {100 * error['rms_relative']:.2g} % RMS" if error else ""))
        if (balance := s.get("energy_balance")):
            lines.append(f"  energy residual {100 * balance['residual_relative']:.2g} % of the work in")
        tail = [f"{len(self.notes)} note{'s' if len(self.notes) != 1 else ''} in .notes"] if self.notes else []
        tail.append(f"files in {self.out}" if self.out else "no files written")
        lines.append("  " + "; ".join(tail) + ")")
        return "\n".join(lines)


def _driveline_aliases(scene) -> dict[str, str]:
    """A driveline's short names (``w1``, ``tau2``, ...) -> its signals; none for other scenes."""
    from harness.description import scene_kinds
    from harness.judges import metrics

    try:
        return metrics.signals(scene)
    except (scene_kinds.NotADriveline, KeyError, ValueError, AttributeError):
        return {}


def _step(step, label="step") -> float | None:
    """``step`` as seconds (units taken), checked as every communication step is."""
    step = _inputs.seconds(step, label)
    if step is not None and (problem := scene_files.step_problem(step, label)):
        raise InputError(problem)
    return step


def run(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, master: str | None = None,
        step: float | str | None = None, stop: float | str | None = None, tolerance: float | None = None,
        strict: bool = False, reference: bool = True, out: Path | str | None = None, progress: bool = False,
        stream: bool = False, notify: Callable[[str, str], None] | None = None, claimed: bool = False,
        observer=None, latency: bool = False, plots: bool = True) -> Run:
    """Run a scene as ``lever run`` does and return it (``Run``).

    ``overrides``: ``{"coupling.misalignment": "20 deg"}`` or ``["coupling.stiffness=900"]``;
    ``master``: one of ``lever run --help``'s (default: the scene's); ``step``, ``stop``:
    the communication step and a shorter (or longer) run, in seconds or with a time unit
    (``"1 ms"``); ``reference``: solve the monolithic reference
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
    step = _step(step)
    out = _inputs.folder(out)
    options = {}
    if tolerance is not None:
        tolerance = _inputs.number(tolerance, "tolerance")
        if "tolerance" not in masters.MASTERS[chosen].options:
            raise InputError(f"--tolerance: master '{chosen}' takes no tolerance (masters that do: "
                             + ", ".join(n for n, m in masters.MASTERS.items() if "tolerance" in m.options) + ")")
        if not (_math.isfinite(tolerance) and 0 < tolerance < 1):
            raise InputError(f"tolerance={tolerance}: must lie in (0, 1)")
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
    plan = _plans.check(spec, fmu_dir=fmu_dir)
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
        say("warning", scene_files.unconnected_message(result.unconnected_inputs))
    if result.unchecked_connections:
        say("note", scene_files.unchecked_message(result.unchecked_connections))
    solution = None
    try:
        if "reference" in spec.features and reference and not stream and result.ok:
            try:
                solution = monolithic.solve(plan, result.times)
            except monolithic.ReferenceUnavailable as error:
                solution = _made_reference(plan, result.times, str(error), say)
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


def _made_reference(plan, times, why: str, say):
    """A reference made from the scene's FMUs (``harness.judges.fmu_reference``) where the
    monolithic one is ``why`` unavailable; None, said in one line, where none can be had."""
    from harness.judges import fmu_reference

    made = "Model Exchange" if fmu_reference.offers_model_exchange(plan) else "extrapolated co-simulation runs"
    say("note", f"no monolithic reference ({why}): the error is measured against a reference made from the "
                f"scene's FMUs ({made}; cached once computed)")
    try:
        return fmu_reference.reference(plan, times)
    except fmu_reference.ReferenceUnavailable as error:
        say("note", f"no reference for this scene, so no error: {error}")
    except (ValueError, RuntimeError, OSError) as error:     # the run's own results are kept whatever the reference did
        say("note", f"no reference for this scene, so no error: making it failed ({type(error).__name__}: {error})")
    return None


#: ``lever validate --tolerance``: the engineer's verdict (harness.judges.verdict) or fmpy's
#: cross-check band (harness.judges.validation)
VERDICTS = ("lever", "cross-check")


@_dataclass(repr=False)
class Validation:
    """The verdict on one NAME (``lever validate NAME``): per signal (``findings.signals``),
    the problems that fail it (``findings.problems``), the span judged, and the result that
    was judged.  ``repr()`` says PASS or FAIL, the failing signals and the problems in a
    few lines."""
    #: what was judged: a reference's name or an FMU file
    name: str
    #: the verdict in detail (``harness.judges.validation.Findings``)
    findings: object
    #: the tolerance band per signal
    bands: dict
    #: the result judged (``.times``, ``.traces``, ``.how``)
    result: object
    #: the committed reference traces
    reference: object
    #: where validation.json and the plots went (None: none written)
    out: Path | None = None

    @property
    def passed(self) -> bool:
        """Whether every signal passes and nothing fails the whole result."""
        return self.findings.passed

    def __repr__(self) -> str:
        f = self.findings
        verdict = "PASS" if f.passed else "FAIL"
        span = f", judged {f.describe_span()}" if f.span else ""
        failed = [s for s in f.signals if not s.passed]
        if hasattr(f, "tolerance"):         # fmpy's cross-check band (harness.judges.validation)
            lines = [f"Validation({self.name}: {verdict}{span}; {len(f.signals)} signals, "
                     f"{len(f.signals) - len(failed)} within the band ({f.tolerance.describe()})"]
            shown = [f"  FAIL {s.name}: {100 * s.fraction_outside:.3g} % of the samples outside "
                     f"+-{s.band_width:.4g}, max error {s.max_error:.4g} at t = {s.max_error_time:.4g} s"
                     for s in failed]
        else:                               # the engineer's verdict (harness.judges.verdict)
            lines = [f"Validation({self.name}: {verdict}{span}; {len(f.signals)} signals judged, "
                     f"{len(f.signals) - len(failed)} pass"
                     + (f", {len(f.not_judged)} not judged" if f.not_judged else "")]
            shown = [f"  FAIL {s.name}: " + "; ".join(f"{c.quantity} {c.detail}" for c in s.failed)
                     for s in failed]
        lines += shown[:8]
        if len(failed) > 8:
            lines.append(f"  ... {len(failed) - 8} more failing signals in .findings.signals")
        lines += [f"  problem: {p}" for p in f.problems[:4]]
        if len(f.problems) > 4:
            lines.append(f"  ... {len(f.problems) - 4} more problems in .findings.problems")
        lines[-1] += f"; files in {self.out})" if self.out else ")"
        return "\n".join(lines)


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
            raise InputError(f"--set {key}: {model} has no parameter '{name}'{scene_files.did_you_mean(name, known)} "
                             f"(parameters: {', '.join(known)})")
        value = scene_files.coerce(raw)
        problems = scene_files.value_findings(f"{model}.{name}", var, value)     # type, unit's dimension, range
        if problems:
            raise InputError("; ".join(problems))
        values[name] = converted(var, value, key)
    return values


def _window(window) -> tuple[float | None, float | None] | None:
    """``window`` as ``(start, stop)`` in seconds: from ``"START:STOP"`` or a pair whose
    sides are times (units taken) or None."""
    if window is None or isinstance(window, str):
        return parse_window(window)
    if not (isinstance(window, (tuple, list)) and len(window) == 2):
        raise InputError(f"window={window!r}: expected (start, stop) in seconds or 'START:STOP'")
    return _inputs.seconds(window[0], "window start"), _inputs.seconds(window[1], "window stop")


def parse_window(text: str | None) -> tuple[float | None, float | None] | None:
    """``--window START:STOP`` (either side may be left empty: the reference's own end; a
    side may carry a time unit, ``0:500 ms``)."""
    if text is None:
        return None
    parts = str(text).split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        low, high = (_inputs.seconds(p, "--window") if p.strip() else None for p in parts)
    except (ValueError, InputError):
        raise InputError(f"--window {text}: expected START:STOP in seconds, e.g. 2:10 or 0:1 or 0:500 ms (an empty "
                         "side: the reference's own start or stop)") from None
    for v in (low, high):
        if v is not None and not _math.isfinite(v):
            raise InputError(f"--window {text}: the times must be finite")
    if low is not None and high is not None and not high > low:
        raise InputError(f"--window {text}: STOP must be > START")
    return low, high


def _fmu_file(name) -> Path | None:
    """NAME as an FMU file (``lever validate path/Model.fmu``), or None for a name."""
    return Path(name) if scene_files.is_fmu_path(name) else None


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


def validate(name: str, *, overrides=None, master: str | None = None, step: float | str | None = None,
             result=None, tolerance: str = "lever",
             window: tuple[float | str | None, float | str | None] | str | None = None,
             out: Path | str | None = None, rtol=None, signals=None) -> Validation:
    """Judge NAME against its committed reference traces, as ``lever validate NAME``: run
    the FMU stand-alone or the scene (with ``overrides``, ``master``, ``step``), or judge
    ``result`` instead: a ``Run`` (what ``api.run`` returned), a numpy structured array
    with a ``time`` field (``Run.array()``, fmpy's ``simulate_fmu``), a ``(times, {signal:
    values})`` pair, a pandas DataFrame with a ``time`` column, or the path of a CSV another
    tool wrote; signals named like the reference's (``component.variable`` for a scene,
    the FMU's variable names for an FMU).  NAME may be an FMU file (``.fmu``, FMI 2.0 or
    3.0, such as an FMI 3.0 edition in build/fmus3): it runs stand-alone as its model's
    name does, judged by that model's reference.  ``tolerance``: "lever" or "cross-check"
    (the band's figures).  ``window``: judge only ``(start, stop)`` of the reference's span
    (e.g. a shorter run; seconds or with a time unit, ``("0 s", "500 ms")``, or
    ``"START:STOP"``); ``out``: write validation.json, the result and a plot per failing
    signal there.  ``repr()`` of what it returns says PASS or FAIL and why."""
    from harness.engine.component import FmuUnusable
    from harness.engine.me_component import NoModelExchange
    from harness.engine.system import SceneInvalid
    from harness.formats import reference_traces
    from harness.judges import validation, verdict

    if not isinstance(name, (str, _os.PathLike)):
        raise InputError(f"name={name!r}: expected a reference's name (a scene or an FMU, e.g. 'kavz685' or "
                         "'EngineShaft') or an FMU file's path")
    fmu_file = _fmu_file(name)
    label, name = (str(name), fmu_file_model(fmu_file)[0]) if fmu_file is not None else (str(name), str(name))
    known = reference_traces.all_names()
    if name not in known:
        raise InputError(reference_traces.why_no_reference(name)
                         or f"no reference '{name}'{scene_files.did_you_mean(name, known)} (known: {', '.join(known)})")
    _inputs.choice(tolerance, "tolerance", VERDICTS)
    if tolerance != "lever" and (_assignments(rtol) or _assignments(signals)):
        raise InputError(f"--rtol and --signals set the 'lever' verdict; --tolerance {tolerance} is fmpy's band, "
                         "which has its own figures and judges every signal")
    try:
        rules = verdict.parse_rtol(_assignments(rtol), "--rtol")
    except ValueError as error:
        raise InputError(str(error)) from None
    step = _step(step)
    out = _inputs.folder(out)
    window = _window(window)
    given = _inputs.result_traces(result) if result is not None else None
    try:
        ref = reference_traces.read(name)
    except reference_traces.TraceFileError as error:
        raise InputError(str(error)) from None
    if isinstance(given, Path):
        try:
            other = reference_traces.read_csv(given)
        except reference_traces.TraceFileError as error:
            raise InputError(str(error)) from None
        judged = reference_traces.Result(other.times, other.signals, f"from {given}")
    elif given is not None:
        times, traces, how = given
        judged = reference_traces.Result(times, traces, how, failure=getattr(result, "failure", None))
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
    if tolerance == "lever":
        try:
            settings = verdict.settings_of(ref)
            findings = verdict.judge(judged.times, judged.traces, ref.outputs.times, ref.outputs.signals,
                                     window=(start, stop), transient=settings.transient,
                                     rtol=verdict.Tolerances([settings.rules, rules]), signals=_assignments(signals),
                                     kinds=settings.kinds, rotation_signal=settings.rotation_signal, name=label)
        except ValueError as error:
            raise InputError(str(error)) from None
        bands = {}
        findings.notes += reference_traces.provenance_notes(
            ref, given if isinstance(given, Path) else None if result is not None else result, overrides, master, step)
    else:
        findings, bands = validation.compare_span(label, judged.times, judged.traces, ref.outputs.times,
                                                  ref.outputs.signals, validation.TOLERANCES[tolerance], start, stop,
                                                  (ref.opt.start, ref.opt.stop))
    if judged.failure:
        findings.problems.append(f"the run failed: {judged.failure}")
    if out is not None:
        reference_traces.write_validation(out, findings, bands, judged, ref, write_result=result is None)
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
                  out: Path | str | None = None, rtol=None, signals=None) -> Iterator[Validation]:
    """``lever validate NAMES``: ``validate`` for each name (none: every reference), in
    ``out`` (one name) or ``out/<name>`` (default results/validate/<name>); input checked
    and the FMUs built before the first."""
    from harness.paths import RESULTS

    chosen = reference_names(_inputs.names(names, "names"))
    if result is not None and len(chosen) != 1:
        raise InputError("--result: name exactly one reference the CSV is to be compared with "
                         "(e.g. lever validate --result run.csv kavz685)")
    span = _window(window)
    step = _step(step)
    if result is None and any(_fmu_file(name) is None for name in chosen):
        build()
    for name in chosen:
        folder = name
        if _fmu_file(name) is not None:       # results/validate/<Model>-fmi<major version>
            model, version = fmu_file_model(_fmu_file(name))
            folder = f"{model}-fmi{version.split('.')[0]}"
        target = out if (out and len(chosen) == 1) else Path(out or RESULTS / "validate") / folder
        yield validate(name, overrides=_assignments(overrides), master=master, step=step, result=result,
                       tolerance=tolerance, window=span, out=target, rtol=rtol, signals=signals)


@_dataclass
class ReferenceCheck:
    """One committed reference trace against what the project computes now."""
    name: str
    #: "current", "stale" (not current, left), "updated" (not current, rewritten) or
    #: "unavailable" (no reference can be computed: ``reason``)
    status: str
    problems: list[str] = _field(default_factory=list)
    #: per signal: ``signal``, ``max_change``, ``relative``, ``at_time``
    changes: list = _field(default_factory=list)
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
        except (ReferenceUnavailable, scene_files.SceneError) as error:
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


def bench(scene: str | Path | scene_files.Scene = "kavz685", *, repeats: int = 3, only: Iterable[str] = (),
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
    repeats = _inputs.count(repeats, "repeats", 1, 20)
    only = _inputs.names(only, "only")
    out = _inputs.folder(out)
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
    return BenchResult(result)


class BenchResult(dict):
    """What ``bench`` returns: the benchmark's result as a dict (``["claims"]``, ``["cases"]``,
    ``["summary"]``, ``["written"]``, ...); ``repr()`` says in a screen how many cases ran
    and failed, the claims' lines ``lever bench`` prints and where the files are."""

    def __repr__(self) -> str:
        cases = self.get("cases") or []
        failed = [c for c in cases if getattr(c, "failure", None)]
        lines = [f"BenchResult({self.get('scene')}: {len(cases) - len(failed)} of {len(cases)} cases ran"
                 + (f", {len(failed)} FAILED ({', '.join(c.label for c in failed[:4])}"
                    f"{', ...' if len(failed) > 4 else ''})" if failed else ", none failed")]
        summary = list(self.get("summary") or [])
        lines += summary[:14] + ([f"  ... {len(summary) - 14} more lines in ['summary']"] if len(summary) > 14 else [])
        written = self.get("written") or []
        lines.append(f"  written: {Path(written[0]).parent}/ ({', '.join(Path(w).name for w in written)}))"
                     if written else "  nothing written)")
        return "\n".join(lines)


def _claim(out: Path) -> Path:
    """``out`` made, proven writable and locked for this process (InputError when it cannot
    be, or another lever is writing there)."""
    from harness.formats import outputs

    try:
        return outputs.claim(Path(out))
    except outputs.OutputError as error:
        raise InputError(str(error)) from None


def stability_map(scene: str | Path | scene_files.Scene = "kavz685", *, stiffnesses: Iterable[float] = (),
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

    out = _inputs.folder(out)
    min_steps = _inputs.count(min_steps, "min_steps", 16, 100000)
    jobs = _inputs.count(jobs, "jobs", 1, 64)
    stiffnesses, dampings, h_omegas = ([_inputs.number(v, label) for v in values] for label, values in (
        ("stiffnesses", stiffnesses), ("dampings", dampings), ("h_omegas", h_omegas)))
    masters = _inputs.names(masters, "masters")
    try:
        spec = load(scene)
        plan = stabilitymap.default_plan(spec, dense)
    except (scene_files.SceneError, scene_kinds.NotADriveline, ValueError) as error:
        raise InputError(str(error)) from None
    stiffnesses, dampings, h_omegas, masters = list(stiffnesses), list(dampings), list(h_omegas), list(masters)
    unknown = [m for m in masters if m not in stabilitymap.FIXED_STEP_MASTERS]
    if unknown:
        raise InputError(f"--master {', '.join(unknown)}: not a fixed-step master (known: "
                         f"{', '.join(stabilitymap.FIXED_STEP_MASTERS)})")
    for name, values, low in (("--stiffness", stiffnesses, 0.0), ("--h-omega", h_omegas, 0.0)):
        if any(not (_math.isfinite(v) and v > low) for v in values):
            raise InputError(f"{name}: values must be finite and > {low:g}")
    if any(not (_math.isfinite(v) and v >= 0) for v in dampings):
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
    _inputs.scene_argument(scene)
    axes = _inputs.names(axes, "axes")
    thin = _inputs.count(thin, "thin", 1, 100)
    workers = None if workers is None else _inputs.count(workers, "workers", 1, 256)
    stop = _inputs.seconds(stop, "stop")
    out = _inputs.folder(out)
    try:
        chosen = sweeps.thin(sweeps.select(list(axes)), thin)
        load(scene).with_overrides(extra)
    except (ValueError, scene_files.SceneError) as error:
        raise InputError(str(error)) from None
    if stop is not None and not stop > 0:
        raise InputError(f"stop={stop}: must be > 0 s")
    try:
        sweeps.check(chosen, scene, stop, extra)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None
    build()
    out = Path(out or RESULTS / "sweep")
    _claim(out)
    try:
        with _resumable(out):
            return sweeps.sweep(chosen, out, scene=scene, stop=stop, extra=extra, workers=workers, dask=dask,
                                progress=progress, resume=resume)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def sweep_verdict(trend: dict) -> str:
    """A trend's verdict as ``lever sweep`` prints it."""
    from harness.studies.sweep import NOT_JUDGED

    return {"yes": "reproduced", "partly": "partly", "no": "NOT reproduced", NOT_JUDGED: NOT_JUDGED}[trend["reproduced"]]


def study(name: str, out: Path | str | None = None, lags: Iterable[float] = ()) -> tuple[str, Path]:
    """``lever study NAME``: the numbers behind a documented decision ("transfer-modes") or
    statement ("runup"; ``lags``: scan these engine torque lags [s]; "reference-agreement": the
    references made from the FMUs against the monolithic one); returns the table and
    the file it was written to in ``out`` (default results/studies)."""
    from harness.paths import RESULTS

    out = _inputs.folder(out) or RESULTS / "studies"
    lags = [_inputs.seconds(lag, "lags") for lag in lags]
    if name == "runup":
        from harness.studies import runup

        for lag in lags:
            if not (_math.isfinite(lag) and 0.0 <= lag <= 100.0):
                raise InputError(f"--scan {lag}: engine.torque_lag must be in [0, 100] s")
        text = runup.scan(lags) if lags else runup.markdown(runup.table())
        out.mkdir(parents=True, exist_ok=True)
        (out / "runup.md").write_text(text + "\n")
        return text, out / "runup.md"
    if name not in ("transfer-modes", "reference-agreement"):
        raise InputError(f"no study '{name}' (known: transfer-modes, runup, reference-agreement)")
    if lags:
        raise InputError("--scan applies to the runup study only")
    if name == "reference-agreement":
        from harness.studies import reference_agreement

        build()
        text = reference_agreement.study()
        out.mkdir(parents=True, exist_ok=True)
        (out / "reference_agreement.md").write_text(text + "\n")
        return text, out / "reference_agreement.md"
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

    out = _inputs.folder(out) or RESULTS / "measured"
    stiffness = None if stiffness is None else _inputs.number(stiffness, "stiffness")
    if stiffness is not None and not (_math.isfinite(stiffness) and stiffness > 0):
        raise InputError(f"--stiffness {stiffness}: must be > 0 N*m/rad")
    files = list(files) or measurement.default_files()
    _, unusable = measurement.pair_tables(files)
    if unusable:       # the files are at fault, not the model: bad input
        raise InputError("the measurement files cannot be used:\n  - " + "\n  - ".join(unusable))
    build()
    findings = measurement.validate_measured(files, out, stiffness=stiffness, cycles=cycles)
    grades = json.loads((out / "measured.json").read_text())["grades"]
    return {"grades": grades, "findings": findings, "report": out / "measured.md"}


def engines(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, engines: Iterable[str] = (),
            step: float | None = None, repeats: int = 3, out: Path | str | None = None,
            progress: Callable[[str], None] | None = None) -> list[Path]:
    """``lever engines``: the scene in every engine that runs our FMUs (``engines``: these),
    error against the monolithic reference and run time; writes engines.md and engines.json
    to ``out`` (default results/engines/<scene>) and returns their paths."""
    from harness import peers
    from harness.studies import engines as comparison

    spec = load(scene, overrides)
    step, repeats, out = _step(step), _inputs.count(repeats, "repeats", 1, 20), _inputs.folder(out)
    chosen = _inputs.names(engines, "engines") or list(comparison.ENGINES)
    unknown = [n for n in chosen if n not in comparison.ENGINES]
    if unknown:
        raise InputError(f"unknown engine {', '.join(unknown)} (known: {', '.join(comparison.ENGINES)})")
    build()
    if refused := [said for name in chosen if (said := peers.problem(name, spec, spec.fmu_dir or FMUS))]:
        raise InputError("; ".join(refused) + " (--engine chooses the engines)")
    rows = comparison.compare(spec, chosen, step, repeats, spec.fmu_dir or FMUS, progress=progress)
    return comparison.write(Path(out) if out else comparison.default_out(spec), spec, rows)


def hosts(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, hosts: Iterable[str] = (),
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
    step, repeats, out = _step(step), _inputs.count(repeats, "repeats", 1, 20), _inputs.folder(out)
    chosen = tuple(_inputs.names(hosts, "hosts")) or comparison.HOSTS
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


def export(scene: str | Path | scene_files.Scene = "kavz685", to: str = "ssp", overrides=None, *,
           out: Path | str | None = None) -> tuple[Path, dict[str, str], list[str]]:
    """``lever export-ssp`` (``to="ssp"``: an SSP archive) and ``lever export-container``
    (``to="container"``: one FMU holding the scene's FMUs): the scene with ``overrides``
    written to ``out`` (default results/<to>/<scene>.<suffix>).  Returns the file, what each
    engine needs to run it with its values (engine -> a command line) and what some engines
    would run otherwise than the scene says (sentences; none when the file carries every
    value)."""
    from harness.engine.system import SceneInvalid
    from harness.paths import RESULTS

    if to == "ssp":
        from harness.formats import ssp
        write, suffix, how_to_run = ssp.export, "ssp", ssp.how_to_run
    elif to == "container":
        from harness.formats import container
        write, suffix, how_to_run = container.build_container, "fmu", lambda *_: ({}, [])
    else:
        raise InputError(f"to={to!r}: ssp or container")
    spec = load(scene, overrides)
    out = _inputs.folder(out)
    build()
    out = Path(out) if out else RESULTS / to / f"{spec.name}.{suffix}"
    fmu_dir = spec.fmu_dir or FMUS
    try:
        path = write(spec, out, fmu_dir)
    except SceneInvalid as error:
        raise InputError(str(error)) from None
    return (path, *how_to_run(spec, path, fmu_dir))


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

    masters = _inputs.names(masters, "masters")
    names = _inputs.names(names, "names")
    check_masters(*masters)
    stop = _inputs.seconds(stop, "stop")
    if stop is not None and not stop >= 0:
        raise InputError(f"stop={stop}: must be >= 0 s (0: each scene's own length)")
    build()
    try:
        yield from fingerprint.fingerprints(list(names) or None, masters or None, stop or None)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def bad_inputs() -> tuple[list, str]:
    """``lever badinputs``: the bad-input corpus through fmpy's FMU2Slave on the built FMUs;
    the outcomes (``passed``, ``case.name``, ``messages``) and their summary."""
    from harness.formats import badinputs

    build()
    outcomes = badinputs.run()
    return outcomes, badinputs.summary(outcomes)

