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
and one failing case (recorded with its diagnosis) does not cost the others.
"""
from __future__ import annotations

import json
import re
import time as clock
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.formats import plotting
from harness.judges import metrics
from harness.description import scene as scenes
from harness.engine import interrupt
from harness.studies.cases import CALIBRATION_STEPS, FAILED, CaseLog, case_key, collect, duration_text, step_cost
from harness.paths import DATA, FMUS, RESULTS

SHORT = ("w1", "w2", "a1", "a2", "tau1", "tau2")


@dataclass
class Axis:
    """One study: ``quantity`` takes ``values``; ``overrides(value)`` are the scene
    assignments of a case, on top of ``base`` (the figure's conditions)."""
    name: str
    figure: str
    quantity: str                      # label with unit
    values: list
    base: list[str]
    assign: str                        # "component.parameter" the value goes to ("load" pairs: mean, bound)
    #: what the monograph reports: quantity key -> [(x, value or (low, high)), ...]
    reported: dict = field(default_factory=dict)
    note: str = ""

    def overrides(self, value) -> list[str]:
        if self.assign == "load":
            mean, bound = value
            return self.base + [f"load.mean_torque={mean}", f"load.random_amplitude={bound}"]
        if self.assign == "coupling.misalignment":
            return self.base + [f"coupling.misalignment={value} deg"]
        return self.base + [f"{self.assign}={value}"]

    def x(self, value) -> float:
        return float(value[0]) if self.assign == "load" else float(value)


FIG_317 = ["load.mean_torque=150", "load.random_amplitude=11"]     # Figs. 3.17-3.18: 150 +- 11 N*m, 15 deg
#: Load points Mm +- dM the monograph names (sections 3.3, 4.2), chosen with dM growing with
#: Mm as along its Fig. 3.15 (100 +- 8.8 ... 500 +- 21.9): the amplitudes follow dM too.
LOADS = [(100.0, 8.8), (150.0, 11.5), (225.4, 18.3), (350.0, 21.0), (500.0, 21.9), (550.0, 24.1)]
LOADS_412 = [(65.4, 5.3), (150.0, 11.5), (320.0, 12.0), (450.0, 21.5)]


def default_axes() -> list[Axis]:
    return [
        Axis("load", "3.15, 3.16", "mean load Mc [N*m]", LOADS, [], "load",
             {"A_w1": [(100, 0.65), (500, 3.94)], "A_w2": [(100, 0.92), (500, 5.18)],
              "A_a1": [(150, 180.0), (500, 380.0)], "A_a2": [(150, 210.0), (500, 510.0)],
              "A_tau1": [(500, 43.2)], "A_tau2": [(500, 49.4)],
              "mean_w": [(100, 37.2), (550, 23.4)], "mean_tau": [(100, 78.0), (550, 484.0)]},
             "alpha = 15 deg, load Mm +- dM as the monograph pairs them (dM growing with Mm)"),
        Axis("inertia", "3.16", "driven inertia I2 [kg*m^2]", [0.08, 0.12, 0.161, 0.22, 0.30], [], "load.inertia",
             {"mean_w": [(0.30, 33.9)], "mean_tau": [(0.30, 281.0)]},
             "alpha = 15 deg, load 107.5 +- 8.8 N*m; the curve's start values are garbled in the source"),
        Axis("stiffness", "3.17", "stiffness c [N*m/rad]", [200.0, 450.0, 715.4, 820.0, 1000.0, 1250.0], FIG_317,
             "coupling.stiffness",
             {"dA_w": [(200, 1.26), (820, 0.78)], "dA_a": [(200, 980.0), (820, 395.0)],
              "dA_tau": [(200, 7.1), (820, 13.2)]},
             "alpha = 15 deg, load 150 +- 11 N*m; the printed dA_M 'decreases from 7.1 to 13.2' is overlaid as printed"),
        Axis("damping", "3.17", "damping b [N*m*s/rad]", [0.5, 2.0, 4.0, 6.35, 8.5, 10.0], FIG_317, "coupling.damping",
             {"dA_w": [(10, 0.38)], "dA_a": [(10, 128.0)], "dA_tau": [(10, 12.8)]},
             "alpha = 15 deg, load 150 +- 11 N*m"),
        Axis("misalignment", "3.18", "misalignment alpha [deg]", [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0], FIG_317,
             "coupling.misalignment",
             {"dA_w": [(10, 0.28), (35, 1.37)], "dA_a": [(10, 225.0), (35, 98.0)], "dA_tau": [(10, 11.0), (35, 56.0)]},
             "load 150 +- 11 N*m; the printed dA_a '(225 ... 98)' is overlaid as printed"),
        Axis("stiffness_measured", "4.8", "stiffness c [N*m/rad]", [450.0, 650.0, 750.0, 900.0, 1200.0],
             ["load.mean_torque=225.4", "load.random_amplitude=18.3", "coupling.misalignment=16 deg"],
             "coupling.stiffness", {}, "alpha = 16 deg, load 225.4 +- 18.3 N*m; overlaid: the amplitudes of the "
             "measured mean torque curves (Tables 4.2-4.11, about 220 N*m, angle-periodic load)"),
        Axis("load_alpha0", "4.12", "mean load Mc [N*m]", LOADS_412, ["coupling.misalignment=0"], "load",
             {"A_tau1": [(65.4, (6.3, 8.1)), (320, (7.5, 9.1))]}, "alpha = 0 (measured ranges, Fig. 4.11)"),
        Axis("load_alpha5", "4.12", "mean load Mc [N*m]", LOADS_412, ["coupling.misalignment=5 deg"], "load",
             {"A_tau1": [(450, (30.1, 39.3))], "A_tau2": [(320, (32.0, 34.2)), (420, (35.4, 46.1))]},
             "alpha = 5 deg (measured ranges, Figs. 4.10-4.11)"),
    ]


def measured_amplitudes() -> dict:
    """A of the measured mean drive and driven torque curves per grade, from the data
    files (for the Fig. 4.8 overlay): {"A_tau1": [(c, A)], "A_tau2": [...]}."""
    from harness.studies.measured import amplitude, pair_tables

    pairs, _ = pair_tables([DATA / "monograph"])
    out = {"A_tau1": [], "A_tau2": []}
    for drive, driven in pairs:
        if drive.stiffness:
            out["A_tau1"].append((drive.stiffness, amplitude(drive.mean_curve)))
            out["A_tau2"].append((drive.stiffness, amplitude(driven.mean_curve)))
    return out


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


#: a key or a word of the monograph's index: A_w1, mean_tau2 (1 the drive, 2 the driven shaft), unevenness_1
_INDEXED = re.compile(r"\b(?:(A|mean)_(w|a|tau)([12])|unevenness_([12]))\b")


def signal_key(key: str, names: dict) -> str:
    """``key`` (or every such word of a text) under the traces' signal names: ``A_w1`` ->
    ``A_engine.w``, ``mean_tau2`` -> ``mean_coupling.tau2``, ``unevenness_2`` ->
    ``unevenness_load.w`` (``names``: ``metrics.signals`` of the scene); other keys as they are."""
    def named(m):
        if m.group(4):
            return f"unevenness_{names['w' + m.group(4)]}"
        return f"{m.group(1)}_{names[m.group(2) + m.group(3)]}"
    return _INDEXED.sub(named, key)


def published(report: dict, names: dict) -> dict:
    """The report as written and returned: each case's amplitudes, means and unevenness,
    the trends' quantities and numbers under the traces' signal names (``signal_key``);
    the differences (``dA_tau``) and the shafts' common means (``mean_w``) keep theirs."""
    cases = [{**c, "result": {signal_key(k, names): v for k, v in c["result"].items()}} for c in report["cases"]]
    trends_named = [{**t, "holds_for": [signal_key(q, names) for q in t["holds_for"]],
                     "numbers": signal_key(t["numbers"], names)} for t in report["trends"]]
    differences = {f"dA_{q}": signal_key(f"A_{q}2 - A_{q}1", names) for q in ("w", "a", "tau")}
    return {**report, "differences": differences, "cases": cases, "trends": trends_named}


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
          fmu_dir: Path = FMUS) -> list[dict]:
    """The sweep's cases (``plan``), each checked as a run would check it: a bad scene,
    assignment or experiment is a ``SceneError`` before anything runs."""
    spec = scenes.load(scene).with_overrides(list(extra or []))
    cases = plan(axes, scene, stop, extra, fmu_dir)
    for case in cases:
        _check_experiment(spec.experiment, spec.with_overrides(case["overrides"]).experiment, stop)
    return cases


def _check_experiment(scene: scenes.Experiment, e: scenes.Experiment, stop: float | None) -> None:
    """Refuse, before anything runs, a case whose experiment no run could take.  A sweep
    compares steady amplitudes, so a --stop within the scene's start-up transient is
    refused, not met by shortening the transient as `lever run --stop` does (that would
    judge the start-up)."""
    findings = scenes.experiment_findings(e)
    if stop is not None and (e.transient_note is not None or (findings and not 0.0 <= e.transient < e.stop - e.start)):
        raise scenes.SceneError(
            f"--stop {stop:g} s: the scene leaves its first experiment.transient = {scene.transient:g} s out of the "
            f"amplitudes, so a case must run past it (allowed: --stop > {scene.start + scene.transient:g} s; or "
            f"lower the transient with --set experiment.transient=...)")
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


# ----------------------------------------------------------------------------------------
# Trends (docs/physics.md#what-the-monograph-reports) - pure functions of the results


def _series(axis: str, results: list[dict], quantity: str):
    rows = [(r["x"], r["result"][quantity]) for r in results
            if r["axis"] == axis and r["result"].get("status") == "ok"]
    rows.sort()
    return np.array([x for x, _ in rows]), np.array([y for _, y in rows])


def _monotone(y, sign) -> bool:
    return len(y) >= 2 and bool(np.all(sign * np.diff(y) > 0))


#: the smallest relative change over an axis that counts as a trend of a mean
MEANINGFUL = 1e-3


def _span(y) -> float:
    """(max - min) / |mean| of a series."""
    y = np.asarray(y, dtype=float)
    return float((np.max(y) - np.min(y)) / abs(np.mean(y))) if len(y) and np.mean(y) else 0.0


def _moves(y) -> bool:
    return _span(y) > MEANINGFUL


def _nonlinearity(x, y) -> float:
    """Largest deviation from the straight line through the end points, relative to the
    rise between them."""
    if len(x) < 3 or y[-1] == y[0]:
        return float("nan")
    line = y[0] + (y[-1] - y[0]) * (x - x[0]) / (x[-1] - x[0])
    return float(np.max(np.abs(y - line)) / abs(y[-1] - y[0]))


def _fmt_series(x, y, unit="") -> str:
    return ", ".join(f"{xi:g}: {yi:.3g}" for xi, yi in zip(x, y)) + (f" {unit}" if unit else "")


def _verdict(holds: list[str], of: list[str]) -> str:
    return "yes" if len(holds) == len(of) else ("partly" if holds else "no")


#: the fewest cases that ran a verdict rests on: fewer values show no trend (two points
#: are always monotone, and a curve needs three)
MIN_CASES = 3
NOT_JUDGED = "not judged"


def _ran(results: list[dict], axis: str | None = None) -> tuple[int, int]:
    """(cases that ran, cases planned) of ``axis`` (of every axis when None)."""
    rows = [r for r in results if axis is None or r["axis"] == axis]
    return sum(r["result"].get("status") == "ok" for r in rows), len(rows)


def trends(axes: list[Axis], results: list[dict]) -> list[dict]:
    """Each qualitative finding of the monograph (docs/physics.md#what-the-monograph-reports),
    judged on the sweep's numbers: "yes", "partly" (``holds_for`` says for which
    quantities), "no", or "not judged" when fewer than ``MIN_CASES`` of its cases ran,
    with the numbers it rests on.  A finding about the size of a difference ("shrinks")
    is judged on its magnitude: dA = A2 - A1 that goes from +0.03 to -0.9 grew."""
    names = {a.name for a in axes}
    out = []

    def add(trend, holds, of, numbers, ran):
        done, planned = ran
        if done < MIN_CASES:
            out.append({"trend": trend, "reproduced": NOT_JUDGED, "holds_for": [],
                        "numbers": f"not judged: {done} of {planned} cases ran (a verdict needs {MIN_CASES})"})
            return
        if done < planned:
            numbers += f" ({done} of {planned} cases ran)"
        out.append({"trend": trend, "reproduced": _verdict(holds, of), "holds_for": holds, "numbers": numbers})

    ok = [r for r in results if r["result"].get("status") == "ok"]
    lines, holds = [], []
    if ok:
        for q, label in (("w", "speed"), ("a", "acceleration"), ("tau", "torque")):
            less = sum(r["result"][f"A_{q}1"] < r["result"][f"A_{q}2"] for r in ok)
            if less == len(ok):
                holds.append(label)
            lines.append(f"{label}: A1 < A2 in {less} of {len(ok)} cases")
        worst = min(ok, key=lambda r: r["result"]["A_tau2"] - r["result"]["A_tau1"])
        lines.append(f"smallest A_tau2 - A_tau1: {worst['result']['A_tau2'] - worst['result']['A_tau1']:.3g} N*m "
                     f"({worst['axis']} = {worst['x']:g})")
    add("the drive shaft's speed, acceleration and torque fluctuate less than the driven shaft's",
        holds, ["speed", "acceleration", "torque"], "; ".join(lines), _ran(results))
    amplitudes = ["A_w1", "A_w2", "A_a1", "A_a2", "A_tau1", "A_tau2"]
    for axis_name, label in (("load", "load"), ("misalignment", "alpha")):
        if axis_name not in names:
            continue
        parts, holds = [], []
        for q in amplitudes:
            x, y = _series(axis_name, results, q)
            curved = _nonlinearity(x, y)
            if _monotone(y, +1) and curved > 0.05:
                holds.append(q)
            parts.append(f"{q} {_fmt_series(x, y)} (off a straight line by {100 * curved:.0f} % of the rise)")
        add(f"fluctuation amplitudes grow non-linearly with {label}", holds, amplitudes, "; ".join(parts),
            _ran(results, axis_name))
    if "load" in names:
        x, w = _series("load", results, "mean_w")
        add("mean speed falls with load", ["mean speed"] if _monotone(w, -1) else [], ["mean speed"],
            "mean speed [rad/s] at " + _fmt_series(x, w), _ran(results, "load"))
        x, t = _series("load", results, "mean_tau")
        add("mean torque rises with load", ["mean torque"] if _monotone(t, +1) else [], ["mean torque"],
            "mean torque [N*m] at " + _fmt_series(x, t), _ran(results, "load"))
    for axis_name, label in (("stiffness", "stiffer"), ("damping", "more damped")):
        if axis_name not in names:
            continue
        parts, holds = [], []
        for q, unit in (("dA_w", "rad/s"), ("dA_a", "rad/s^2"), ("dA_tau", "N*m")):
            x, y = _series(axis_name, results, q)
            if _monotone(np.abs(y), -1):
                holds.append(q)
            parts.append(f"|{q}| [{unit}] {_fmt_series(x, np.abs(y))}")
        add(f"a {label} elastic element shrinks the drive/driven amplitude difference (|dA|, dA = A2 - A1)",
            holds, ["dA_w", "dA_a", "dA_tau"], "; ".join(parts), _ran(results, axis_name))
    if "inertia" in names:
        x, w = _series("inertia", results, "mean_w")
        _, t = _series("inertia", results, "mean_tau")
        # A change the size of rounding is no trend: the monograph's mean speed falls by 9 % (Fig. 3.16);
        # an angle-locked load part moves the model's by some 0.002 %
        holds = (["mean speed"] if _monotone(w, -1) and _moves(w) else []) + \
            (["mean torque"] if _monotone(t, +1) and _moves(t) else [])
        add("a heavier driven shaft (I2) lowers the mean speed and raises the mean torque (Fig. 3.16)",
            holds, ["mean speed", "mean torque"],
            f"mean speed [rad/s] at I2 {_fmt_series(x, w, '')}; mean torque [N*m] {_fmt_series(x, t)}.  In the model "
            "the steady means are set by the engine characteristic and the mean load alone; I2 enters only the "
            f"fluctuations (the means move by {100 * _span(w):.2g} % and {100 * _span(t):.2g} % over the axis; "
            f"a trend needs {100 * MEANINGFUL:g} %)", _ran(results, "inertia"))
    return out


# ----------------------------------------------------------------------------------------
# Report


def write(out: Path, axes: list[Axis], report: dict, names: dict | None = None) -> dict:
    """sweep.json, sweep.md and a plot an axis of ``report`` (its cases by the monograph's
    index) to ``out``; returns the report as ``published`` under the signals' ``names``
    (default: ``metrics.signals`` of the report's scene)."""
    names = names or metrics.signals(scenes.load(report["scene"]))
    out.mkdir(parents=True, exist_ok=True)
    public = published(report, names)
    (out / "sweep.json").write_text(json.dumps(public, indent=2, default=str))
    results = report["cases"]
    failed = [r for r in results if r["result"].get("status") != "ok"]
    amplitudes = ("A_w1", "A_w2", "A_a1", "A_a2", "A_tau1", "A_tau2")
    lines = [f"# Parameter sweep of the {report['scene']} scene against the monograph's figures", "",
             "Amplitudes A = (max - min)/2 and means after the start-up transient of the drive shaft's "
             f"({names['w1']}, {names['a1']}, {names['tau1']}) and the driven shaft's ({names['w2']}, {names['a2']}, "
             f"{names['tau2']}) signals; dA = A driven - A drive (the monograph's difference, e.g. dA_tau = "
             f"{public['differences']['dA_tau']}).  Each axis varies one quantity at the "
             "conditions of the figure it mirrors.", "", "## Trends (docs/physics.md#what-the-monograph-reports)", "",
             "| trend | reproduced | numbers |", "|---|---|---|"]
    for t in public["trends"]:
        verdict = {"yes": "yes", "partly": "partly: " + ", ".join(t["holds_for"]), "no": "**no**",
                   NOT_JUDGED: NOT_JUDGED}[t["reproduced"]]
        lines.append(f"| {t['trend']} | {verdict} | {_cell(t['numbers'])} |")
    for axis in axes:
        rows = [r for r in results if r["axis"] == axis.name]
        lines += ["", f"## {axis.name} (Fig. {axis.figure}): {axis.quantity}", "", axis.note, "",
                  f"![{axis.name}](sweep_{axis.name}.png)", "",
                  "| value | " + " | ".join(signal_key(k, names).replace("_", " ", 1) for k in amplitudes)
                  + " | mean speed | mean torque | status |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            res = r["result"]
            if res.get("status") == "ok":
                cells = " | ".join(f"{res[k]:.4g}" for k in amplitudes + ("mean_w", "mean_tau"))
                lines.append(f"| {r['x']:g} | {cells} | ok |")
            else:
                lines.append(f"| {r['x']:g} |" + " - |" * 8 + f" failed: {_cell(res.get('error'))} "
                             f"({_cell(res.get('where'))}) |")
        reported = dict(axis.reported)
        if axis.name == "stiffness_measured":
            reported.update(measured_amplitudes())
        if reported:
            lines += ["", "Reported by the monograph: " + "; ".join(
                f"{signal_key(k, names)} " + ", ".join(f"{x:g} -> {_range(v)}" for x, v in pts)
                for k, pts in reported.items())]
            compared = against_monograph(rows, reported)
            if compared:
                lines += ["", "The model beside the monograph (its cases interpolated at the printed points):", ""]
                lines += [f"- {comparison_sentence(c)}" for c in compared]
        _plot(out / f"sweep_{axis.name}.png", axis, rows, reported)
    if failed:
        lines += ["", "## Failed cases", ""] + [f"- {r['axis']} = {r['x']:g}: {_cell(r['result'].get('error'))} "
                                                f"({_cell(r['result'].get('where'))})" for r in failed]
    (out / "sweep.md").write_text("\n".join(lines) + "\n")
    return public


def _cell(text) -> str:
    """``text`` on one line for a Markdown table cell: its lines joined (a multi-line
    error would end the table), pipes escaped."""
    return " ".join(line.strip() for line in str(text).splitlines() if line.strip()).replace("|", "\\|")


def _range(v) -> str:
    return f"{v[0]:g}-{v[1]:g}" if isinstance(v, (tuple, list)) else f"{v:g}"


#: each column of a sweep's plot: the quantity, its label, its unit
PLOT_COLUMNS = (("w", "speed", "rad/s"), ("a", "acceleration", "rad/s^2"), ("tau", "torque", "N*m"))


def _reported_value(v) -> float:
    """A printed value, or the middle of a printed range."""
    return 0.5 * (v[0] + v[1]) if isinstance(v, (tuple, list)) else float(v)


def against_monograph(rows: list[dict], reported: dict) -> list[dict]:
    """The model against each reported amplitude series it can be set beside: per key
    (``A_w1``, ``dA_tau``, ...), the printed values, the model's at the same points (its
    cases interpolated, points outside them left out), how many times larger the printed
    ones are, and whether their signs agree."""
    ok = sorted((r for r in rows if r["result"].get("status") == "ok"), key=lambda r: r["x"])
    x = np.array([r["x"] for r in ok], dtype=float)
    out = []
    for q, label, unit in PLOT_COLUMNS:
        for key in (f"A_{q}1", f"A_{q}2", f"dA_{q}"):
            points = [(px, _reported_value(v)) for px, v in reported.get(key) or ()
                      if len(x) >= 2 and x[0] <= px <= x[-1] or len(x) == 1 and px == x[0]]
            if not points:
                continue
            model = np.interp([px for px, _ in points], x, [r["result"][key] for r in ok])
            printed = np.array([v for _, v in points])
            ratios = np.abs(printed) / np.maximum(np.abs(model), 1e-300)
            out.append({"key": key, "quantity": label, "unit": unit, "x": [px for px, _ in points],
                        "printed": printed.tolist(), "model": model.tolist(),
                        "ratio": (float(ratios.min()), float(ratios.max())),
                        "opposite_sign_at": [px for (px, _), a, b in zip(points, printed, model)
                                             if np.sign(a) != np.sign(b)]})
    return out


def comparison_sentence(c: dict) -> str:
    """One comparison of ``against_monograph`` in words, e.g. 'dA torque: the monograph
    +11 -> +56 N*m, the model -0.16 -> -2.1 N*m: 17-27x larger, of opposite sign'."""
    def series(values):
        return " -> ".join(f"{v:+.3g}" if c["key"].startswith("dA") else f"{v:.3g}" for v in values)

    size = _times(c) + " the model's"
    sign = _sign_words(c)
    name = c["key"].split("_")[0] + " " + c["quantity"] + {"1": " drive", "2": " driven"}.get(c["key"][-1], "")
    return (f"{name}: the monograph {series(c['printed'])} {c['unit']}, the model {series(c['model'])} {c['unit']} "
            f"(at {', '.join(f'{x:g}' for x in c['x'])}): {size}{sign}")


#: printed and model values further apart than this factor share a logarithmic axis
#: (symmetric-logarithmic for differences, which change sign), so both can be read
LOG_RATIO = 10.0


def _scale_for(ax, values) -> None:
    """A logarithmic y-axis when ``values`` span more than ``LOG_RATIO`` or change sign
    (symmetric-logarithmic when any is negative), so that the model and the monograph are
    each readable on one axes."""
    v = np.abs(np.asarray([x for x in values if np.isfinite(x)], dtype=float))
    v = v[v > 0]
    if not len(v):
        return
    changes_sign = min(values) < 0 < max(values)
    if v.max() / v.min() < LOG_RATIO and not changes_sign:
        return
    if min(values) > 0:
        ax.set_yscale("log")
    else:
        # the linear part around 0 a decade below the smallest value, on a power of ten: its
        # ticks (-1, 0, 1 of that power) then stand a decade's height apart, not on each other
        ax.set_yscale("symlog", linthresh=float(10.0 ** np.floor(np.log10(v.min()))), linscale=1.0)
    ax.autoscale_view()
    ax.margins(y=0.12)
    if min(values) > 0:
        plotting.log_ticks(ax.yaxis)
    else:
        from matplotlib import ticker

        ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda y, _: f"{y:g}"))      # -10 -1 0 1 10


def _plot(path: Path, axis: Axis, rows: list[dict], reported: dict):
    """One column per quantity (and the means for the load and inertia axes): the model's
    amplitudes and its dA = A2 - A1, the monograph's points (crosses) on the same axes -
    logarithmic where they are a decade or more apart - and each panel's comparison in
    words (how many times the model's, and a sign that differs)."""
    plt = plotting.pyplot()
    ok = sorted((r for r in rows if r["result"].get("status") == "ok"), key=lambda r: r["x"])
    x = np.array([r["x"] for r in ok])
    value = lambda key: [r["result"][key] for r in ok]  # noqa: E731
    columns = list(PLOT_COLUMNS) + ([("mean", "mean", "")] if axis.name in ("load", "inertia") else [])
    comparisons = {c["key"]: c for c in against_monograph(rows, reported)}
    fig, grid = plt.subplots(2, len(columns), figsize=(4.6 * len(columns), 6.6), squeeze=False,
                             sharex=True, layout="constrained")
    for col, (q, label, unit) in enumerate(columns):
        top, middle = grid[0, col], grid[1, col]
        if q == "mean":
            top.plot(x, value("mean_w"), "-o", color="tab:purple", label="model mean w")
            top.set_ylabel("mean speed [rad/s]")
            middle.plot(x, value("mean_tau"), "-o", color="tab:brown", label="model mean torque")
            middle.set_ylabel("mean torque [N*m]")
            _overlay(top, reported.get("mean_w"), "reported mean w", "k")
            _overlay(middle, reported.get("mean_tau"), "reported mean torque", "k")
            continue
        for i, style, color in ((1, "-o", "C0"), (2, "--s", "C1")):
            top.plot(x, value(f"A_{q}{i}"), style, color=color, label=f"model {('drive', 'driven')[i - 1]}")
        _overlay(top, reported.get(f"A_{q}1"), "monograph drive", "C0")
        _overlay(top, reported.get(f"A_{q}2"), "monograph driven", "C1")
        top.set_ylabel(f"{label} amplitude A [{unit}]")
        middle.plot(x, value(f"dA_{q}"), "-o", color="tab:green", label="model dA = A2 - A1")
        _overlay(middle, reported.get(f"dA_{q}"), "monograph dA", "tab:green")
        middle.axhline(0, color="0.6", lw=0.8)
        middle.set_ylabel(f"dA {label} [{unit}]")
        for ax, keys in ((top, (f"A_{q}1", f"A_{q}2")), (middle, (f"dA_{q}",))):
            shown = [v for k in keys for v in value(k)] + [_reported_value(v) for k in keys
                                                           for _, v in reported.get(k) or ()]
            _scale_for(ax, shown)
            said = [comparisons[k] for k in keys if k in comparisons]
            if said:
                # above the panel, not on it: a box on the data hid the points it spoke of
                ax.set_title("\n".join(_panel_note(c) for c in said), fontsize=7.5, loc="left")
    for axes_row in grid:
        for ax in axes_row:
            ax.grid(alpha=0.3)
            if ax.axison and not ax.has_data():
                ax.text(0.5, 0.5, f"no case ran ({len(rows)} failed)", transform=ax.transAxes, ha="center",
                        va="center", color="0.5")
    for row in grid:
        plotting.row_legend(row, fontsize=7)
    for ax in grid[-1]:
        ax.set_xlabel(axis.quantity)
    fig.suptitle(f"{axis.name} (Fig. {axis.figure}): {axis.note}" + ("" if not comparisons else
                 "\nthe monograph's points (x) on the model's axes"), fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _panel_note(c: dict) -> str:
    """A panel's comparison, short: 'monograph dA = 17-27x the model's, opposite sign'."""
    which = {"1": " drive", "2": " driven"}.get(c["key"][-1], "")
    return (f"monograph{which} {c['key'].split('_')[0]} = {_times(c)} the model's"
            + _sign_words(c))


def _times(c: dict) -> str:
    """How many times the model's the printed values are: '26x', '3.1-11x', '17-140x'."""
    low, high = (f"{r:.2g}" if r < 100 else f"{r:.0f}" for r in c["ratio"])
    return f"{low}x" if low == high else f"{low}-{high}x"


def _sign_words(c: dict) -> str:
    """', of opposite sign' (everywhere), ', of opposite sign at 35', or nothing."""
    at = c["opposite_sign_at"]
    if not at:
        return ""
    return ", of opposite sign" + ("" if len(at) == len(c["x"]) else " at " + ", ".join(f"{x:g}" for x in at))


def _overlay(ax, points, label, color):
    if not points:
        return
    for i, (x, v) in enumerate(points):
        if isinstance(v, (tuple, list)):
            ax.errorbar([x], [0.5 * (v[0] + v[1])], yerr=[[0.5 * (v[1] - v[0])]], fmt="x", color=color,
                        capsize=3, label=label if i == 0 else None)
        else:
            ax.plot([x], [v], "x", color=color, ms=9, mew=2, label=label if i == 0 else None)


def select(names: list[str] | None) -> list[Axis]:
    axes = default_axes()
    if not names:
        return axes
    known = {a.name: a for a in axes}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"unknown sweep axis {', '.join(unknown)} (known: {', '.join(known)})")
    return [known[n] for n in names]


def thin(axes: list[Axis], every: int) -> list[Axis]:
    """Every ``every``-th value of each axis, always keeping both ends (quick looks)."""
    from dataclasses import replace
    if every <= 1:
        return axes
    return [replace(a, values=[v for i, v in enumerate(a.values) if i % every == 0 or i == len(a.values) - 1])
            for a in axes]


__all__ = ["Axis", "default_axes", "plan", "check", "run_case", "sweep", "trends", "select", "thin", "published",
           "signal_key"]
