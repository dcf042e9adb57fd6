"""The work-precision benchmark: error against run time for every way the harness can
step a scene, next to other co-simulation engines on the same FMUs, the monolithic
solution and the FMU-call floor (``lever bench [SCENE]``).

Each case runs ``repeats`` times; the run time quoted is the median [min-max] of the
stepping loops (instantiation left out, for every engine alike).  What is divided by what
(a master and its baseline, a master and DOP853, a step and the do-nothing floor) is measured
side by side: the cases a headline ratio divides run again in turn, round after round
(``measure_rounds``), and the ratio is the median of the rounds' ratios with their range.  A
master's FMU-call floor is timed just before each of its runs and its call prices just before
and after them.  A figure that cannot be (a share below zero, a floor above the step it bounds,
a figure from fewer runs than asked) is flagged with the machine's load and the spread, not
shown (``harness.studies.trust``).  Errors are measured once
(runs are deterministic) against the tight monolithic reference on the run's own
communication grid: time-averaged RMS and max of ``tau1, tau2, w1, w2`` relative to the
mean torque and speed, over the whole run and after the scene's start-up transient, and
the energy residual.

The plan comes from the scene's ``[bench]`` table (steps per master, tolerances for
adaptive ones, peers, monolithic tolerances, the target error); masters it does not
name are left out.
"""
from __future__ import annotations

import csv
import json
import math
import statistics as stats
import time as clock
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from harness.description import kinds
from harness.engine import interrupt
from harness.engine import masters as master_family
from harness.judges import metrics
from harness.judges import monolithic as reference
from harness.studies import hollow, trust
from harness.studies.cases import FAILED, CaseLog, case_key
from harness.description import scene as scenes
from harness.paths import FMUS, RESULTS
from harness.engine.run import RunResult, recorded_names, simulate
from harness.engine.component import FmuCallError
from harness.engine.system import FloorPlan, System


@dataclass
class Case:
    engine: str                 # a master's name, a peer's, or "monolithic"
    kind: str                   # "master", "peer", "monolithic"
    step: float | None          # communication step [s] (first step for adaptive runs)
    tolerance: float | None = None
    wall_times: list = field(default_factory=list)
    steps: int = 0
    fmu_calls: int = 0
    rollbacks: int = 0
    errors: dict = field(default_factory=dict)   # rms/max relative, whole run and after transient
    energy_residual: float | None = None
    floor_time: float | None = None
    failure: str | None = None
    largest_step: float | None = None           # the longest communication step taken [s]
    #: the stepping loop's FMI calls, component -> kind -> count (a master's run)
    calls_by_kind: dict = field(default_factory=dict)
    #: where the run time went (``time_split``): crossing, slave, master [s]
    split: dict | None = None
    #: the call prices measured just before and just after the case's runs:
    #: {"ours"|"hollow": [before, after]}, each component -> kind -> seconds a call
    prices: dict | None = None
    #: runs asked for (``repeats``); fewer were made when a run failed or took long
    asked: int = 0
    #: the FMU-call floor [s a step] timed just before each run (masters): one per run
    floor_times: list = field(default_factory=list)
    #: the machine's one-minute load average before and after the case's runs
    load: list = field(default_factory=list)
    #: why the split is not shown (``trust.split_problems``), with the machine's noise
    split_unreliable: str | None = None

    @property
    def wall(self) -> float:
        return stats.median(self.wall_times) if self.wall_times else math.nan

    @property
    def stable(self) -> bool:
        return self.failure is None and math.isfinite(self.errors.get("tau_rms", math.nan))

    @property
    def label(self) -> str:
        if self.kind == "monolithic":
            return f"monolithic rtol={self.tolerance:g}"
        if self.tolerance is not None:
            return f"{self.engine} tol={self.tolerance:g}"
        return f"{self.engine} h={self.step:g}"


def plan(scene: scenes.Scene, only: list[str] | None = None) -> dict:
    """The scene's benchmark plan, with defaults: every master at the scene's step."""
    table = dict(scene.bench)
    steps = {name: [float(h) for h in values] for name, values in table.get("steps", {}).items()}
    tolerances = {name: [float(x) for x in values] for name, values in table.get("tolerances", {}).items()}
    if not steps and not tolerances:
        steps = {name: [scene.experiment.step] for name, m in master_family.MASTERS.items() if not m.adaptive}
    try:
        master_family.check(*steps, *tolerances)
    except master_family.UnknownMaster as error:
        raise ValueError(f"scene '{scene.name}' [bench]: {error}") from None
    if only:
        master_family.check(*only)
        steps = {k: v for k, v in steps.items() if k in only}
        tolerances = {k: v for k, v in tolerances.items() if k in only}
    return {
        "steps": steps,
        "tolerances": tolerances,
        "peers": {name: [float(h) for h in values] for name, values in table.get("peers", {}).items()},
        # ECCO: (first step, tolerance) pairs, its tolerance in joules per step
        "peer_tolerances": {name: [float(x) for x in values]
                            for name, values in table.get("peer_tolerances", {}).items()},
        "monolithic": [float(x) for x in table.get("monolithic_rtol", [1e-4, 1e-6, 1e-8])],
        "target_error": float(table.get("target_error", 1e-3)),
        "baseline": table.get("baseline", "jacobi"),
        "repeats_limit_s": float(table.get("repeats_limit_s", 5.0)),
    }


# -- measuring -------------------------------------------------------------------------------------

def _judge(case: Case, scene: scenes.Scene, times, traces):
    """Errors and energy residual of a finished run against the tight reference."""
    ref = reference.solve(scene, times)
    transient = scene.experiment.start + scene.experiment.transient
    for suffix, after in (("", None), ("_after_transient", transient)):
        e = metrics.driveline_errors(scene, times, traces, ref.times, ref.traces, after=after)
        if len(e) < 4:
            continue
        for kind in ("tau", "w"):
            for measure in ("rms", "max"):
                case.errors[f"{kind}_{measure}{suffix}"] = max(e[f"{kind}1"][f"{measure}_relative"],
                                                               e[f"{kind}2"][f"{measure}_relative"])
    if all(n in traces for n in kinds.energy_variables(scene)):
        case.energy_residual = metrics.energy_balance(scene, times, traces)["residual_relative"]


def _measure(case: Case, scene, run_once, repeats, limit_s, floor=None) -> Case:
    """Run ``run_once()`` (-> RunResult) up to ``repeats`` times for the median run time;
    judge the first run (runs are deterministic), stop at a failure or a long run.
    ``floor()`` (seconds a step of the FMU calls alone) is timed just before each run, so
    that a run and the floor it is divided by saw the same machine."""
    case.asked = repeats
    case.load.append(trust.load_average())
    for attempt in range(repeats):
        if floor is not None:
            case.floor_times.append(floor())
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
#: steps of each pricing of the calls, before and after a case's runs
PRICE_STEPS = 1000


def run_master(scene, name, step, tolerance, repeats, fmu_dir, limit_s, twins: Path | None = None) -> Case:
    """A master's case: its runs, each after the FMU-call floor at its step (the scene's
    for an adaptive master), and with ``twins`` (the do-nothing FMUs) the prices of a call
    into ours and into the twins just before and just after the runs, for its time split."""
    options = {"tolerance": tolerance} if tolerance is not None else {}
    at = step if tolerance is None else scene.experiment.step
    prices = {"ours": [], "hollow": []}

    def price():
        if twins is not None:
            prices["ours"].append(call_prices(scene, fmu_dir, n_steps=PRICE_STEPS, step=at))
            prices["hollow"].append(call_prices(scene, twins, n_steps=PRICE_STEPS, step=at))

    price()
    case = _measure(Case(name, "master", step, tolerance), scene,
                    lambda: simulate(scene, name, step, fmu_dir, options=options), repeats, limit_s,
                    floor=lambda: call_floor(scene, n_steps=FLOOR_STEPS, fmu_dir=fmu_dir, step=at))
    price()
    if twins is not None:
        case.prices = prices
    return case


def run_peer(scene, name, step, repeats, fmu_dir, limit_s, tolerance=None) -> Case:
    from harness.formats import peers
    case = Case(name, "peer", step, tolerance)
    reason = peers.available(name)
    if reason:
        case.failure = f"not run: {reason}"
        return case
    return _measure(case, scene, lambda: peers.simulate_peer(name, scene, step, fmu_dir, tolerance=tolerance),
                    repeats, limit_s)


def run_monolithic(scene, rtol, grid_step, repeats) -> Case:
    """The unsplit equations with scipy at a looser tolerance: the cost of not
    co-simulating at all (same physics code, no FMU calls)."""
    case = Case("monolithic", "monolithic", grid_step, rtol)
    e = scene.experiment
    times = np.linspace(e.start, e.stop, int(round((e.stop - e.start) / grid_step)) + 1)
    solution = None
    case.asked = repeats
    case.load.append(trust.load_average())
    for _ in range(repeats):
        solution = reference.solve(scene, times, use_cache=False, rtol=rtol, atol=rtol * 1e-2)
        interrupt.check()
        case.wall_times.append(solution.wall_time)
    case.load.append(trust.load_average())
    case.steps = solution.n_rhs
    _judge(case, scene, solution.times, solution.traces)
    return case


def _initial_states(system: System) -> list | None:
    """Every component's state as initialised, for the floor's motion to start again from
    (None when a component cannot give its state)."""
    components = list(system.components.values())
    if not all(c.description.coSimulation.canGetAndSetFMUstate for c in components):
        return None
    return [(c, c.save_state()) for c in components]


def _start_again(system: System, states: list | None, start: float, error: FmuCallError):
    """The floor's motion failed at a step (an FMU refused a call: bare steps at this step
    diverge, as an explicit master's would, and FMI allows no further step after an error):
    every component back to its initial state, the buffers refilled.  Without states, or
    when the first step fails, there is nothing to time: the error stands."""
    if states is None:
        raise error
    for component, state in states:
        component.restore_state(state, start)
    system.propagate()


def _free_states(states: list | None):
    for component, state in states or []:
        try:
            component.free_state(state)
        except FmuCallError:
            pass            # an instance that fails here is freed next: the first error stands


def call_floor(scene: scenes.Scene, n_steps: int = 20000, fmu_dir: Path = FMUS, step: float | None = None) -> float:
    """Seconds per communication step of the FMI calls alone: ``System.floor_step``, the
    engine's own step of every component, one propagation (every output read once, every
    target's inputs set once, the copies carrying the values so that the models run the
    scene's motion: a shaft's substeps may depend on its speed) and the re-reads of
    recorded outputs that depend on inputs, in a bare loop (no master, no recording).  What
    any master must pay at the least.  Steps of ``step`` (default the scene's): a shaft's
    fmi2DoStep costs more the longer the step.  Where the motion diverges at this step it
    starts again from the initial states (``_start_again``); only completed steps are timed."""
    system = System(scene, fmu_dir, record=recorded_names(scene))
    states = None
    try:
        system.initialize()
        states = _initial_states(system)
        plan = system.floor_plan()
        floor_step = system.floor_step
        timer = clock.perf_counter
        h = step or scene.experiment.step
        start = t = scene.experiment.start
        spent, done = 0.0, 0
        last = timer()
        while done < n_steps:
            try:
                floor_step(t, h, plan)
            except FmuCallError as error:
                _start_again(system, states if t != start else None, start, error)
                t = start
                last = timer()
                continue
            now = timer()
            spent += now - last
            last = now
            done += 1
            t += h
        interrupt.check()
        return spent / n_steps
    finally:
        _free_states(states)
        system.free()


#: kinds of FMI call a master makes, as ``System.calls_by_kind`` counts them
CALL_KINDS = ("get", "set", "step", "state")


def call_prices(scene: scenes.Scene, fmu_dir: Path = FMUS, n_steps: int = 2000,
                step: float | None = None) -> dict[str, dict[str, float]]:
    """Seconds per FMI call, by component and kind: the floor's step (``call_floor``) with
    every raw call wrapped in a timer of its own, so that each is priced where it falls in
    a step (a read after a step pays for the outputs the step left to compute), less the
    timer's own cost; and ``state``, fmi2GetFMUstate, fmi2SetFMUstate and fmi2FreeFMUstate
    in turn (a third of the three), for the stateful components that can roll back.  Summed
    over one step's calls, the prices are the floor.  Steps of ``step`` (default the
    scene's): a shaft's fmi2DoStep costs more the longer the step (it sub-steps its load)."""
    timer = clock.perf_counter
    system = System(scene, fmu_dir, record=recorded_names(scene))
    states = None
    try:
        system.initialize()
        states = _initial_states(system)
        spent = {name: {"get": 0.0, "set": 0.0, "step": 0.0} for name in system.order}

        def timed(call, account: dict, kind: str):
            # the interval holds the raw call alone, as the floor's loop makes it
            def timed_call(handle, a, b, c):
                started = timer()
                status = call(handle, a, b, c)
                account[kind] += timer() - started
                return status
            return timed_call

        def timed_visit(visit):
            return replace(visit, get_real=None if visit.get_real is None else
                           timed(visit.get_real, spent[visit.component.name], "get"),
                           sends=tuple(replace(send, set_real=timed(send.set_real, spent[send.component.name], "set"))
                                       for send in visit.sends))

        plan = system.floor_plan()
        plan = FloorPlan(tuple(replace(call, do_step=timed(call.do_step, spent[call.component.name], "step"))
                               for call in plan.steps),
                         [timed_visit(v) for v in plan.propagation], [timed_visit(v) for v in plan.rereads])
        counted = system.calls_by_kind
        made = {name: dict.fromkeys(spent[name], 0) for name in spent}
        h = step or scene.experiment.step
        start = t = scene.experiment.start
        done = 0
        while done < n_steps:
            before = counted()
            kept = {name: dict(kinds) for name, kinds in spent.items()}
            try:
                system.floor_step(t, h, plan)
            except FmuCallError as error:
                # the failed step's calls are not priced (see call_floor)
                _start_again(system, states if t != start else None, start, error)
                for name in spent:
                    spent[name].update(kept[name])
                t = start
                continue
            after = counted()
            for name in made:
                for kind in made[name]:
                    made[name][kind] += after[name][kind] - before[name][kind]
            done += 1
            t += h
        # the timer's own share of an interval, taken from every timed call
        empty = 0.0
        for _ in range(n_steps):
            started = timer()
            empty += timer() - started
        own = empty / n_steps
        prices = {name: {kind: max(0.0, spent[name][kind] / made[name][kind] - own)
                         for kind in spent[name] if made[name][kind]} for name in spent}
        for name in system.stateful:
            c = system.components[name]
            if c.description.coSimulation.canGetAndSetFMUstate:
                started = timer()
                for _ in range(n_steps):
                    state = c.save_state()
                    c.restore_state(state, c.time)
                    c.free_state(state)
                prices[name]["state"] = (timer() - started) / (3 * n_steps)
        return prices
    finally:
        _free_states(states)
        system.free()


def time_split(wall: float, calls: dict[str, dict[str, int]], ours: dict[str, dict[str, float]],
               hollow: dict[str, dict[str, float]]) -> dict[str, float] | None:
    """A run's time ``wall`` split by where it went, from the calls it made (component ->
    kind -> count) and the prices of a call (component -> kind -> seconds) into our FMUs
    and into their do-nothing twins:

    * ``crossing``: the twins' prices times the calls - what any pythonfmu FMU costs;
    * ``slave``: our prices minus the twins' times the calls - our FMUs' own work behind
      the calls (the native entry's checks, the FMI glue, the model's physics);
    * ``master``: the rest - the master's arithmetic, its Python, the recording.

    None when a call kind was made that has no price (e.g. states of an FMU that cannot
    roll back)."""
    crossing = slave = 0.0
    for name, by_kind in calls.items():
        for kind, count in by_kind.items():
            if not count:
                continue
            if kind not in ours.get(name, {}) or kind not in hollow.get(name, {}):
                return None
            crossing += count * hollow[name][kind]
            slave += count * (ours[name][kind] - hollow[name][kind])
    return {"crossing": crossing, "slave": slave, "master": wall - crossing - slave}


# -- the whole benchmark -------------------------------------------------------------------------------

def fingerprint(scene: scenes.Scene, repeats: int, fmu_dir: Path = FMUS) -> dict:
    """What a benchmark's results depend on: a case log with another fingerprint is set
    aside, never mixed in (the scene with its bench plan, the repeats, the FMU build)."""
    from lever import __version__
    stamp = Path(fmu_dir) / "build-stamp.json"
    return {"study": "bench", "scene": asdict(scene), "repeats": repeats, "lever": __version__,
            "fmus": json.loads(stamp.read_text()).get("hash") if stamp.exists() else None}


def _logged(log: CaseLog | None, case: Case, measure) -> tuple[Case, bool]:
    """``measure()`` -> Case, through the case log: a case already in the log is taken
    from it; a case that raises is recorded as failed with its diagnosis, and the
    benchmark goes on with the others."""
    if log is None:
        try:
            return measure(), False
        except Exception as error:  # noqa: BLE001 - one failed case must not cost the others
            case.failure = f"{type(error).__name__}: {error}"
            return case, False
    key = case_key(case.kind, case.engine, case.step, case.tolerance)
    entry, reused = log.run(key, lambda: asdict(measure()))
    if entry.get("status") == FAILED:
        case.failure = f"{entry['error']} (at {entry['where']})"
        return case, reused
    return Case(**{k: v for k, v in entry.items() if k in Case.__dataclass_fields__}), reused


def bench(scene: scenes.Scene, repeats: int = 3, fmu_dir: Path = FMUS, only: list[str] | None = None,
          peers: bool = True, monolithic: bool = True, progress=None, out: Path | None = None,
          resume: bool = True) -> dict:
    """Run the scene's plan.  With ``out``, every finished case goes to ``out/cases.jsonl``
    as it finishes (harness.studies.cases): a benchmark killed part-way and run again resumes
    with the cases not yet done (``resume=False`` starts afresh).  Ctrl-C stops it at the
    running case's next step (logged as interrupted) with ``Interrupted``."""
    with interrupt.deferred():
        return _bench(scene, repeats, fmu_dir, only, peers, monolithic, progress, out, resume)


def _bench(scene, repeats, fmu_dir, only, peers, monolithic, progress, out, resume) -> dict:
    p = plan(scene, only)
    say = progress or (lambda text: None)
    log = CaseLog(out, fingerprint(scene, repeats, fmu_dir), resume=resume) if out is not None else None
    if log is not None and len(log):
        say(f"resuming: {len(log)} case(s) already in {log.path}")
    # the load seen by the measurements themselves (kept in the case log: a resumed
    # benchmark reports the load its cases ran under, not the load when it resumed)
    machine = trust.LoadLog()
    cases: list[Case] = []

    def take(case: Case, measure):
        case, reused = _logged(log, case, measure)
        cases.append(case)
        machine.samples += [x for x in case.load if x is not None]
        say(_line(case) + ("  (from the case log)" if reused else ""))

    def floors(fmus: Path, name: str) -> Case:
        case = Case(name, "floor", scene.experiment.step, asked=repeats, load=[trust.load_average()])
        case.wall_times = [call_floor(scene, fmu_dir=fmus) for _ in range(repeats)]
        case.load.append(trust.load_average())
        return case

    floor_case, _ = _logged(log, Case("floor", "floor", scene.experiment.step), lambda: floors(fmu_dir, "floor"))
    machine.samples += [x for x in floor_case.load if x is not None]
    floor_per_step = floor_case.wall
    say(f"FMU-call floor: {trust.spread_text(trust.spread(floor_case.wall_times))} per communication step")
    # The same calls into do-nothing twins of the FMUs (pythonfmu, an empty do_step): what
    # any pythonfmu FMU costs, and the other half of each master's time split.
    try:
        twins = hollow.twins(scene, fmu_dir)
    except Exception as error:  # noqa: BLE001 - the benchmark goes on without the split
        twins = None
        say(f"do-nothing FMUs not built ({type(error).__name__}: {error}): no split of the run times")
    hollow_case = None
    if twins is not None:
        hollow_case, _ = _logged(log, Case("floor-hollow", "floor", scene.experiment.step),
                                 lambda: floors(twins, "floor-hollow"))
        machine.samples += [x for x in hollow_case.load if x is not None]
        if hollow_case.wall_times:
            say(f"do-nothing FMU floor: {trust.spread_text(trust.spread(hollow_case.wall_times))} per "
                "communication step (same calls)")
        else:
            say(f"do-nothing FMU floor not measured ({hollow_case.failure}): no split of the run times")
            twins = hollow_case = None
    limit = p["repeats_limit_s"]
    for name, steps in p["steps"].items():
        for h in steps:
            take(Case(name, "master", h),
                 lambda name=name, h=h: run_master(scene, name, h, None, repeats, fmu_dir, limit, twins))
    for name, tolerances in p["tolerances"].items():
        for tol in tolerances:
            take(Case(name, "master", scene.experiment.step, tol),
                 lambda name=name, tol=tol: run_master(scene, name, scene.experiment.step, tol, repeats, fmu_dir,
                                                       limit, twins))
    if peers:
        for name, steps in p["peers"].items():
            for h in steps:
                take(Case(name, "peer", h), lambda name=name, h=h: run_peer(scene, name, h, repeats, fmu_dir, limit))
        for name, tolerances in p["peer_tolerances"].items():
            for tol in tolerances:
                take(Case(name, "peer", scene.experiment.step, tol),
                     lambda name=name, tol=tol: run_peer(scene, name, scene.experiment.step, repeats, fmu_dir,
                                                         limit, tol))
    if monolithic:
        for rtol in p["monolithic"]:
            take(Case("monolithic", "monolithic", scene.experiment.step, rtol),
                 lambda rtol=rtol: run_monolithic(scene, rtol, scene.experiment.step, repeats))
    for case in cases:
        split_case(case)
    # The headline comparisons, measured side by side: the cases they divide run in turn,
    # round after round, with the do-nothing floor in each round.
    chosen = headline_cases(scene, cases, p)
    rounds = None
    if chosen:
        say(f"side by side: {len(chosen)} case(s) the headline ratios divide, {repeats} round(s)")
        key = case_key("rounds", repeats, *(case_key(c.kind, c.engine, c.step, c.tolerance) for c in chosen))
        rounds = _rounds_logged(log, key, lambda: measure_rounds(scene, chosen, repeats, fmu_dir, twins))
        machine.samples += [x for x in rounds.get("load", []) if x is not None]
    return {"scene": scene.name, "plan": p, "repeats": repeats, "floor_per_step_s": floor_per_step,
            "floor_spread": trust.spread(floor_case.wall_times),
            "hollow_floor_per_step_s": hollow_case.wall if hollow_case else None,
            "hollow_floor_spread": trust.spread(hollow_case.wall_times) if hollow_case else None,
            "machine": machine.summary(), "rounds": rounds,
            "eigenfrequency_rad_s": eigenfrequency(scene), "cases": cases,
            "claims": claims(scene, cases, p, hollow_case.wall if hollow_case else None, rounds=rounds,
                             machine=machine.summary())}


def _rounds_logged(log: CaseLog | None, key: str, measure) -> dict:
    if log is None:
        return measure()
    entry, _ = log.run(key, measure)
    if entry.get("status") == FAILED:
        return {"failure": f"{entry['error']} (at {entry['where']})"}
    return entry


def case_noise(case: Case, problems: list[str] | None = None) -> str:
    """The machine's noise around a case, in words (its load and the spread of its runs);
    for ``problems`` that are only fewer runs than asked, the load alone (a long case stops
    repeating on an idle machine too)."""
    loads = [x for x in case.load if x is not None]
    load = {"cpus": trust.cpus(), "load_min": min(loads), "load_max": max(loads)} if loads else None
    if problems and all(p.startswith("from ") for p in problems):
        return trust.noise(load, None).replace("machine too noisy", "the machine", 1)
    return trust.noise(load, trust.spread(case.wall_times))


def split_case(case: Case):
    """A master's time split from the prices measured around its runs; an impossible split
    (a share below zero, priced calls above the run time) is kept aside with the reason."""
    if not (case.prices and case.kind == "master" and case.calls_by_kind and case.wall_times):
        return
    ours, hollow_prices = _median_prices(case.prices["ours"]), _median_prices(case.prices["hollow"])
    case.split = time_split(case.wall, case.calls_by_kind, ours, hollow_prices)
    problems = trust.split_problems(case.split, case.wall)
    case.split_unreliable = ("; ".join(problems) + f": {case_noise(case)}") if problems else None


def _key(case: Case) -> str:
    return case_key(case.kind, case.engine, case.step, case.tolerance)


def headline_cases(scene: scenes.Scene, cases: list[Case], p: dict) -> list[Case]:
    """The cases the headline ratios divide: each master's and the monolithic solution's
    two runs either side of the target error (the interpolation's), the largest stable
    baseline step and the baseline at the scene's step (against the do-nothing floor)."""
    target, baseline = p["target_error"], p["baseline"]
    chosen: dict[str, Case] = {}
    for name, group in _by_engine(cases).items():
        if name in master_family.MASTERS or name == "monolithic":
            for c in bracket(group, target):
                chosen[_key(c)] = c
    stable_base = [c for c in cases if c.engine == baseline and c.kind == "master" and c.stable
                   and c.tolerance is None]
    if stable_base and eigenfrequency(scene):
        largest = max(stable_base, key=lambda c: c.step)
        chosen[_key(largest)] = largest
    at_step = [c for c in stable_base if c.step == scene.experiment.step and c.steps]
    if at_step:
        chosen[_key(at_step[0])] = at_step[0]
    return list(chosen.values())


def measure_rounds(scene: scenes.Scene, chosen: list[Case], repeats: int, fmu_dir: Path,
                   twins: Path | None) -> dict:
    """``repeats`` rounds, each running every chosen case once in turn (A B C A B C ...)
    and the do-nothing floor: the k-th run of each case saw the machine the k-th of the
    others saw, so ratios are taken round by round."""
    walls = {_key(c): [] for c in chosen}
    floors, loads = [], []
    for _ in range(repeats):
        loads.append(trust.load_average())
        if twins is not None:
            floors.append(call_floor(scene, n_steps=FLOOR_STEPS * 2, fmu_dir=twins))
        for c in chosen:
            walls[_key(c)].append(_rerun(scene, c, fmu_dir))
    loads.append(trust.load_average())
    return {"walls": walls, "hollow_floor": floors, "load": loads}


def _rerun(scene: scenes.Scene, case: Case, fmu_dir: Path) -> float:
    """The stepping-loop time of one more run of a case (a master's or the monolithic one)."""
    if case.kind == "monolithic":
        e = scene.experiment
        times = np.linspace(e.start, e.stop, int(round((e.stop - e.start) / case.step)) + 1)
        return reference.solve(scene, times, use_cache=False, rtol=case.tolerance,
                               atol=case.tolerance * 1e-2).wall_time
    options = {"tolerance": case.tolerance} if case.tolerance is not None else {}
    result = simulate(scene, case.engine, case.step, fmu_dir, options=options)
    interrupt.check()
    if not result.ok:
        raise RuntimeError(f"{case.label} failed when run again: {result.failure}")
    return result.wall_time


def _median_prices(runs: list[dict]) -> dict:
    """Component -> kind -> the median price over ``runs`` of ``call_prices``."""
    return {name: {kind: stats.median(run[name][kind] for run in runs) for kind in runs[0][name]}
            for name in runs[0]}


def eigenfrequency(scene: scenes.Scene) -> float | None:
    """The coupling mode's eigenfrequency estimate [rad/s]; None for a scene of another kind."""
    try:
        built = kinds.physics(scene)
    except kinds.NotADriveline:
        return None
    i1, i2 = metrics.inertias(scene)
    return built.coupling.eigen_estimate(i1, i2)[0]


def _line(case: Case) -> str:
    if case.failure:
        return f"  {case.label:34s} FAILED: {case.failure[:150]}"
    return (f"  {case.label:34s} {case.wall:8.3f} s  tau rms {100 * case.errors.get('tau_rms', math.nan):9.4f} %"
            f"  ({case.steps} steps)")


def bracket(cases: list[Case], target: float, key: str = "tau_rms") -> list[Case]:
    """The runs a curve's time at ``target`` is read from: the cheapest run at or below
    the target and the dearest cheaper run above it (if any); [] when no run reaches it."""
    points = sorted((c.wall, c.errors[key], k) for k, c in enumerate(cases) if c.stable and key in c.errors)
    good = [p for p in points if p[1] <= target]
    if not good:
        return []
    w1, e1, k1 = min(good)
    worse = [p for p in points if p[1] > target and p[0] < w1]
    if not worse:
        return [cases[k1]]
    w0, e0, k0 = max(worse)
    return [cases[k1]] if e0 <= e1 else [cases[k1], cases[k0]]


def interpolate(target: float, good: tuple[float, float], worse: tuple[float, float] | None = None) -> float:
    """Run time at ``target`` between (time, error) points either side: log-log."""
    w1, e1 = good
    if worse is None or worse[1] <= e1:
        return w1
    w0, e0 = worse
    x = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return math.exp(math.log(w0) + x * (math.log(w1) - math.log(w0)))


def time_at_error(cases: list[Case], target: float, key: str = "tau_rms") -> float | None:
    """Run time at which a master's curve reaches ``target``: log-log interpolation
    between the cheapest run at or below it and the dearest run above it (None when no
    run reaches it)."""
    pair = bracket(cases, target, key)
    if not pair:
        return None
    return interpolate(target, *((c.wall, c.errors[key]) for c in pair))


def _by_engine(cases: list[Case]) -> dict[str, list[Case]]:
    by_engine: dict[str, list[Case]] = {}
    for case in cases:
        by_engine.setdefault(case.engine if case.kind != "monolithic" else "monolithic", []).append(case)
    return by_engine


def _round_times(group: list[Case], target: float, walls: dict[str, list[float]]) -> list[float] | None:
    """A curve's time at the target in each round (its bracket's runs of that round)."""
    pair = bracket(group, target)
    if not pair or any(_key(c) not in walls for c in pair):
        return None
    series = [walls[_key(c)] for c in pair]
    return [interpolate(target, *((w[k], c.errors["tau_rms"]) for w, c in zip(series, pair)))
            for k in range(min(len(w) for w in series))]


def _unpaired(a: float | None, b: float | None) -> dict | None:
    """A ratio of two medians measured apart (no rounds): said so, never as a spread."""
    if not a or not b:
        return None
    return {"median": a / b, "min": None, "max": None, "n": 0, "ratios": [], "single_run": False,
            "interleaved": False}


def claims(scene: scenes.Scene, cases: list[Case], p: dict, hollow_per_step: float | None = None,
           rounds: dict | None = None, machine: dict | None = None) -> dict:
    """What the benchmark shows, computed from the cases (not asserted).  Each headline
    ratio is the median of the ratios of ``rounds`` (the cases it divides, run side by side
    round after round: ``measure_rounds``) with their range; without rounds, the ratio of
    the two medians, marked as not measured side by side."""
    target = p["target_error"]
    by_engine = _by_engine(cases)
    at_target = {name: time_at_error(group, target) for name, group in by_engine.items()}
    walls = (rounds or {}).get("walls") or {}
    per_round = {name: _round_times(group, target, walls) for name, group in by_engine.items()}

    def ratio(a: str | Case, b: str | Case, a_value=None, b_value=None) -> dict | None:
        sa = per_round.get(a) if isinstance(a, str) else walls.get(_key(a))
        sb = per_round.get(b) if isinstance(b, str) else walls.get(_key(b))
        if sa and sb and len(sa) == len(sb):
            return {**trust.paired_ratio(sa, sb), "interleaved": True}
        return _unpaired(a_value, b_value)

    baseline = p["baseline"]
    base_time = at_target.get(baseline)
    ranked = sorted(((t, n) for n, t in at_target.items() if t is not None and n in master_family.MASTERS))
    out = {"target_error": target, "time_at_target_s": at_target, "baseline": baseline, "ratios": {},
           "machine": machine,
           "time_at_target_side_by_side": {n: trust.spread(t) for n, t in per_round.items() if t}}
    if ranked:
        best_time, best = ranked[0]
        out["best_master"] = best
        r = ratio(baseline, best, base_time, best_time) if base_time else None
        out["speedup_over_baseline"] = r["median"] if r else None
        out["ratios"]["speedup_over_baseline"] = r
        out["peers_at_target_s"] = {n: t for n, t in at_target.items() if n not in master_family.MASTERS}
        if at_target.get("monolithic"):
            r = ratio(best, "monolithic", best_time, at_target["monolithic"])
            out["best_master_over_monolithic"] = r["median"]
            out["ratios"]["best_master_over_monolithic"] = r
    # One baseline step at the scene's step against the same calls into do-nothing FMUs,
    # taken round by round (the floor is timed in each round beside the step).
    hollow_rounds = (rounds or {}).get("hollow_floor") or []
    if hollow_per_step or hollow_rounds:
        at_step = [c for c in cases if c.engine == baseline and c.kind == "master" and c.tolerance is None
                   and c.stable and c.steps and c.step == scene.experiment.step]
        if at_step:
            case = at_step[0]
            steps_walls = walls.get(_key(case))
            if steps_walls and hollow_rounds and len(steps_walls) == len(hollow_rounds):
                per_step_runs = [w / case.steps for w in steps_walls]
                r = {**trust.paired_ratio(per_step_runs, hollow_rounds), "interleaved": True}
                per_step, floor = stats.median(per_step_runs), stats.median(hollow_rounds)
            else:
                per_step, floor = case.wall / case.steps, hollow_per_step
                r = _unpaired(per_step, floor)
            b = {"step": scene.experiment.step, "per_step_s": per_step, "hollow_floor_per_step_s": floor,
                 "over_hollow_floor": r["median"], "ratio": r}
            problems = [trust.floor_problem(floor, per_step)]
            if r.get("min") is not None and r["min"] < 1.0:
                problems.append(f"in {sum(x < 1.0 for x in r['ratios'])} of {r['n']} rounds the do-nothing "
                                "floor was above the step it bounds")
            if case.split and not case.split_unreliable and not case_problems(case):
                # What our slaves do behind the calls bounds the ratio from below: a master
                # that cost nothing would still pay the crossings and the slaves' own work.
                # Both from the call prices, ours and the twins' timed back to back around
                # the case's runs (not the rounds' floor, timed at other moments).
                slave = case.split["slave"] / case.steps
                b.update({"slave_per_step_s": slave,
                          "bound_without_master": (case.split["crossing"] + case.split["slave"])
                          / case.split["crossing"]})
                problems.append(trust.bound_problem(b["bound_without_master"], r))
            elif case.split_unreliable or case.split:
                b["bound_unreliable"] = case.split_unreliable or "; ".join(case_problems(case))
            verdict = trust.judged(r["median"], problems, trust.noise(machine, trust.spread(steps_walls or [])))
            if not verdict["reliable"]:
                b["unreliable"] = verdict["reason"]
            out["baseline_step"] = b
            out["ratios"]["baseline_step_over_hollow_floor"] = r
    # Harness overhead above the FMU-call floor, fixed-step zero-order-hold masters: each
    # run over the floor timed just before it.
    overhead = {}
    for case in cases:
        if case.kind == "master" and case.stable and case.floor_time and case.tolerance is None:
            o = overhead_above_floor(case)
            if o is not None:
                overhead.setdefault(case.engine, []).append(o)
    out["overhead_above_floor"] = {n: stats.median(v) for n, v in overhead.items()}
    # Stability: the largest stable step of the baseline, and which masters stay stable
    # at h * omega_n >= 5 with a bounded energy residual.
    omega = eigenfrequency(scene)
    if omega:
        stable_base = [c for c in by_engine.get(baseline, []) if c.stable and c.tolerance is None]
        if stable_base:
            largest = max(stable_base, key=lambda c: c.step)
            # the bar for the stiff case: the target reached in a tenth of this
            fractions, faster = {}, {}
            for n, t in at_target.items():
                if t is not None and n in master_family.MASTERS and n != baseline:
                    r = ratio(n, largest, t, largest.wall)
                    fractions[n] = r["median"]
                    faster[n] = ratio(largest, n, largest.wall, t)
            out["largest_stable_baseline_step"] = {"step": largest.step, "h_omega": largest.step * omega,
                                                   "wall_s": largest.wall, "runs": len(largest.wall_times),
                                                   "asked": largest.asked, "time_fraction_at_target": fractions,
                                                   "faster": faster}
            if walls.get(_key(largest)):
                out["largest_stable_baseline_step"]["wall_spread_side_by_side"] = trust.spread(walls[_key(largest)])
        large = {}
        for c in cases:
            if c.kind != "master":
                continue
            # a fixed-step run at its step; an adaptive one by the longest step it took
            step = c.step if c.tolerance is None else c.largest_step
            if step is not None and step * omega >= 5.0:
                large.setdefault(c.engine, []).append(
                    {"step": step, "h_omega": step * omega, "stable": c.stable, "tolerance": c.tolerance,
                     "energy_residual": c.energy_residual, "tau_rms": c.errors.get("tau_rms")})
        out["at_h_omega_5_or_more"] = large
    return out


def overhead_above_floor(case: Case) -> float | None:
    """A master's run time above the FMU-call floor: the median over its runs of each run
    over the floor timed just before it (over the median floor for a case without)."""
    if not (case.steps and case.wall_times):
        return None
    if case.floor_times and len(case.floor_times) == len(case.wall_times):
        return trust.paired_ratio(case.wall_times, [f * case.steps for f in case.floor_times])["median"] - 1.0
    return case.wall / case.floor_time - 1.0 if case.floor_time else None


def case_problems(case: Case) -> list[str]:
    """What makes a case's run time no result: fewer runs than asked (a failed case made
    its one run), a call floor above the step it bounds."""
    problems = []
    if not case.failure and case.asked:
        problems.append(trust.runs_problem(len(case.wall_times), case.asked, max(case.wall_times, default=None)))
    if case.kind == "master" and case.floor_times and case.steps and case.wall_times:
        problems.append(trust.floor_problem(stats.median(case.floor_times), case.wall / case.steps))
    return [p for p in problems if p]


# -- writing ------------------------------------------------------------------------------------------------

COLUMNS = ["engine", "kind", "step", "tolerance", "wall_median_s", "wall_min_s", "wall_max_s", "repeats", "asked",
           "load_min", "load_max", "unreliable", "steps", "fmu_calls", "rollbacks", "floor_s", "overhead_above_floor",
           "tau_rms", "tau_max", "w_rms", "w_max", "tau_rms_after_transient", "w_rms_after_transient",
           "energy_residual", "calls_per_step", "crossing_s", "slave_s", "master_s", "split_unreliable", "failure"]


def table_row(case: Case) -> dict:
    """A case as a row of the benchmark's tables (CSV and report).  A case whose run time
    is no result (``case_problems``) says why in ``unreliable``; a split that cannot be
    (``split_case``) is left out, the reason in ``split_unreliable``."""
    problems = case_problems(case)
    overhead = overhead_above_floor(case) if case.floor_time and case.stable and not problems else None
    spread = trust.spread(case.wall_times)
    loads = [x for x in case.load if x is not None]
    split = None if case.split_unreliable or problems else case.split      # a split of no result is none
    return {"engine": case.engine, "kind": case.kind, "step": case.step, "tolerance": case.tolerance,
            "wall_median_s": case.wall, "wall_min_s": spread["min"], "wall_max_s": spread["max"],
            "repeats": len(case.wall_times), "asked": case.asked or None,
            "load_min": min(loads) if loads else None, "load_max": max(loads) if loads else None,
            "unreliable": ("; ".join(problems) + f": {case_noise(case, problems)}") if problems else None,
            "steps": case.steps, "fmu_calls": case.fmu_calls, "rollbacks": case.rollbacks, "floor_s": case.floor_time,
            "overhead_above_floor": overhead, **{k: case.errors.get(k) for k in
                                                 ("tau_rms", "tau_max", "w_rms", "w_max", "tau_rms_after_transient",
                                                  "w_rms_after_transient")},
            "energy_residual": case.energy_residual,
            "calls_per_step": (sum(sum(k.values()) for k in case.calls_by_kind.values()) / case.steps
                               if case.calls_by_kind and case.steps else None),
            **{f"{part}_s": (split or {}).get(part) for part in ("crossing", "slave", "master")},
            "split_unreliable": case.split_unreliable, "failure": case.failure}


def write(out: Path, result: dict) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    rows = [table_row(c) for c in result["cases"]]
    with open(out / "bench.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    payload = {k: v for k, v in result.items() if k != "cases"}
    payload["cases"] = rows
    (out / "bench.json").write_text(json.dumps(payload, indent=2, default=_json))
    (out / "bench.md").write_text(markdown(result, rows))
    paths = [out / "bench.csv", out / "bench.json", out / "bench.md"]
    paths.append(plot(out / "work_precision.png", result))
    return paths


def _json(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, Case):
        return asdict(x)
    raise TypeError(type(x))


def _pct(x):
    return "" if x is None or not math.isfinite(x) else f"{100 * x:.4g} %"


def machine_text(machine: dict | None) -> str:
    """The machine's load during a study, in words."""
    if not machine or machine.get("load_max") is None:
        return "Machine load not known (no load average on this system)."
    return (f"Machine: {machine['cpus']} CPUs, one-minute load average {machine['load_min']:.2f}-"
            f"{machine['load_max']:.2f} during the run (median {machine['load_median']:.2f}, "
            f"{machine['samples']} samples).")


def faster_text(r: dict | None) -> str:
    """``2.1x faster [1.9-2.3x, 3 pairs]`` or ``0.6x`` said as ``1.7x slower``."""
    if not r or r.get("median") is None:
        return "not measured"
    if r["median"] >= 1.0:
        return f"{trust.ratio_text(r, 1)} faster"
    inverse = {**r, "median": 1 / r["median"],
               "min": 1 / r["max"] if r.get("max") else None, "max": 1 / r["min"] if r.get("min") else None}
    return f"{trust.ratio_text(inverse, 1)} slower"


def _ratio(r: dict | None, digits: int = 2) -> str:
    return trust.ratio_text(r, digits)


def markdown(result: dict, rows: list[dict]) -> str:
    c = result["claims"]
    floor = result.get("floor_spread") or trust.spread([result["floor_per_step_s"]])
    hollow_floor = result.get("hollow_floor_spread")
    lines = [f"# Work-precision benchmark: {result['scene']}", "",
             f"Median [min-max] of up to {result['repeats']} repeats of the stepping loop; errors against the "
             f"monolithic reference (DOP853, rtol 1e-10), relative to the mean torque / speed, time-averaged RMS.  "
             f"FMU-call floor: {trust.spread_text(floor)} per communication step"
             + (f"; the same calls into do-nothing FMUs: {trust.spread_text(hollow_floor)}"
                if hollow_floor and hollow_floor.get("n") else "") + ".", "",
             machine_text(result.get("machine") or c.get("machine")), ""]
    if result.get("eigenfrequency_rad_s"):
        lines += [f"Coupling eigenfrequency omega_n = {result['eigenfrequency_rad_s']:.1f} rad/s.", ""]
    lines += ["| engine | step / tol | run time [min-max] | runs | steps | above floor | tau RMS | tau max | w RMS | "
              "tau RMS after transient | energy residual | note |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        setting = f"tol {r['tolerance']:g}" if r["tolerance"] is not None else f"h {r['step']:g} s"
        if r.get("unreliable"):
            wall = "unreliable"
        elif r.get("wall_min_s") is not None and r["repeats"] > 1:
            wall = f"{r['wall_median_s']:.3f} s [{r['wall_min_s']:.3f}-{r['wall_max_s']:.3f}]"
        else:
            wall = f"{r['wall_median_s']:.3f} s"
        note = "; ".join(x for x in ((r["failure"] or "")[:90], r.get("unreliable") or "") if x)
        runs = f"{r['repeats']}" + (f" of {r['asked']}" if r.get("asked") and r["asked"] != r["repeats"] else "")
        lines.append(f"| {r['engine']} | {setting} | {wall} | {runs} | {r['steps']} | "
                     f"{_pct(r['overhead_above_floor'])} | {_pct(r['tau_rms'])} | {_pct(r['tau_max'])} | "
                     f"{_pct(r['w_rms'])} | {_pct(r['tau_rms_after_transient'])} | "
                     f"{'' if r['energy_residual'] is None else format(r['energy_residual'], '.2e')} | {note} |")
    lines += ["", f"## At an RMS torque error of {_pct(c['target_error'])}", "",
              "| engine | run time (interpolated) | in the rounds side by side: median [min-max] |", "|---|---|---|"]
    side = c.get("time_at_target_side_by_side", {})
    for name, t in sorted(c["time_at_target_s"].items(), key=lambda kv: (kv[1] is None, kv[1] or 0)):
        lines.append(f"| {name} | {'not reached' if t is None else f'{t:.3f} s'} | "
                     f"{trust.spread_text(side[name]) if name in side else ''} |")
    ratios = c.get("ratios", {})
    if c.get("best_master"):
        speedup = ratios.get("speedup_over_baseline")
        lines += ["", f"Best master: **{c['best_master']}**, "
                  + (f"{faster_text(speedup)} than {c['baseline']}." if speedup else
                     f"({c['baseline']} does not reach the target).")]
        if ratios.get("best_master_over_monolithic"):
            lines[-1] += (f"  It takes {_ratio(ratios['best_master_over_monolithic'])} the time of the monolithic "
                          "solution (scipy DOP853 on the unsplit equations) at this error.")
        if c.get("ratios") is not None:
            lines += ["", "Each ratio is the median of the ratios of runs made side by side (the cases it divides "
                      "run in turn, round after round), with their range; the run times above are the cases' own "
                      "repeats, made one case after another."]
    split_rows = [r for r in rows if r.get("crossing_s") is not None or r.get("split_unreliable")
                  or (r["kind"] == "master" and r.get("unreliable") and r.get("calls_per_step"))]
    if split_rows:
        lines += ["", "## Where the time goes", "",
                  "Each master's run time split by the calls it made, priced call by call (component and kind: "
                  "get, set, step, state; each price timed call by call in the floor's loop at the case's step - "
                  "the scene's for adaptive masters - just before and just after the case's runs, their mean): "
                  "*crossing* the calls priced at the do-nothing twins of the FMUs (pythonfmu, an empty do_step), "
                  "*slave* the same calls priced at our FMUs minus that (our FMUs' work: the native entry, the "
                  "FMI glue and the physics), *master* the rest of the run time (the master's arithmetic and "
                  "Python, recording).  A split that cannot be (a share below zero, priced calls above the run "
                  "time: the prices and the runs saw different machines) is not shown.", "",
                  "| engine | step / tol | run time | FMI calls per step | crossing | slave | master |",
                  "|---|---|---|---|---|---|---|"]
        for r in split_rows:
            setting = f"tol {r['tolerance']:g}" if r["tolerance"] is not None else f"h {r['step']:g} s"
            wall = r["wall_median_s"]
            calls = "" if r["calls_per_step"] is None else f"{r['calls_per_step']:.1f}"
            if r.get("split_unreliable"):
                parts = f"unreliable: {r['split_unreliable']} | | "
            elif r.get("unreliable"):
                parts = "unreliable: its run time is (above) | | "
            else:
                parts = " | ".join(f"{r[f'{part}_s']:.3f} s ({100 * r[f'{part}_s'] / wall:.0f} %)"
                                   for part in ("crossing", "slave", "master"))
            shown = "unreliable" if r.get("unreliable") else f"{wall:.3f} s"
            lines.append(f"| {r['engine']} | {setting} | {shown} | {calls} | {parts} |")
    if c.get("baseline_step"):
        b = c["baseline_step"]
        if b.get("unreliable"):
            lines += ["", f"One {c['baseline']} step at h = {b['step']:g} s against the do-nothing FMUs' floor: "
                      f"unreliable ({b['unreliable']})."]
        else:
            lines += ["", f"One {c['baseline']} step at h = {b['step']:g} s: {b['per_step_s'] * 1e6:.1f} us, "
                      f"{_ratio(b['ratio'])} the do-nothing FMUs' floor for the same calls "
                      f"({b['hollow_floor_per_step_s'] * 1e6:.1f} us, timed in each round beside the step)."]
            if "bound_without_master" in b:
                lines[-1] += (f" Our slaves' own work behind those calls (the FMI glue and the physics) takes "
                              f"{b['slave_per_step_s'] * 1e6:.1f} us a step, so even a master that cost nothing "
                              f"would take {b['bound_without_master']:.2f}x the floor.")
            elif b.get("bound_unreliable"):
                lines[-1] += f" The bound without a master is not shown: its split is unreliable."
    if c.get("overhead_above_floor"):
        lines += ["", "Harness overhead above the FMU-call floor (each run over the floor timed just before it, "
                  "at the case's step; median over steps; masters that make more FMI calls per step than the "
                  "floor's one step and one propagation show those calls here too): "
                  + ", ".join(f"{n} {_pct(v)}" for n, v in c["overhead_above_floor"].items()) + "."]
    if c.get("largest_stable_baseline_step"):
        s = c["largest_stable_baseline_step"]
        side = s.get("wall_spread_side_by_side")
        short = s.get("asked") and s["runs"] < s["asked"]
        lines += ["", f"Largest stable {c['baseline']} step: {s['step']:g} s (h*omega_n = {s['h_omega']:.3g}), "
                  + (f"run time unreliable (from {s['runs']} of {s['asked']} runs)" if short
                     else f"run time {s['wall_s']:.3f} s")
                  + (f"; side by side with the masters below: {trust.spread_text(side)}" if side else "") + "."]
        faster = s.get("faster", {})
        for name, fraction in sorted(s.get("time_fraction_at_target", {}).items(), key=lambda kv: kv[1]):
            lines.append(f"- {name} reaches {_pct(c['target_error'])} RMS torque error in {fraction:.3f} of that "
                         f"run time ({faster_text(faster.get(name)) if faster.get(name) else ''}).")
    if c.get("at_h_omega_5_or_more"):
        lines += ["", "At h*omega_n >= 5 (adaptive runs: their longest step):"]
        for name, runs in c["at_h_omega_5_or_more"].items():
            for r in runs:
                setting = f"h = {r['step']:g} s" if r.get("tolerance") is None else \
                    f"tol {r['tolerance']:g}, longest step {r['step']:.3g} s"
                lines.append(f"- {name} {setting} (h*omega_n = {r['h_omega']:.2f}): "
                             + (f"stable, energy residual {r['energy_residual']:.2e}, tau RMS {_pct(r['tau_rms'])}"
                                if r["stable"] else "failed"))
    return "\n".join(lines) + "\n"


def summary_lines(result: dict) -> list[str]:
    """The benchmark's outcome in a few lines (what ``lever bench`` prints at the end)."""
    claims = result["claims"]
    lines, target = [], claims["target_error"]
    for name, t in claims["time_at_target_s"].items():
        lines.append(f"  at {100 * target:g} % RMS torque error: {name:26s} "
                     + ("not reached" if t is None else f"{t:.3f} s"))
    ratios = claims.get("ratios", {})
    if claims.get("best_master"):
        speedup = ratios.get("speedup_over_baseline")
        over = ratios.get("best_master_over_monolithic")
        lines.append(f"  best master: {claims['best_master']}"
                     + (f", {faster_text(speedup)} than {claims['baseline']}" if speedup else "")
                     + (f"; {_ratio(over)} the monolithic solution's time" if over else ""))
    if claims.get("baseline_step"):
        b = claims["baseline_step"]
        if b.get("unreliable"):
            lines.append(f"  one {claims['baseline']} step against the do-nothing floor: unreliable ({b['unreliable']})")
        else:
            lines.append(f"  one {claims['baseline']} step: {b['per_step_s'] * 1e6:.1f} us, {_ratio(b['ratio'])} "
                         f"the do-nothing FMUs' floor ({b['hollow_floor_per_step_s'] * 1e6:.1f} us, same calls)")
            if "bound_without_master" in b:
                lines.append(f"    our slaves' own work in it: {b['slave_per_step_s'] * 1e6:.1f} us; a master that "
                             f"cost nothing would take {b['bound_without_master']:.2f}x the floor")
    for case in result["cases"]:
        if case.split and case_problems(case):
            lines.append(f"  {case.label:34s} split unreliable: its run time is ({'; '.join(case_problems(case))})")
        elif case.split_unreliable:
            lines.append(f"  {case.label:34s} split unreliable: {case.split_unreliable}")
        elif case.split:
            lines.append(f"  {case.label:34s} " + ", ".join(
                f"{part} {100 * case.split[part] / case.wall:.0f} %" for part in ("crossing", "slave", "master")))
    if claims.get("overhead_above_floor"):
        lines.append("  above the FMU-call floor: " + ", ".join(
            f"{n} {100 * v:.0f} %" for n, v in claims["overhead_above_floor"].items()))
    lines.append("  " + machine_text(result.get("machine")))
    return lines


def plot(path: Path, result: dict) -> Path:
    from harness.formats import plotting

    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=(11, 6), layout="constrained")
    groups: dict[str, list[Case]] = {}
    for case in result["cases"]:
        key = case.engine if case.kind != "monolithic" else "monolithic (scipy DOP853)"
        groups.setdefault(key, []).append(case)
    for name, group in groups.items():
        points = sorted((c.wall, c.errors["tau_rms"], c.step) for c in group if c.stable and "tau_rms" in c.errors)
        if not points:
            continue
        kind = group[0].kind
        style = {"master": "-o", "peer": "--s", "monolithic": ":^"}[kind]
        line, = ax.loglog([p[0] for p in points], [100 * p[1] for p in points], style, label=name, markersize=4)
        if kind != "monolithic":       # each point's step, as the report's tables list them
            for wall, error, step in points:
                if step:
                    ax.annotate(f"{1e3 * step:g}", (wall, 100 * error), textcoords="offset points", xytext=(3, 3),
                                fontsize=6, color=line.get_color())
    target = result["claims"]["target_error"]
    ax.axhline(100 * target, color="grey", lw=0.8, ls="--", label=f"target error {100 * target:g} %")
    ax.set_xlabel("run time of the stepping loop [s] (median)")
    ax.set_ylabel("RMS torque error [% of mean torque]")
    ax.set_title(f"Work-precision, scene {result['scene']} (numbers: the communication step in ms)")
    ax.grid(True, which="both", alpha=0.3)
    plotting.legend_outside(ax)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "bench" / scene.name
