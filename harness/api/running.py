"""A run from Python (``lever run``): the scene checked, the notes said before it
(``RunNote``, or ``notify``), the run, its reference and its summary."""
from __future__ import annotations

import contextlib as _contextlib
import math as _math
import warnings as _warnings
from pathlib import Path
from typing import Callable

from harness.api import inputs as _inputs
from harness.api.building import build
from harness.api.choices import check_agreement, check_masters, checked_plan, claimed_folder, load
from harness.api.inputs import InputError
from harness.api.results import UNTRUSTED, Run
from harness.description import scene as scene_files
from harness.paths import FMUS


class RunNote(UserWarning):
    """A note about a run the command line prints before it (``Run.notes`` keeps them)."""


def warn_note(kind: str, message: str):
    """A warning or note said as a ``RunNote`` where the caller gave no ``notify``."""
    _warnings.warn(f"{kind}: {message}", RunNote, stacklevel=_inputs.user_stacklevel())


def run(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, master: str | None = None,
        step: float | str | None = None, stop: float | str | None = None, tolerance: float | None = None,
        strict: bool = False, reference: bool = True, out: Path | str | None = None, progress: bool = False,
        stream: bool = False, notify: Callable[[str, str], None] | None = None, claimed: bool = False,
        observer=None, latency: bool = False, plots: bool = True) -> Run:
    """Run a scene as ``lever run`` does and return it (``Run``).

    ``overrides``: ``{"coupling.misalignment": "20 deg"}`` (values with their types: a
    number, a string with its unit, a name, True or False) or ``["coupling.stiffness=900"]``
    (``--set`` texts, read as the command line reads them);
    ``master``: one of ``lever run --help``'s (default: the scene's); ``step``, ``stop``:
    the communication step and a shorter (or longer) run, in seconds or with a time unit
    (``"1 ms"``); ``reference``: solve the monolithic reference
    (its error is in the summary); ``out``: write the run's files there (report.md,
    summary.json, traces.csv, plots); ``stream``: write traces.csv while running (needs
    ``out``).  ``notify(kind, message)`` hears the warnings and notes ("warning", "note");
    ``observer`` is told of every step (``harness.engine.observers``); ``latency``: time every
    step and write latency.md and latency.json to ``out`` (``Run.latency`` summarises them);
    ``plots``: false writes the traces, summary and report without drawing the plots.
    A failed or interrupted run is returned (``Run.ok`` false, ``Run.failure`` says why), and
    so is one not to be trusted (``Run.ok`` false, ``Run.untrusted`` says why, a warning);
    bad input raises InputError before anything runs."""
    from harness.engine import masters
    from harness.engine.component import FmuUnusable
    from harness.engine.me_component import NoModelExchange
    from harness.engine.observers import PaceWatch
    from harness.engine.run import available_memory, simulate, trace_memory
    from harness.engine.system import SceneInvalid
    from harness.formats import outputs, report
    from harness.judges import monolithic
    from harness.judges.stability import run_advice, run_method

    notes: list[str] = []

    def say(kind: str, message: str):
        notes.append(f"{kind}: {message}")
        (notify or warn_note)(kind, message)

    spec = load(scene, overrides, stop=stop, strict=strict)
    chosen = master or spec.experiment.master
    # an unknown master is named where it was given: the argument, an override, the scene file
    check_masters(chosen, argument="master" if master else _inputs.named("overrides").item("experiment.master")
                  if "experiment.master" in spec.overrides else "experiment.master")
    step = _inputs.step(step)
    check_agreement(spec, master=master, step=step)
    out = _inputs.folder(out)
    options = {}
    try:
        masters.stated_options(chosen, spec.experiment)
    except masters.TakesNoTolerance as error:
        raise InputError(f"{spec.path or spec.name}: {error}") from None
    if tolerance is not None:
        tolerance = _inputs.number(tolerance, "tolerance")
        if "tolerance" not in masters.MASTERS[chosen].options:
            raise InputError(f"{_inputs.named('tolerance')}: master '{chosen}' takes no tolerance (masters that do: "
                             + ", ".join(masters.takes_tolerance()) + ")")
        if not (_math.isfinite(tolerance) and 0 < tolerance < 1):
            raise InputError(f"{_inputs.named('tolerance').given(str(tolerance))}: must lie in (0, 1)")
        check_agreement(spec, tolerance=tolerance)
        options["tolerance"] = tolerance
    elif (spec.experiment.tolerance is not None and chosen != spec.experiment.master
          and "tolerance" in masters.MASTERS[chosen].options):
        say("note", f"experiment.tolerance = {spec.experiment.tolerance:g} is the scene's master's "
                    f"({spec.experiment.master}); {chosen} runs at its own default "
                    f"{masters.MASTERS[chosen].options['tolerance']:g} (give {_inputs.named('tolerance').given('...')} "
                    "to set it)")
    if stream and out is None:
        raise InputError(f"{_inputs.named('stream')}: name the output folder ({_inputs.named('out').given('...')}) "
                         "the traces are streamed to")
    if latency and out is None:
        raise InputError(f"{_inputs.named('latency')}: name the output folder ({_inputs.named('out').given('...')}) "
                         "the latency tables are written to")
    if latency:
        from harness.studies import latency as step_latency
        if observer is not None:
            raise InputError(f"{_inputs.named('latency')}: it times the steps with its own observer; give no other "
                             "observer")
        observer = timer = step_latency.StepTimer()
    build()
    fmu_dir = spec.fmu_dir or FMUS
    # the scene's names and values first: the stability advisor reads a sound scene only
    plan = checked_plan(spec, fmu_dir)
    if spec.experiment.transient_note:
        say("note", spec.experiment.transient_note)
    advice = run_advice(spec, chosen, step or spec.experiment.step, fmu_dir, lambda text: say("note", text))
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
                             f"({free / 2**30:.1f} GiB): use {_inputs.named('stream').on()} (writes traces.csv while "
                             f"running, keeps 1 row in k in memory), a larger {_inputs.named('step')} or a shorter "
                             "experiment.stop")
    with _contextlib.ExitStack() as folder:
        if out is not None:       # before the run: a bad or busy folder is said at once
            out = folder.enter_context(claimed_folder(out, already=claimed))
        if observer is None:        # a long run says how long, from its own pace, once it has one
            observer = PaceWatch(spec.experiment.stop, lambda message: say("note", message))
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
                    solution = _made_reference(plan, result, str(error), say)
        except KeyboardInterrupt:
            say("note", "interrupted while solving the reference: the run's results are written without it")
            result.failure_stage, result.failure = "interrupted", f"interrupted after the run, at t = {result.times[-1]:.6g} s"
            result.diagnosis = {"kind": "interrupted", "time": float(result.times[-1]), "message": result.failure}
        if out is not None:
            summary = report.write(Path(out), result, solution, plots=plots)
        else:
            summary = report.summarize(result, solution)
        if summary.get("untrusted"):
            say("warning", f"{UNTRUSTED}: {summary['untrusted']}")
        done = Run(result, solution, summary, Path(out) if out is not None else None, notes)
        if latency:
            done.latency = step_latency.report(Path(out), timer, result)
        return done


def _made_reference(plan, run, why: str, say):
    """A reference made from the scene's FMUs (``harness.judges.fmu_reference``) where the
    monolithic one is ``why`` unavailable, at the times of ``run``, what it takes said before
    it is made (from ``run``'s pace); None, said in one line, where none can be had."""
    from harness.judges import fmu_reference

    made = "Model Exchange" if fmu_reference.offers_model_exchange(plan) else "extrapolated co-simulation runs"
    wait = fmu_reference.expected_wait(plan, run)
    say("note", f"no monolithic reference ({why}): the error is measured against a reference made from the "
                f"scene's FMUs ({made}" + ("; cached)" if wait is None else f", cached once made): making it takes {wait}"))
    try:
        return fmu_reference.reference(plan, run.times)
    except fmu_reference.ReferenceUnavailable as error:
        say("note", f"no reference for this scene, so no error: {error}")
    except (ValueError, RuntimeError, OSError) as error:     # the run's own results are kept whatever the reference did
        say("note", f"no reference for this scene, so no error: making it failed ({type(error).__name__}: {error})")
    return None
