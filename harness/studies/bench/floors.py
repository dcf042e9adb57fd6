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
from harness.studies.bench.master_time import uninterrupted


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
    return floors_side_by_side([scene], n_steps, fmu_dir, step)[0]


def floors_side_by_side(versions: list[scenes.Scene], n_steps: int, fmu_dir: Path = FMUS,
                        step: float | None = None, chunk: int | None = None) -> list[float]:
    """``call_floor`` of each scene in ``versions`` (e.g. one scene with its FMUs' FMI 2.0
    and FMI 3.0 editions), all instantiated at once and taking turns every ``chunk``
    completed steps (default: all ``n_steps`` at once), so that each saw the machine the
    others saw; seconds per step of each."""
    loops = []
    try:
        for scene in versions:
            loops.append(_FloorLoop(scene, fmu_dir, step))
        _in_turns(loops, n_steps, chunk, _FloorLoop.advance)
        interrupt.check()
        return [loop.spent / n_steps for loop in loops]
    finally:
        for loop in loops:
            loop.free()


def _in_turns(loops: list, n_steps: int, chunk: int | None, run):
    """``run(loop, count)`` on each of ``loops`` in turn, ``chunk`` at a time (default all
    ``n_steps`` at once), until each has had ``n_steps``: side by side, each loop sees the
    machine the others saw."""
    given = [0] * len(loops)
    while any(k < n_steps for k in given):
        for i, loop in enumerate(loops):
            count = min(chunk or n_steps, n_steps - given[i])
            run(loop, count)
            given[i] += count


class _StepLoop:
    """One scene's system, initialized, its initial states kept to start again from where
    the motion diverges (``_start_again``), stepping by ``step`` (default the scene's) from
    the scene's start: what the floor's loop and the prices' loop share."""

    def __init__(self, scene: scenes.Scene, fmu_dir: Path, step: float | None):
        self.system = System(scene, fmu_dir, record=recorded_names(scene))
        self.states = None
        try:
            self.system.initialize()
            self.states = _initial_states(self.system)
            self._compile()
        except BaseException:
            self.free()
            raise
        self.h = step or scene.experiment.step
        self.start = self.t = scene.experiment.start
        self.done = 0

    def _compile(self):
        """The calls the loop makes, made once (the system is initialized)."""
        raise NotImplementedError

    def free(self):
        _free_states(self.states)
        self.states = None
        self.system.free()


class _FloorLoop(_StepLoop):
    """One scene's system making the floor's steps (``call_floor``) a number at a time."""

    def _compile(self):
        self.plan = self.system.floor_plan()
        self.spent = 0.0

    def advance(self, count: int):
        """``count`` more completed steps, their time added to ``spent``."""
        floor_step, timer, plan, h = self.system.floor_step, clock.perf_counter, self.plan, self.h
        t, spent, done, goal = self.t, self.spent, self.done, self.done + count
        last = timer()
        while done < goal:
            try:
                floor_step(t, h, plan)
            except FmuCallError as error:
                _start_again(self.system, self.states if t != self.start else None, self.start, error)
                t = self.start
                last = timer()
                continue
            now = timer()
            spent += now - last
            last = now
            done += 1
            t += h
        self.t, self.spent, self.done = t, spent, done


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
    return prices_side_by_side([scene], fmu_dir, n_steps, step)[0]


def prices_side_by_side(versions: list[scenes.Scene], fmu_dir: Path = FMUS, n_steps: int = 2000,
                        step: float | None = None, chunk: int | None = None) -> list[dict[str, dict[str, float]]]:
    """``call_prices`` of each scene in ``versions``, all instantiated at once and taking
    turns every ``chunk`` steps (default: all at once), the state calls too."""
    loops = []
    try:
        for scene in versions:
            loops.append(_PriceLoop(scene, fmu_dir, step))
        _in_turns(loops, n_steps, chunk, _PriceLoop.advance)
        # the timer's own share of an interval, taken from every timed call
        timer = clock.perf_counter
        empty = 0.0
        for _ in range(n_steps):
            started = timer()
            empty += timer() - started
        own = empty / n_steps
        prices = [loop.prices(own) for loop in loops]
        _in_turns(loops, n_steps, chunk, _PriceLoop.time_states)
        for loop, found in zip(loops, prices):
            for name, spent in loop.state_spent.items():
                found[name]["state"] = spent / (3 * n_steps)
        return prices
    finally:
        for loop in loops:
            loop.free()


class _PriceLoop(_StepLoop):
    """One scene's system making the floor's steps with every call timed on its own
    (``call_prices``), a number of steps at a time."""

    def _compile(self):
        system = self.system
        timer = clock.perf_counter
        self.spent = spent = {name: {"get": 0.0, "set": 0.0, "step": 0.0} for name in system.order}

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
        self.plan = FloorPlan(tuple(replace(call, do_step=timed(call.do_step, spent[call.component.name], "step"))
                                    for call in plan.steps),
                              [timed_visit(v) for v in plan.propagation], [timed_visit(v) for v in plan.rereads])
        # each completed step's seconds and calls by component and kind: a step interrupted by
        # another process is set aside (``master_time.uninterrupted``), as in the timed runs -
        # one interruption of milliseconds in a thousand calls of a microsecond each would
        # price every one of them several microseconds too high
        self.steps: list[tuple[dict, dict]] = []
        self.state_spent = {name: 0.0 for name in system.stateful
                            if system.components[name].description.coSimulation.canGetAndSetFMUstate}

    def advance(self, count: int):
        """``count`` more completed steps, their calls priced."""
        system, spent, steps, counted = self.system, self.spent, self.steps, self.system.calls_by_kind
        goal = self.done + count
        while self.done < goal:
            before = counted()
            kept = {name: dict(kinds) for name, kinds in spent.items()}
            try:
                system.floor_step(self.t, self.h, self.plan)
            except FmuCallError as error:
                # the failed step's calls are not priced (see call_floor)
                _start_again(system, self.states if self.t != self.start else None, self.start, error)
                for name in spent:
                    spent[name].update(kept[name])
                self.t = self.start
                continue
            after = counted()
            steps.append(({name: {kind: spent[name][kind] - kept[name][kind] for kind in spent[name]} for name in spent},
                           {name: {kind: after[name][kind] - before[name][kind] for kind in spent[name]}
                            for name in spent}))
            self.done += 1
            self.t += self.h

    def prices(self, own: float) -> dict[str, dict[str, float]]:
        """Seconds per call of each component and kind in the steps so far that were not
        interrupted (``master_time.uninterrupted``), less the timer's ``own``."""
        kept = [self.steps[k] for k in uninterrupted([sum(sum(kinds.values()) for kinds in spent.values())
                                                      for spent, _ in self.steps])]
        prices = {}
        for name, kinds in self.spent.items():
            prices[name] = {}
            for kind in kinds:
                made = sum(step_made[name][kind] for _, step_made in kept)
                if made:
                    spent = sum(step_spent[name][kind] for step_spent, _ in kept)
                    prices[name][kind] = max(0.0, spent / made - own)
        return prices

    def time_states(self, count: int):
        """``count`` rounds of getting, setting and freeing a state of each component that
        can roll back, timed into ``state_spent``."""
        timer = clock.perf_counter
        for name in self.state_spent:
            c = self.system.components[name]
            started = timer()
            for _ in range(count):
                state = c.save_state()
                c.restore_state(state, c.time)
                c.free_state(state)
            self.state_spent[name] += timer() - started


def time_split(wall: float, calls: dict[str, dict[str, int]], ours: dict[str, dict[str, float]],
               twins: dict[str, dict[str, float]]) -> dict[str, float] | None:
    """A run's time ``wall`` split by where it went, from the calls it made (component ->
    kind -> count) and the prices of a call (component -> kind -> seconds) into our FMUs
    (``ours``) and into their do-nothing twins (``twins``):

    * ``crossing``: the twins' prices times the calls - what the calls cost on the FMUs' own
      path (our native entry, its channel's bookkeeping, pythonfmu) with nothing behind it;
    * ``slave``: our prices minus the twins' times the calls - our FMUs' own work behind
      the calls (the FMI glue, the model's physics);
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
