"""The studies from Python, each what its command prints, as values: the benchmark, the
stability map, the sweeps, the documented studies, the measured data, the engines and
hosts compared, the fingerprints; a study stopped by Ctrl-C says what its case log kept."""
from __future__ import annotations

import contextlib as _contextlib
import math as _math
from pathlib import Path
from typing import Callable, Iterable, Iterator

from harness.api import inputs as _inputs
from harness.api.building import build
from harness.api.choices import check_masters, checked_plan, claimed_folder, load
from harness.api.inputs import InputError
from harness.api.results import BenchResult, Returned, ReturnedTuple, StabilityMapResult
from harness.description import scene as scene_files
from harness.paths import FMUS


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


def bench(scene: str | Path | scene_files.Scene = "kavz685", *, repeats: int = 3, only: Iterable[str] = (),
          peers: bool = True, monolithic: bool = True, out: Path | str | None = None, resume: bool = True,
          progress: Callable[[str], None] | None = None, claimed: bool = False, fmi_editions: bool = True) -> dict:
    """The work-precision benchmark of ``lever bench``: every master (``only``: these), the
    peers and the monolithic solutions over a range of steps, and (``fmi_editions``) the
    FMUs' FMI 2.0 and FMI 3.0 editions side by side; returns the result (its ``claims``:
    time at the target error, best master, ...; ``fmi_editions``) and writes bench.csv,
    bench.md, bench.json and work_precision.png to ``out`` (default results/bench/<scene>),
    resuming from its cases.jsonl unless ``resume`` is false."""
    from harness.studies import bench as benchmark

    spec = load(scene)
    repeats = _inputs.count(repeats, "repeats", 1, 20)
    only = _inputs.names(only, "only")
    check_masters(*only, argument="only")
    out = _inputs.folder(out)
    try:
        benchmark.check_plan(spec, list(only))      # refuses unknown masters before anything runs
    except ValueError as error:
        raise InputError(str(error)) from None
    build()
    out = Path(out) if out is not None else benchmark.default_out(spec)
    with claimed_folder(out, already=claimed) as out, _resumable(out):
        result = benchmark.bench(spec, repeats, only=list(only), peers=peers, monolithic=monolithic,
                                 progress=progress or (lambda *_: None), out=out, resume=resume,
                                 fmi_editions=fmi_editions)
        result["written"] = benchmark.write(out, result)
    result["summary"] = benchmark.summary_lines(result)
    return BenchResult(result)




def stability_map(scene: str | Path | scene_files.Scene = "kavz685", *, stiffnesses: Iterable[float] = (),
                  dampings: Iterable[float] = (), h_omegas: Iterable[float] = (), masters: Iterable[str] = (),
                  dense: bool = False, min_steps: int = 500, refine: bool = True, jobs: int = 1,
                  resume: bool = True, out: Path | str | None = None,
                  progress: Callable[[str], None] | None = None) -> StabilityMapResult:
    """``lever stability``: every case of the map classified against the edges the linear
    analysis predicts (empty sequences: the default plan's, ``dense``: denser), for any scene
    with our LeverCoupling between two shafts (FMUs of one's own are measured first:
    ``harness.judges.port_probe``; ``progress`` hears a long probe's estimate); writes
    stability.md, stability.csv, stability_map.png and cases.jsonl to ``out`` (default
    results/stability/<scene>), resuming from the case log unless ``resume`` is false.
    Returns ``result``, ``agreement`` and ``written`` (a dict whose ``repr()`` says what
    ``lever stability`` prints).

    Where such an FMU refuses the probe runs, the map runs unpredicted: its cases at the
    scene's step times 0.1 ... 100, ``["agreement"]["no_prediction"]`` the sentence naming
    the FMU and what it refused, ``["agreement"]["advice"]`` what the observed runs say."""
    from harness.description import scene_kinds
    from harness.studies import stability_report, stabilitymap

    out = _inputs.folder(out)
    min_steps = _inputs.count(min_steps, "min_steps", 16, 100000)
    jobs = _inputs.count(jobs, "jobs", 1, 64)
    stiffnesses, dampings, h_omegas = ([_inputs.number(v, label) for v in values] for label, values in (
        ("stiffnesses", stiffnesses), ("dampings", dampings), ("h_omegas", h_omegas)))
    masters = _inputs.names(masters, "masters")
    try:
        spec = load(scene)
    except (scene_files.SceneError, ValueError) as error:
        raise InputError(str(error)) from None
    build()
    try:
        plan = stabilitymap.default_plan(spec, dense, say=progress)
    except (scene_kinds.NotADriveline, ValueError) as error:
        raise InputError(str(error)) from None
    stiffnesses, dampings, h_omegas, masters = list(stiffnesses), list(dampings), list(h_omegas), list(masters)
    if h_omegas and not plan.predicted:
        _, why = stabilitymap.linear_model(spec)
        raise InputError(f"--h-omega: this map has no h*omega_n to run at, omega_n being unknown.  {why}  Leave "
                         f"--h-omega out: the cases then run at the scene's step times "
                         f"{', '.join(f'{r:g}' for r in plan.step_ratios)}")
    unknown = [m for m in masters if m not in stabilitymap.FIXED_STEP_MASTERS]
    if unknown:
        raise InputError(f"{_inputs.named('masters').given(', '.join(unknown))}: not a fixed-step master (known: "
                         f"{', '.join(stabilitymap.FIXED_STEP_MASTERS)})")
    for name, values, low in (("stiffnesses", stiffnesses, 0.0), ("h_omegas", h_omegas, 0.0)):
        if any(not (_math.isfinite(v) and v > low) for v in values):
            raise InputError(f"{_inputs.named(name)}: values must be finite and > {low:g}")
    if any(not (_math.isfinite(v) and v >= 0) for v in dampings):
        raise InputError(f"{_inputs.named('dampings')}: values must be finite and >= 0")
    plan.stiffnesses = sorted(set(stiffnesses)) or plan.stiffnesses
    plan.dampings = sorted(set(dampings), reverse=True) or plan.dampings
    plan.h_omegas = sorted(set(h_omegas)) or plan.h_omegas
    plan.masters = list(dict.fromkeys(masters)) or plan.masters
    plan.min_steps = min_steps
    plan.refine = refine
    with claimed_folder(out or stabilitymap.default_out(spec)) as out:
        with _resumable(out):
            result = stabilitymap.sweep(spec, plan, out, jobs=jobs, resume=resume, progress=progress)
        written = stability_report.write(out, result)
    return StabilityMapResult(result=result, agreement=stabilitymap.agreement(result), written=written)


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

    extra = _inputs.assignments(overrides)
    _inputs.scene_argument(scene)
    axes = _inputs.names(axes, "axes")
    thin = _inputs.count(thin, "thin", 1, 100)
    workers = None if workers is None else _inputs.count(workers, "workers", 1, 256)
    stop = _inputs.seconds(stop, "stop")
    out = _inputs.folder(out)
    try:
        chosen = sweeps.thin(sweeps.select(list(axes)), thin)
        load(scene).with_overrides(extra, _inputs.named("overrides"))
    except (ValueError, scene_files.SceneError) as error:
        raise InputError(str(error)) from None
    if stop is not None and not stop > 0:
        raise InputError(f"{_inputs.named('stop').given(str(stop))}: must be > 0 s")
    try:
        sweeps.check(chosen, scene, stop, extra, named=(_inputs.named("stop"), _inputs.named("overrides")))
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None
    build()
    checked_plan(load(scene, extra))          # the parameters' types, units and ranges, before any case runs
    out = Path(out or RESULTS / "sweep")
    try:
        with claimed_folder(out), _resumable(out):
            return Returned(sweeps.sweep(chosen, out, scene=scene, stop=stop, extra=extra, workers=workers,
                                         dask=dask, progress=progress, resume=resume))
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def sweep_verdict(trend: dict) -> str:
    """A trend's verdict as ``lever sweep`` prints it."""
    from harness.studies.sweep_trends import NOT_JUDGED

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
                raise InputError(f"{_inputs.named('lags').given(str(lag))}: engine.torque_lag must be in "
                                 "[0, 100] s")
        text = runup.scan(lags) if lags else runup.markdown(runup.table())
        out.mkdir(parents=True, exist_ok=True)
        (out / "runup.md").write_text(text + "\n")
        return ReturnedTuple((text, out / "runup.md"))
    if name not in ("transfer-modes", "reference-agreement"):
        raise InputError(f"no study '{name}' (known: transfer-modes, runup, reference-agreement)")
    if lags:
        raise InputError(f"{_inputs.named('lags')} applies to the runup study only")
    if name == "reference-agreement":
        from harness.studies import reference_agreement

        build()
        text = reference_agreement.study()
        out.mkdir(parents=True, exist_ok=True)
        (out / "reference_agreement.md").write_text(text + "\n")
        return ReturnedTuple((text, out / "reference_agreement.md"))
    from harness.studies import decisions

    build()
    return ReturnedTuple((decisions.transfer_modes(out), out / "transfer_modes.md"))


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
        raise InputError(f"{_inputs.named('stiffness').given(str(stiffness))}: must be > 0 N*m/rad")
    files = list(files) or measurement.default_files()
    _, unusable = measurement.pair_tables(files)
    if unusable:       # the files are at fault, not the model: bad input
        raise InputError("the measurement files cannot be used:\n  - " + "\n  - ".join(unusable))
    build()
    findings = measurement.validate_measured(files, out, stiffness=stiffness, cycles=cycles)
    grades = json.loads((out / "measured.json").read_text())["grades"]
    return Returned(grades=grades, findings=findings, report=out / "measured.md")


def engines(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, engines: Iterable[str] = (),
            step: float | None = None, repeats: int = 3, out: Path | str | None = None,
            progress: Callable[[str], None] | None = None) -> list[Path]:
    """``lever engines``: the scene in every engine that runs our FMUs (``engines``: these),
    error against the monolithic reference and run time; writes engines.md and engines.json
    to ``out`` (default results/engines/<scene>) and returns their paths."""
    from harness import peers
    from harness.studies import engines as comparison

    spec = load(scene, overrides)
    step, repeats, out = _inputs.step(step), _inputs.count(repeats, "repeats", 1, 20), _inputs.folder(out)
    chosen = _inputs.names(engines, "engines") or list(comparison.ENGINES)
    unknown = [n for n in chosen if n not in comparison.ENGINES]
    if unknown:
        raise InputError(f"unknown engine {', '.join(unknown)} (known: {', '.join(comparison.ENGINES)}; "
                         f"{_inputs.named('engines')} chooses the engines)")
    build()
    checked_plan(spec)
    if refused := [said for name in chosen if (said := peers.problem(name, spec, spec.fmu_dir or FMUS))]:
        raise InputError("; ".join(refused) + f" ({_inputs.named('engines')} chooses the engines)")
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
    step, repeats, out = _inputs.step(step), _inputs.count(repeats, "repeats", 1, 20), _inputs.folder(out)
    chosen = tuple(_inputs.names(hosts, "hosts")) or comparison.HOSTS
    unknown = [n for n in chosen if n not in comparison.HOSTS]
    if unknown:
        raise InputError(f"unknown host {', '.join(unknown)} (known: {', '.join(comparison.HOSTS)}; "
                         f"{_inputs.named('hosts')} chooses the hosts)")
    if native_env not in ("bare", "set-up"):
        raise InputError(f"{_inputs.named('native_env').given(repr(native_env))}: bare or set-up")
    if fmu_dir is None:
        build()
    checked_plan(spec, fmu_dir)
    environment = comparison.set_up_environment() if native_env == "set-up" else None
    if refused := comparison.problems(spec, chosen, fmu_dir or spec.fmu_dir or FMUS):
        raise InputError("; ".join(refused) + f" ({_inputs.named('hosts')} chooses the hosts)")
    report = comparison.time_hosts(spec, step, repeats, fmu_dir or spec.fmu_dir or FMUS, chosen, environment,
                                   log=log or (lambda *_: None))
    folder = Path(out) if out else comparison.default_out(spec)
    folder.mkdir(parents=True, exist_ok=True)
    table = comparison.table(report)
    (folder / "hosts.json").write_text(json.dumps(report, indent=1))
    (folder / "hosts.md").write_text(table)
    return Returned(report=report, table=table, written=[folder / "hosts.md", folder / "hosts.json"])


def fingerprints(names: Iterable[str] = (), masters: Iterable[str] = (), stop: float | None = 0.2
                 ) -> Iterator[tuple[str, str, int, str]]:
    """``lever fingerprint``: ``(scene, master, rows, SHA-256 of the traces)`` for every
    committed scene (or ``names``) and master (or ``masters``), each run for at most
    ``stop`` seconds (0 or None: its own length)."""
    from harness.studies import fingerprint

    masters = _inputs.names(masters, "masters")
    names = _inputs.names(names, "names")
    check_masters(*masters, argument="masters")
    stop = _inputs.seconds(stop, "stop")
    if stop is not None and not stop >= 0:
        raise InputError(f"{_inputs.named('stop').given(str(stop))}: must be >= 0 s (0: each scene's own length)")
    build()
    try:
        yield from fingerprint.fingerprints(list(names) or None, masters or None, stop or None)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None
