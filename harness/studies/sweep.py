"""``lever sweep``: the monograph's parameter studies (Figs. 3.15-3.18, 4.8, 4.12) rerun
with the project's model, with what the monograph reports overlaid, and a trend report
that says, with the numbers, which of its qualitative findings (docs/physics.md#what-the-monograph-reports) the
model reproduces.

A sweep is a set of *axes*; each varies one quantity of a base scene (default
``kavz685``) over the range the monograph studies (docs/physics.md#kavz-685), at the conditions of the figure it
mirrors, and records means and amplitudes ``A = (max - min)/2`` of the shafts' speeds,
accelerations and torques after the start-up transient.  The cases compute by the
monograph's index (``A_w1``: 1 the drive, 2 the driven shaft, as its figures are keyed);
what sweep.json, sweep.md and the caller get names each signal as the traces do
(``A_engine.w``, ``mean_coupling.tau2``: ``published``).  Cases run on local processes
(``concurrent.futures``) or on a Dask cluster (``address``); each finished or failed case
is kept in a :class:`harness.studies.cases.CaseLog`, so a killed sweep resumes where it stopped
and one failing case (recorded with its diagnosis) does not cost the others.  The trends are
judged in ``sweep_trends``, the report written by ``sweep_report``; the axes are
``sweep_axes``'.
"""
from __future__ import annotations

import time as clock
import traceback
from pathlib import Path

from harness.judges import metrics
from harness.description import scene as scenes
from harness.description.arguments import SET, Argument
from harness.engine import interrupt
from harness.studies.cases import CALIBRATION_STEPS, FAILED, CaseLog, case_key, collect, duration_text, step_cost
from harness.studies.sweep_axes import Axis, default_axes, select, thin
from harness.studies.sweep_report import published, signal_key, write
from harness.studies.sweep_trends import trends
from harness.paths import FMUS, RESULTS

SHORT = ("w1", "w2", "a1", "a2", "tau1", "tau2")


# ----------------------------------------------------------------------------------------
# One case (runs in a worker process or on a Dask worker: plain data in, plain data out)


def run_case(case: dict) -> dict:
    """Simulate one case and return its statistics, or its failure with a diagnosis.
    Never raises: a worker's exception would lose the diagnosis on the way back."""
    from harness.engine.run import simulate

    started = clock.perf_counter()
    try:
        spec = scenes.load(case["scene"]).with_overrides(case["overrides"])
        result = simulate(spec, fmu_dir=Path(case.get("fmu_dir", FMUS)))
        if not result.ok:
            return {"status": FAILED, "error": result.failure, "where": f"simulate ({result.failure_stage})"}
        names = metrics.signals(spec)
        stats = metrics.statistics(result.times, result.traces, [names[k] for k in SHORT], spec.experiment.transient)
        out = {"status": "ok", "wall_s": clock.perf_counter() - started}
        for k in SHORT:
            out[f"A_{k}"] = stats[names[k]]["amplitude"]
            out[f"mean_{k}"] = stats[names[k]]["mean"]
        out["mean_w"] = 0.5 * (out["mean_w1"] + out["mean_w2"])
        out["mean_tau"] = 0.5 * (abs(out["mean_tau1"]) + abs(out["mean_tau2"]))
        for q in ("w", "a", "tau"):
            out[f"dA_{q}"] = out[f"A_{q}2"] - out[f"A_{q}1"]
        out["unevenness_1"] = stats[names["w1"]].get("unevenness")
        out["unevenness_2"] = stats[names["w2"]].get("unevenness")
        return out
    except Exception as error:  # noqa: BLE001 - recorded as the case's diagnosis
        frame = traceback.extract_tb(error.__traceback__)[-1]
        return {"status": FAILED, "error": f"{type(error).__name__}: {error}",
                "where": f"{Path(frame.filename).name}:{frame.lineno} in {frame.name}"}


def plan(axes: list[Axis], scene: str = "kavz685", stop: float | None = None, extra: list[str] | None = None,
         fmu_dir: Path = FMUS) -> list[dict]:
    """Every case of the sweep: axis, value, the scene assignments and the log key."""
    cases = []
    tail = list(extra or []) + ([f"experiment.stop={stop}"] if stop else [])
    for axis in axes:
        for value in axis.values:
            overrides = axis.overrides(value) + tail
            cases.append({"axis": axis.name, "value": list(value) if isinstance(value, tuple) else value,
                          "x": axis.x(value), "scene": scene, "overrides": overrides, "fmu_dir": str(fmu_dir),
                          "key": case_key(scene, *overrides)})
    return cases


def sweep(axes: list[Axis] | None = None, out: Path | None = None, scene: str = "kavz685",
          stop: float | None = None, extra: list[str] | None = None, workers: int | None = None,
          dask: str | None = None, progress: bool = True, resume: bool = True, fmu_dir: Path = FMUS) -> dict:
    """Run (or resume) a sweep and write ``sweep.md``, ``sweep.json`` and a plot per axis
    into ``out``.  Returns the results: {"cases": [...], "trends": [...]}.  Ctrl-C stops
    it at once with ``Interrupted``: the cases under way are logged as interrupted (run
    again on resuming), the finished ones kept; no report is written."""
    with interrupt.deferred():
        return _sweep(axes, out, scene, stop, extra, workers, dask, progress, resume, fmu_dir)


def _sweep(axes, out, scene, stop, extra, workers, dask, progress, resume, fmu_dir) -> dict:
    axes = axes or default_axes()
    out = Path(out or RESULTS / "sweep")
    cases = check(axes, scene, stop, extra, fmu_dir)
    # the code that runs the cases (the physics among it) is in every case log's fingerprint
    fingerprint = {"scene": scene, "scene_text": scenes.resolve(scene).read_text(), "stop": stop,
                   "extra": list(extra or [])}
    log = CaseLog(out, fingerprint, resume=resume)
    pending = [c for c in cases if c["key"] not in log]
    pending = list({c["key"]: c for c in pending}.values())         # one run per distinct case
    if pending and progress and not dask:
        import sys
        print(f"sweep: {len(pending)} cases to run; {duration_text(estimated_seconds(pending, workers), NARROW)}",
              file=sys.stderr, flush=True)
    bar = _bar(len(cases), len(cases) - len(pending), dask) if progress else None
    if pending:
        if dask:
            _run_dask(pending, log, dask, bar)
        else:
            _run_local(pending, log, workers, bar)
    if bar is not None:
        bar.close()
    results = []
    for case in cases:
        entry = dict(case)
        entry.pop("fmu_dir", None)
        entry["result"] = log.get(case["key"]) or {"status": FAILED, "error": "not run"}
        results.append(entry)
    report = {"scene": scene, "stop": stop, "cases": results, "trends": trends(axes, results)}
    return write(out, axes, report, metrics.signals(scenes.load(scene)))


#: how to make a sweep shorter, said with its estimate when it is long
NARROW = "--axis, --thin or --stop make it shorter"

def estimated_seconds(pending: list[dict], workers: int | None = None) -> float:
    """How long the ``pending`` cases will take on ``workers`` local processes, about: the
    first case's set-up and its time a step, from two short runs of it timed now, times
    every case's steps.  A case that fails ends early: an estimate, not a promise."""
    import os

    from harness.engine.run import simulate

    first = pending[0]
    base = scenes.load(first["scene"])
    spec = base.with_overrides(first["overrides"])

    def timed(steps: int) -> float:
        e = spec.experiment
        short = spec.with_overrides([f"experiment.stop={e.start + steps * e.step!r}", "experiment.transient=0"])
        started = clock.perf_counter()
        simulate(short, fmu_dir=Path(first.get("fmu_dir", FMUS)))
        return clock.perf_counter() - started

    timed(CALIBRATION_STEPS[0])      # the first run pays for imports and loading the FMUs
    setup, per_step = step_cost(timed)
    total = 0.0
    for case in pending:
        e = base.with_overrides(case["overrides"]).experiment
        total += setup + per_step * (e.stop - e.start) / e.step
    workers = workers or max(1, min(len(pending), os.cpu_count() or 1))
    return total / max(1, min(workers, len(pending)))


def check(axes: list[Axis], scene: str = "kavz685", stop: float | None = None, extra: list[str] | None = None,
          fmu_dir: Path = FMUS, named: tuple[Argument, Argument] = (Argument("--stop"), SET)) -> list[dict]:
    """The sweep's cases (``plan``), each checked as a run would check it: a bad scene,
    assignment or experiment is a ``SceneError`` before anything runs, naming ``stop`` and
    ``extra`` as ``named`` (the command line's ``--stop`` and ``--set``, or the API's)."""
    spec = scenes.load(scene).with_overrides(list(extra or []), named[1])
    cases = plan(axes, scene, stop, extra, fmu_dir)
    for case in cases:
        _check_experiment(spec.experiment, spec.with_overrides(case["overrides"]).experiment, stop, named)
    return cases


def _check_experiment(scene: scenes.Experiment, e: scenes.Experiment, stop: float | None,
                      named: tuple[Argument, Argument]) -> None:
    """Refuse, before anything runs, a case whose experiment no run could take.  A sweep
    compares steady amplitudes, so a --stop within the scene's start-up transient is
    refused, not met by shortening the transient as `lever run --stop` does (that would
    judge the start-up)."""
    findings = scenes.experiment_findings(e)
    if stop is not None and (e.transient_note is not None or (findings and not 0.0 <= e.transient < e.stop - e.start)):
        raise scenes.SceneError(
            f"{named[0].given(f'{stop:g} s')}: the scene leaves its first experiment.transient = {scene.transient:g} s "
            f"out of the amplitudes, so a case must run past it (allowed: {named[0]} > "
            f"{scene.start + scene.transient:g} s; or lower the transient with "
            f"{named[1].item('experiment.transient')}=...)")
    if findings:
        raise scenes.SceneError("; ".join(findings))


def _bar(total, done, dask):
    from tqdm import tqdm
    return tqdm(total=total, initial=done, desc="sweep" + (" [dask]" if dask else ""), unit="case", leave=False)


def _run_local(pending, log, workers, bar):
    import concurrent.futures as cf
    import multiprocessing
    import os

    workers = workers or max(1, min(len(pending), os.cpu_count() or 1))
    # fork: the workers leave with os._exit, skipping pythonfmu's fragile native teardown.
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as pool:
        futures = {pool.submit(run_case, case): case for case in pending}

        def record(case, result):
            log.record(case["key"], result)
            if bar is not None:
                bar.update(1)

        collect(pool, futures, log, lambda case: case["key"],
                lambda error: {"status": FAILED, "error": f"{type(error).__name__}: {error}", "where": "worker process"},
                record)


def _run_dask(pending, log, address, bar):
    from distributed import Client, as_completed

    with Client(address, timeout="30s") as client:
        futures = {client.submit(run_case, case, pure=False, key=f"lever-sweep-{i}-{case['key'][:40]}"): case
                   for i, case in enumerate(pending)}
        finishing = as_completed(list(futures))
        while not finishing.is_empty():
            if interrupt.requested():       # Ctrl-C: the unfinished cases are cancelled, not done
                unfinished = [f for f in futures if not f.done()]
                under_way = _executing(client, unfinished)
                client.cancel(unfinished)
                for future in unfinished:
                    if future.key in under_way:
                        log.interrupted(futures[future]["key"])
                interrupt.check()
            batch = finishing.next_batch(block=False)
            if not batch:
                clock.sleep(0.2)
            for future in batch:
                case = futures[future]
                try:
                    result = future.result()
                except Exception as error:  # noqa: BLE001 - a lost worker, a cancelled task
                    result = {"status": FAILED, "error": f"{type(error).__name__}: {error}", "where": "dask worker"}
                log.record(case["key"], result)
                if bar is not None:
                    bar.update(1)


def _executing(client, futures) -> set:
    """The keys of ``futures`` a worker is running now (not those queued on a worker):
    Dask's call stacks are of running tasks only."""
    try:
        stacks = client.call_stack(keys=[f.key for f in futures])
    except Exception:  # noqa: BLE001 - a lost scheduler: nothing is known to be under way
        return set()
    return {key for per_worker in stacks.values() for key in per_worker}


__all__ = ["Axis", "default_axes", "plan", "check", "run_case", "sweep", "trends", "select", "thin", "published",
           "signal_key"]
