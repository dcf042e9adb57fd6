"""What the FMI calls alone cost: the FMU-call floor (one communication step of the calls
every master makes, and nothing else, timed through the engine's own ``System.floor_step``)
and the price of each call by component and kind, which split a master's run time into
the crossing into the FMUs, our FMUs' own work and the master's (``time_split``).  Timed
on our FMUs, and on their do-nothing twins (``do_nothing_twins``) for the crossing alone."""
from __future__ import annotations

import statistics as stats
import time as clock
from dataclasses import replace
from pathlib import Path

from harness.description import scene as scenes
from harness.engine import interrupt
from harness.description.plan import recorded_names
from harness.engine.component import FmuCallError
from harness.engine.system import FloorPlan, System
from harness.paths import FMUS


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
               twins: dict[str, dict[str, float]]) -> dict[str, float] | None:
    """A run's time ``wall`` split by where it went, from the calls it made (component ->
    kind -> count) and the prices of a call (component -> kind -> seconds) into our FMUs
    (``ours``) and into their do-nothing twins (``twins``):

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
            if kind not in ours.get(name, {}) or kind not in twins.get(name, {}):
                return None
            crossing += count * twins[name][kind]
            slave += count * (ours[name][kind] - twins[name][kind])
    return {"crossing": crossing, "slave": slave, "master": wall - crossing - slave}


def median_prices(runs: list[dict]) -> dict:
    """Component -> kind -> the median price over ``runs`` of ``call_prices``."""
    return {name: {kind: stats.median(run[name][kind] for run in runs) for kind in runs[0][name]}
            for name in runs[0]}
