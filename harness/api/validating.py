"""Validation from Python (``lever validate`` and ``lever reference``): a result, a scene
or an FMU file judged against its committed reference traces."""
from __future__ import annotations

import math as _math
import os as _os
from pathlib import Path
from typing import Callable, Iterable, Iterator

from harness.api import inputs as _inputs
from harness.api.building import build
from harness.api.choices import check_agreement, check_masters, load
from harness.api.inputs import InputError
from harness.api.results import ReferenceCheck, Validation
from harness.api.running import warn_note
from harness.description import scene as scene_files
from harness.engine.observers import PaceWatch
from harness.paths import FMUS


#: ``lever validate --tolerance``: the engineer's verdict (harness.judges.verdict) or fmpy's
#: cross-check band (harness.judges.validation)
VERDICTS = ("lever", "cross-check")


def fmu_start_values(model: str, assignments, fmu_path: Path | None = None) -> dict:
    """``name=value`` settings for an FMU run stand-alone: its parameters (and inputs not in
    the ``_in.csv``), checked against the model description (of the FMU file ``fmu_path``,
    default ``model``'s in build/fmus); InputError otherwise."""
    from fmpy import read_model_description

    from harness.description.plan import converted

    path = fmu_path if fmu_path is not None else FMUS / f"{model}.fmu"
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    values = {}
    for assignment in _inputs.assignments(assignments):
        if "=" not in assignment:
            raise InputError(f"{_inputs.named('overrides').given(repr(assignment))}: expected name=value")
        key, raw = (x.strip() for x in assignment.split("=", 1))
        name = key.split(".", 1)[1] if key.startswith(model + ".") else key
        var = variables.get(name)
        if var is None or var.causality not in ("parameter", "input"):
            known = [v.name for v in variables.values() if v.causality == "parameter"]
            raise InputError(f"{_inputs.named('overrides').item(key)}: {model} has no parameter '{name}'"
                             f"{scene_files.did_you_mean(name, known)} "
                             f"(parameters: {', '.join(known)})")
        value = scene_files.coerce(raw)
        problems = scene_files.value_findings(f"{model}.{name}", var, value)     # type, unit's dimension, range
        if problems:
            raise InputError("; ".join(problems))
        values[name] = converted(var, value, key)
    return values


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
             out: Path | str | None = None, rtol=None, signals=None, reference=None,
             notify: Callable[[str, str], None] | None = None, plots: bool = True) -> Validation:
    """Judge NAME against its committed reference traces (or ``reference``), as ``lever validate NAME``: run
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
    signal there (``plots`` false: without the plots).  ``result`` may also be a lever results folder (its traces.csv; judged
    against its reference.csv, the reference made for that run's parameters, unless
    ``reference`` is given).  ``reference``: judge against these traces instead of the
    committed ones - a CSV (a time column and named columns), a lever results folder (its
    reference.csv), or any form ``result`` takes; NAME still says what the signals are (the
    start-up transient, kinds, the driven shaft).  ``repr()`` of what it returns says PASS or
    FAIL, why, and which reference judged."""
    from harness.engine.component import FmuUnusable
    from harness.engine.me_component import NoModelExchange
    from harness.engine.system import SceneInvalid
    from harness.formats import given_traces, reference_traces
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
    overrides = _inputs.assignments(overrides)
    rtol, signals = _inputs.tolerances(rtol, "rtol"), _inputs.names(signals, "signals")
    if tolerance != "lever" and (rtol or signals):
        raise InputError(f"{_inputs.named('rtol')} and {_inputs.named('signals')} set the 'lever' verdict; "
                         f"{_inputs.named('tolerance').typed(tolerance)} is fmpy's band, which has its own figures "
                         "and judges every signal")
    try:
        rules = verdict.parse_rtol(rtol, _inputs.named("rtol"))
    except ValueError as error:
        raise InputError(str(error)) from None
    step = _inputs.step(step)
    out = _inputs.folder(out)
    window = _inputs.window(window)
    given = _inputs.result_traces(result) if result is not None else None
    try:
        ref = reference_traces.read(name)
    except reference_traces.TraceFileError as error:
        raise InputError(str(error)) from None
    own_reference = None          # (traces, what they are) judging instead of the committed reference
    try:
        if reference is not None:
            held = _inputs.result_traces(reference, "reference")
            said = _inputs.named("reference")
            if isinstance(held, Path):
                read = given_traces.read_given(held, "reference", said)
                own_reference = (given_traces.sorted_reference(read, said), f"{read.path} (given)")
            else:
                own_reference = (given_traces.sorted_reference(given_traces.Given(
                    reference_traces.Traces(*held[:2]), Path("(given)")), said), "the traces given")
        if isinstance(given, Path):
            said = _inputs.named("result")
            read = given_traces.read_given(given, "result", said)
            if read.path.name == "traces.csv" and own_reference is None and (read.path.parent / "reference.csv").is_file():
                made = given_traces.read_given(read.path.parent, "reference", said)
                own_reference = (given_traces.sorted_reference(made, said),
                                 f"{made.path}, made for that run's parameters by `lever run`")
            given = read
    except reference_traces.TraceFileError as error:
        raise InputError(str(error)) from None
    if own_reference is not None:
        missing = set(ref.outputs.signals)
        ref = reference_traces.ReferenceTraces(ref.name, ref.kind, own_reference[0], ref.opt, ref.inputs,
                                               ref.description)
        if not set(ref.outputs.signals) & missing:
            raise InputError(f"reference {own_reference[1]}: none of {name}'s signals "
                             f"({', '.join(sorted(missing))}) among its columns ({', '.join(ref.outputs.signals)})")
        span = (float(ref.outputs.times[0]), float(ref.outputs.times[-1]))
        ref.opt = reference_traces.Options(ref.opt.step, span[0], span[1], ref.opt.rel_tol)
    if isinstance(given, given_traces.Given):
        judged = reference_traces.Result(given.traces.times, given.traces.signals, f"from {given.path}")
        given = given.path
    elif given is not None:
        times, traces, how = given
        judged = reference_traces.Result(times, traces, how, failure=getattr(result, "failure", None))
    else:
        if fmu_file is None:
            build()
        if ref.kind == "fmu":
            if master or step:
                raise InputError(f"{_inputs.named('master')}/{_inputs.named('step')}: {label} is an FMU run "
                                 "stand-alone at its _ref.opt step")
            try:
                judged = reference_traces.run_fmu(name, ref, fmu_start_values(name, overrides, fmu_path=fmu_file),
                                                  fmu_path=fmu_file)
            except FmuUnusable as error:     # no binary here, or it refused to instantiate: bad input
                raise InputError(f"{label}: {error}") from None
        else:
            spec = load(name, overrides)
            if master:
                check_masters(master)
            check_agreement(spec, master=master, step=step)
            # a long run says how long, from its own pace, once it has one (as ``lever run``)
            watch = PaceWatch(spec.experiment.stop, lambda message: (notify or warn_note)("note", message))
            try:
                judged = reference_traces.run_scene(spec, master, step, observer=watch)
            except (SceneInvalid, NoModelExchange) as error:
                raise InputError(str(error)) from None
    start, stop = ref.opt.start, ref.opt.stop
    if window is not None:
        low, high = window
        start = start if low is None else low
        stop = stop if high is None else high
        if not (ref.opt.start <= start < stop <= ref.opt.stop):
            shown = ":".join(str(side) if side is not None else "" for side in window)
            raise InputError(f"{_inputs.named('window').typed(shown)}: must lie in the reference's span, "
                             f"{ref.opt.start:g} ... {ref.opt.stop:g} s, with START < STOP")
    if tolerance == "lever":
        _check_chosen(signals, rules, ref.outputs.signals, judged.traces)
        try:
            settings = verdict.settings_of(ref)
            findings = verdict.judge(judged.times, judged.traces, ref.outputs.times, ref.outputs.signals,
                                     window=(start, stop), transient=settings.transient,
                                     rtol=verdict.Tolerances([settings.rules, rules]), signals=signals,
                                     kinds=settings.kinds, rotation_signal=settings.rotation_signal, name=label,
                                     units=settings.units)
        except ValueError as error:
            raise InputError(str(error)) from None
        bands = {}
        findings.reference = _reference_said(ref, own_reference, findings)
        if own_reference is None:
            findings.notes += given_traces.provenance_notes(
                ref, given if isinstance(given, Path) else getattr(result, "summary", None), overrides, master, step)
    else:
        try:
            findings, bands = validation.compare_span(label, judged.times, judged.traces, ref.outputs.times,
                                                      ref.outputs.signals, validation.TOLERANCES[tolerance], start,
                                                      stop, (ref.opt.start, ref.opt.stop))
        except validation.TooSparse as error:
            raise InputError(str(error)) from None
    if judged.failure:
        findings.problems.append(f"the run failed: {judged.failure}")
    if out is not None:
        from harness.formats import validation_files

        validation_files.write_validation(out, findings, bands, judged, ref, write_result=result is None,
                                          plots=plots)
    return Validation(label, findings, bands, judged, ref, Path(out) if out is not None else None)


def _check_chosen(signals: list[str], rules: list, reference: dict, columns) -> None:
    """InputError naming ``signals`` or ``rtol`` as the caller did, for a chosen signal the
    reference or the result lacks, or a tolerance for a signal or kind the reference does not
    know (the verdict refuses them too, naming the command line's options)."""
    from harness.judges import tolerances, validation

    unknown = [s for s in signals if s not in reference]
    if unknown:
        raise InputError(f"{_inputs.named('signals').given(', '.join(unknown))}: not a signal of the reference (its "
                         f"signals: {', '.join(reference)})")
    mapping = validation.match_columns(list(reference), [str(c) for c in columns])[0]
    absent = [s for s in signals if s not in mapping]
    if absent:
        raise InputError(f"{_inputs.named('signals').given(', '.join(absent))}: not in the result (its columns: "
                         f"{', '.join(map(str, columns)) or 'none'})")
    targets = tolerances.Tolerances([rules]).unknown_targets(list(reference))
    if targets:
        raise InputError(f"{_inputs.named('rtol')}: tolerance for {', '.join(targets)}: neither a signal of the "
                         f"reference nor a kind (kinds: {', '.join(tolerances.KINDS)}; signals: "
                         f"{', '.join(reference)})")


def _reference_said(ref, own_reference, findings) -> str:
    """Which reference judged, how dense it is and its own error, in one line."""
    from harness.judges import sampled

    what = own_reference[1] if own_reference else (
        f"the committed {ref.name}_ref.csv ({'the exact response' if ref.kind == 'fmu' else 'the monolithic solver'}, "
        f"rtol {ref.opt.rel_tol:g})")
    errors = [s.reference_error for s in findings.signals if s.reference_error == s.reference_error]
    worst = max(findings.signals, key=lambda s: s.reference_error / (s.power.band if s.power and s.power.band
                                                                      else 1.0), default=None) if errors else None
    own = (f"; between its samples it errs by up to {worst.reference_error:.2g} on {worst.name}, estimated"
           + (f": {100 * worst.reference_error / worst.power.band:.2g} % of its tube" if worst.power else "")
           if worst is not None else "")
    return f"{what}, {len(ref.outputs.times)} samples {sampled.spacing(ref.outputs.times)}{own}"


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
                  out: Path | str | None = None, rtol=None, signals=None, reference=None,
                  notify: Callable[[str, str], None] | None = None, plots: bool = True) -> Iterator[Validation]:
    """``lever validate NAMES``: ``validate`` for each name (none: every reference), in
    ``out`` (one name) or ``out/<name>`` (default results/validate/<name>); input checked
    and the FMUs built before the first."""
    from harness.paths import RESULTS

    names = _inputs.names(names, "names")
    if not names and result is not None:     # a lever results folder says which scene it ran
        names = [_scene_of_run(result)]
    if reference is not None and result is None:
        raise InputError(f"{_inputs.named('reference')}: judges a {_inputs.named('result')} (a CSV or a lever results "
                         "folder); a run lever validate makes itself is judged against NAME's committed reference")
    chosen = reference_names(names)
    if result is not None and len(chosen) != 1:
        raise InputError(f"{_inputs.named('result')}: name exactly one reference the CSV is to be compared with "
                         f"(e.g. {_one_reference_named()})")
    span = _inputs.window(window)
    step = _inputs.step(step)
    if result is None and any(_fmu_file(name) is None for name in chosen):
        build()
    for name in chosen:
        folder = name
        if _fmu_file(name) is not None:       # results/validate/<Model>-fmi<major version>
            model, version = fmu_file_model(_fmu_file(name))
            folder = f"{model}-fmi{version.split('.')[0]}"
        target = out if (out and len(chosen) == 1) else Path(out or RESULTS / "validate") / folder
        yield validate(name, overrides=_inputs.assignments(overrides), master=master, step=step, result=result,
                       tolerance=tolerance, window=span, out=target, rtol=rtol, signals=signals, reference=reference,
                       notify=notify, plots=plots)


def _scene_of_run(result) -> str:
    """The scene a lever results folder (or a traces.csv in one) ran, from its summary.json."""
    import json

    folder = Path(result) if Path(result).is_dir() else Path(result).parent
    try:
        return str(json.loads((folder / "summary.json").read_text())["scene"])
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"{_inputs.named('result').typed(str(result))}: name the reference it is to be compared "
                         f"with (e.g. {_one_reference_named()}); no lever summary.json beside it says which scene it "
                         "ran") from None


def _one_reference_named() -> str:
    """A result judged against a named reference, as the caller writes it."""
    return ("lever validate --result run.csv kavz685" if _inputs.named("result").is_option
            else "validate_each(['kavz685'], result='run.csv')")


def references(names: Iterable[str] = (), update: bool = False, until: float | None = None) -> Iterator[ReferenceCheck]:
    """``lever reference``: regenerate each reference trace (``names``: FMUs or scenes; none:
    all) and compare it with the committed one; ``update``: write the stale ones.
    ``until`` [s]: regenerate and compare each only up to that time (quicker; a change that
    shows only later is not seen), never with ``update``."""
    from harness.formats import reference_traces
    from harness.judges.monolithic import ReferenceUnavailable

    if until is not None and update:
        raise InputError("until: a reference is updated whole; check up to a time, or update without it")
    if until is not None and not (_math.isfinite(until) and until > 0):
        raise InputError(f"until = {until:g} s: a time after the start, above 0 s")
    for name in reference_names(names):
        try:
            fresh = reference_traces.generate(name, until)
        except (ReferenceUnavailable, scene_files.SceneError) as error:
            yield ReferenceCheck(name, "unavailable", reason=str(error))
            continue
        except reference_traces.SpanError as error:
            raise InputError(f"until: {error}") from None
        try:
            committed = reference_traces.read(name)
        except reference_traces.TraceFileError:
            committed = None
        if committed is not None and until is not None:
            committed = reference_traces.head(committed, until)
        diff = reference_traces.difference(committed, fresh)
        if diff.current:
            yield ReferenceCheck(name, "current")
            continue
        if update:
            reference_traces.write(fresh)
        yield ReferenceCheck(name, "updated" if update else "stale", list(diff.problems), list(diff.changes),
                             folder=reference_traces.paths(name)["ref"].parent)
