"""Running and timing the cases: each case's repeats (a master's each after the FMU-call
floor at its step, its call prices just before and after them), its errors judged once
against the tight monolithic reference (runs are deterministic), and the side-by-side
rounds of the cases a headline ratio divides."""
from __future__ import annotations

import statistics as stats
import time as clock
from pathlib import Path

import numpy as np

from harness.description import scene_kinds
from harness.description import scene as scenes
from harness.engine import interrupt
from harness.engine import masters as master_family
from harness.engine.run import RunResult, simulate
from harness.engine.system import CO_SIMULATION
from harness.judges import metrics
from harness.judges import fmu_reference, monolithic, stability
from harness.studies import trust
from harness.studies.bench import floors, master_time, replay
from harness.studies.bench.schedule import Case


def _judge(case: Case, scene: scenes.Scene, times, traces):
    """Errors and energy residual of a finished run against the tight reference."""
    try:        # the monolithic reference, or for a scene it does not know one made from the FMUs
        ref = fmu_reference.reference(monolithic.planned(scene), times)
    except fmu_reference.ReferenceUnavailable:
        return      # no errors: the study says once why (``fmu_reference.described``)
    transient = scene.experiment.start + scene.experiment.transient
    names = metrics.signals(scene)
    for suffix, after in (("", None), ("_after_transient", transient)):
        e = metrics.driveline_errors(scene, times, traces, ref.times, ref.traces, after=after)
        if len(e) < 4:
            continue
        for kind in ("tau", "w"):
            for measure in ("rms", "max"):
                case.errors[f"{kind}_{measure}{suffix}"] = max(e[names[f"{kind}1"]][f"{measure}_relative"],
                                                               e[names[f"{kind}2"]][f"{measure}_relative"])
    if (energy := scene_kinds.energy_variables(scene)) and all(n in traces for n in energy):
        case.energy_residual = metrics.energy_balance(scene, times, traces)["residual_relative"]


def _measure(case: Case, scene, run_once, repeats, limit_s, floor=None, own_calls=None) -> Case:
    """Run ``run_once()`` (-> RunResult) up to ``repeats`` times for the median run time;
    judge the first run (runs are deterministic), stop at a failure or a long run.
    ``floor()`` (seconds a step of the FMU calls alone) and ``own_calls()`` (a run and its
    own calls replayed, side by side: ``(run, replay)`` seconds, None where not measured)
    are timed just before each run."""
    case.asked = repeats
    case.load.append(trust.load_average())
    for attempt in range(repeats):
        if floor is not None:
            case.floor_times.append(floor())
        if own_calls is not None:
            pair = own_calls()
            if pair is not None:
                case.own_calls_pairs.append(list(pair))
        result: RunResult = run_once()
        interrupt.check()          # Ctrl-C during a peer's run: the case is not measured
        case.wall_times.append(result.wall_time)
        if attempt == 0:
            # a master counts its accepted steps; a peer, its communication points
            case.steps = (int(result.counters.get("steps", 0)) if case.kind == "master"
                          else max(0, len(result.times) - 1))
            case.fmu_calls = int(result.counters.get("fmu_calls", 0))
            case.rollbacks = int(result.counters.get("rollbacks", 0))
            case.calls_by_kind = result.counters.get("calls_by_kind", {})
            case.rhs = result.counters.get("rhs")
            if len(result.times) > 1:
                case.largest_step = float(np.max(np.diff(result.times)))
            if not result.ok:
                case.failure = result.failure
                break
            _judge(case, scene, result.times, result.traces)
        if result.wall_time > limit_s:     # long runs: one or two repeats say enough
            break
    case.load.append(trust.load_average())
    if case.floor_times and case.steps:
        case.floor_time = stats.median(case.floor_times) * case.steps
    return case


#: steps of the floor timed before each run of a case (about 0.1 s of calls)
FLOOR_STEPS = 2000

#: how many times the FMU-call floor a master's step costs at most, about (an implicit
#: master iterating, or CVODE's many calls): a benchmark whose runs would take less than a
#: minute at this many floors is not timed for an estimate
COSTLIEST_STEP_IN_FLOORS = 30.0


def planned_runs(scene, p: dict, repeats: int) -> list[tuple[str, float, int]]:
    """``(master, output step, runs)`` of each master's and peer's case of plan ``p`` (a
    peer as the plan's baseline master, a tolerance case at its output grid)."""
    runs = [(name, h, repeats) for name, steps in p["steps"].items() for h in steps]
    runs += [(name, p["output_steps"].get(name, scene.experiment.step), repeats)
             for name, tolerances in p["tolerances"].items() for _ in tolerances]
    runs += [(p["baseline"], h, repeats) for steps in p["peers"].values() for h in steps]
    runs += [(p["baseline"], scene.experiment.step, repeats) for tolerances in p["peer_tolerances"].values()
             for _ in tolerances]
    return runs


def estimated_seconds(scene, p: dict, repeats: int, fmu_dir: Path, floor_per_step: float) -> float | None:
    """How long the masters' and peers' runs of plan ``p`` will take, about: each master's
    set-up and cost of a communication step timed now (``cases.step_cost``, at the scene's
    step), times each case's steps and repeats (one run where it would pass the plan's
    ``repeats_limit_s``), with the floor timed before each run (and a fixed-step master's
    recording and replays of its own calls).  None where the runs would
    take less than a minute even at ``COSTLIEST_STEP_IN_FLOORS`` times the FMU-call floor
    (nothing is timed then).  The monolithic solutions and the side-by-side rounds come on
    top, and an adaptive master's steps are its own: an estimate, not a promise."""
    from harness.studies.cases import CALIBRATION_STEPS, step_cost

    e = scene.experiment
    runs = planned_runs(scene, p, repeats)
    steps = {run: (e.stop - e.start) / run[1] for run in runs}
    if sum(steps[r] * r[2] for r in runs) * floor_per_step * COSTLIEST_STEP_IN_FLOORS < 60.0:
        return None

    def timed(name: str, count: int) -> float:
        short = scene.with_overrides([f"experiment.stop={e.start + count * e.step!r}", "experiment.transient=0"])
        options, _ = master_options(scene, name, None)
        started = clock.perf_counter()
        simulate(short, name, e.step, fmu_dir, options=options)
        return clock.perf_counter() - started

    masters = list(dict.fromkeys(name for name, _, _ in runs))
    timed(masters[0], CALIBRATION_STEPS[0])          # the first run pays for imports and loading the FMUs
    cost = {name: step_cost(lambda count, name=name: timed(name, count)) for name in masters}
    # a fixed-step master's case (``planned_runs`` lists them first) records its calls in
    # one run more and before each run runs once more with their replay side by side
    # (about a run's time twice, less the master's once)
    fixed = sum(len(hs) for hs in p["steps"].values())
    total = 0.0
    for k, run in enumerate(runs):
        name, _, runs_asked = run
        setup, per_step = cost[name]
        one = setup + per_step * steps[run]
        replayed = k < fixed
        total += (one * (3 if replayed else 1) + FLOOR_STEPS * floor_per_step) \
            * (1 if one > p["repeats_limit_s"] else runs_asked) \
            + 4 * PRICE_STEPS * floor_per_step \
            + (one if replayed else 0.0)            # the call prices before and after a case; the recording
    return total


#: steps of each pricing of the calls, before and after a case's runs
PRICE_STEPS = 1000


#: the engine name of the unsplit equations under CVODE (``run_monolithic``)
MONOLITHIC_CVODE = "monolithic-cvode"


def master_options(scene, name: str, tolerance: float | None) -> tuple[dict, str | None]:
    """A master's options in the benchmark: its tolerance, and for the Model Exchange
    master the CVODE method the stability analysis chooses (as ``lever run`` passes it),
    with which and why (None for a master without a method to choose)."""
    options = {"tolerance": tolerance} if tolerance is not None else {}
    if "method" not in master_family.MASTERS[name].options:
        return options, None
    chosen = stability.cvode_method(scene)
    if chosen is None:
        return options, "CVODE, Adams or BDF as the master chooses from its Jacobian at the start"
    options["method"] = chosen[0]
    return options, f"CVODE-{chosen[0]}: {chosen[1]}"


#: the runs with every call timed that measure a master's own time (``master_time``): the
#: least of three, their spread flags a busy machine
TIMED_RUNS = 3


def run_master(scene, name, step, tolerance, repeats, fmu_dir, limit_s, twins: Path | None = None) -> Case:
    """A master's case: its runs, each after the FMU-call floor at its step (the scene's
    for an adaptive master) and, for a fixed-step co-simulation master, after one more run
    side by side with the replay of its own calls (``replay.OwnCallsFloor``: recorded in
    one more run), and with ``twins``
    (the do-nothing FMUs) the prices of a call into ours and into the twins just before and
    just after the runs, for its time split."""
    options, method = master_options(scene, name, tolerance)
    at = step if tolerance is None else scene.experiment.step
    prices = {"ours": [], "hollow": []}

    def price():
        if twins is not None:
            prices["ours"].append(floors.call_prices(scene, fmu_dir, n_steps=PRICE_STEPS, step=at))
            prices["hollow"].append(floors.call_prices(scene, twins, n_steps=PRICE_STEPS, step=at))

    price()
    # a fixed-step co-simulation master's own calls, recorded in a run of their own
    own_calls = (replay.OwnCallsFloor(scene, name, step, options, fmu_dir) if tolerance is None and
                 master_family.master_class(name).interface == CO_SIMULATION else None)
    case = _measure(Case(name, "master", step, tolerance), scene,
                    lambda: simulate(scene, name, step, fmu_dir, options=options), repeats, limit_s,
                    floor=lambda: floors.call_floor(scene, n_steps=FLOOR_STEPS, fmu_dir=fmu_dir, step=at),
                    own_calls=own_calls)
    if own_calls is not None:
        case.own_calls = own_calls.summary()
        del own_calls       # the recording's memory back before the next case
    price()
    if twins is not None:
        case.prices = prices
        if case.failure is None and master_family.master_class(name).interface == CO_SIMULATION:
            # the split's master share measured directly, in runs of their own (every call timed)
            case.timed = master_time.measure(scene, name, step, options, fmu_dir, tolerance=tolerance,
                                             runs=TIMED_RUNS if len(case.wall_times) == repeats else 2).summary()
    case.method = method
    return case


def run_peer(scene, name, step, repeats, fmu_dir, limit_s, tolerance=None) -> Case:
    from harness import peers
    case = Case(name, "peer", step, tolerance)
    reason = peers.available(name)
    if reason:
        case.failure = f"not run: {reason}"
        return case
    return _measure(case, scene, lambda: peers.simulate_peer(name, scene, step, fmu_dir, tolerance=tolerance),
                    repeats, limit_s)


def monolithic_method(scene, engine: str) -> tuple[str, str]:
    """``(method, why)`` of a monolithic engine: scipy's DOP853, or CVODE's BDF or Adams as
    the stability analysis chooses it for the scene (BDF where it has no driveline to
    analyse)."""
    if engine != MONOLITHIC_CVODE:
        return "DOP853", "scipy's DOP853"
    chosen = stability.cvode_method(scene)
    method = chosen[0] if chosen else "BDF"
    return f"CVODE-{method}", (chosen[1] if chosen else "no driveline to analyse")


def run_monolithic(scene, rtol, grid_step, repeats, engine: str = "monolithic") -> Case:
    """The unsplit equations at a looser tolerance, with scipy's DOP853 (``engine``
    "monolithic") or CVODE (``MONOLITHIC_CVODE``): the cost of not co-simulating at all
    (same physics code, no FMU calls)."""
    case = Case(engine, "monolithic", grid_step, rtol)
    method, why = monolithic_method(scene, engine)
    case.method = f"{method}: {why}"
    e = scene.experiment
    times = np.linspace(e.start, e.stop, int(round((e.stop - e.start) / grid_step)) + 1)
    solution = None
    case.asked = repeats
    case.load.append(trust.load_average())
    for _ in range(repeats):
        solution = monolithic.solve(scene, times, use_cache=False, rtol=rtol, atol=rtol * 1e-2, method=method)
        interrupt.check()
        case.wall_times.append(solution.wall_time)
    case.load.append(trust.load_average())
    case.steps = case.rhs = solution.n_rhs
    _judge(case, scene, solution.times, solution.traces)
    return case


def measure_rounds(scene: scenes.Scene, chosen: list[Case], repeats: int, fmu_dir: Path,
                   twins: Path | None) -> dict:
    """``repeats`` rounds, each running every chosen case once in turn and the do-nothing
    floor: the k-th run of each case saw the machine the k-th of the others saw, so ratios
    are taken round by round.  The rounds go forth and back (A B C, C B A, ...): a machine
    that slows or speeds up through a round favours no case, and cases next to each other
    in ``chosen`` (``headlines.headline_cases`` puts the ones a ratio divides together) run
    next to each other."""
    walls = {c.key: [] for c in chosen}
    floor_times, loads = [], []
    for k in range(repeats):
        loads.append(trust.load_average())
        if twins is not None:
            floor_times.append(floors.call_floor(scene, n_steps=FLOOR_STEPS * 2, fmu_dir=twins))
        for c in (chosen if k % 2 == 0 else chosen[::-1]):
            walls[c.key].append(_rerun(scene, c, fmu_dir))
    loads.append(trust.load_average())
    return {"walls": walls, "hollow_floor": floor_times, "load": loads}


def _rerun(scene: scenes.Scene, case: Case, fmu_dir: Path) -> float:
    """The stepping-loop time of one more run of a case (a master's or the monolithic one)."""
    if case.kind == "monolithic":
        e = scene.experiment
        times = np.linspace(e.start, e.stop, int(round((e.stop - e.start) / case.step)) + 1)
        return monolithic.solve(scene, times, use_cache=False, rtol=case.tolerance, atol=case.tolerance * 1e-2,
                                method=monolithic_method(scene, case.engine)[0]).wall_time
    options, _ = master_options(scene, case.engine, case.tolerance)
    result = simulate(scene, case.engine, case.step, fmu_dir, options=options)
    interrupt.check()
    if not result.ok:
        raise RuntimeError(f"{case.label} failed when run again: {result.failure}")
    return result.wall_time
