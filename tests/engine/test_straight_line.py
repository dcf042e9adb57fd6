"""Plans compiled to straight-line Python (``harness.engine.straight_line``) make the calls
the interpreting loops make (``System.step_with``, ``System.interpret``), in their order,
with the same arguments and counters, and fail the same way; a failing line shows in a
traceback."""
from __future__ import annotations

import traceback

import numpy as np
import pytest

from harness.description import scene
from harness.engine import run
from harness.engine.component import step_call
from harness.engine.interface import CallCounts
from harness.engine.straight_line import straight_line
from harness.engine.system import Copy, Send, StepCall, System, Visit


class Stub(CallCounts):
    """A component as a plan sees it: counters, a name, ``fail`` noted (and raised)."""

    def __init__(self, name, log):
        self.name, self.log = name, log
        self._start_counts()
        self.time = 0.0

    def fail(self, call, status):
        self.log.append(("fail", self.name, call, status))
        raise RuntimeError(f"{self.name}: {call} -> {status}")


def _plan(log, statuses):
    """Two readers and one target, every raw call logged with its arguments; ``statuses``
    maps a call (kind, component) to the status it returns (0 otherwise)."""
    a, b, c = (Stub(n, log) for n in "abc")

    def raw(kind, who):
        def call(handle, first, second, third):
            if kind == "step":
                log.append((kind, who.name, handle, first, second, third))
            else:
                log.append((kind, who.name, handle, list(first), int(second), list(third)))
                if kind == "get":        # a read fills its buffer: the outputs a's 1, 2, b's 10
                    for k in range(len(third)):
                        third[k] = {"a": 1.0 + k, "b": 10.0 + k}[who.name]
            return statuses.get((kind, who.name), 0)
        return call

    outputs_a, outputs_b, inputs_c = [0.0, 0.0], [0.0], [0.0, 0.0, 0.0]
    send = Send(c, raw("set", c), "hc", [7, 8, 9], 3, inputs_c)
    visits = [Visit(a, raw("get", a), "ha", [1, 2], 2, outputs_a, (Copy(inputs_c, ((0, 1), (2, 0))),), ()),
              Visit(b, raw("get", b), "hb", [3], 1, outputs_b, (Copy(inputs_c, ((1, 0),)),), (send,)),
              Visit(None, None, None, None, 0, None, (), (send,))]
    steps = (StepCall(a, raw("step", a), "ha"), StepCall(b, raw("step", b), "hb"))
    return (a, b, c), steps, visits, inputs_c


def _interpreted(steps, visits, t, h):
    System.step_with(steps, t, h)
    System.interpret(visits)


@pytest.mark.parametrize("refused", [None, ("step", "b"), ("get", "a"), ("get", "b"), ("set", "c")])
def test_the_generated_function_makes_the_interpreters_calls(refused):
    outcomes = []
    for make in (lambda steps, visits: lambda t, h: _interpreted(steps, visits, t, h),
                 lambda steps, visits: straight_line("test", visits, steps)):
        log = []
        components, steps, visits, inputs = _plan(log, {refused: 3} if refused else {})
        run_step = make(steps, visits)
        try:
            run_step(0.25, 1e-3)
            raised = None
        except RuntimeError as error:
            raised = str(error)
        outcomes.append((log, raised, list(inputs),
                         [(c.gets, c.sets, c.steps, c.time) for c in components]))
    assert outcomes[0] == outcomes[1]
    log, raised, inputs, counters = outcomes[1]
    if refused is None:
        # the copies by hand: c's inputs are a's second output, b's, a's first
        assert inputs == [2.0, 10.0, 1.0] and raised is None
        assert [entry[:2] for entry in log] == [("step", "a"), ("step", "b"), ("get", "a"), ("get", "b"),
                                               ("set", "c"), ("set", "c")]
        assert log[4] == ("set", "c", "hc", [7, 8, 9], 3, [2.0, 10.0, 1.0])
        assert counters == [(1, 0, 1, 0.25 + 1e-3), (1, 0, 1, 0.25 + 1e-3), (0, 2, 0, 0.0)]
    else:
        kind, who = refused
        call = {"get": "fmi2GetReal", "set": "fmi2SetReal", "step": step_call(0.25, 1e-3)}[kind]
        assert log[-1] == ("fail", who, call, 3) and raised == f"{who}: {call} -> 3"


def test_no_steps_given_and_none_to_make_differ():
    """A function of steps takes ``(t, h)`` also where there are none to make (a scene without
    feedthrough components); a function of visits alone takes nothing."""
    log = []
    _, _, visits, _ = _plan(log, {})
    straight_line("test", (), ())(0.0, 0.1)
    straight_line("test", visits)()
    assert [entry[:2] for entry in log] == [("get", "a"), ("get", "b"), ("set", "c"), ("set", "c")]


def test_a_failing_line_shows_in_the_traceback():
    log = []
    _, steps, visits, _ = _plan(log, {("get", "b"): 4})
    run_step = straight_line("test", visits, steps)
    with pytest.raises(RuntimeError) as caught:
        run_step(0.0, 0.1)
    shown = "".join(traceback.format_tb(caught.tb))
    assert "component1.fail('fmi2GetReal', status)" in shown and "<harness test " in shown
    assert "status = get_real1(handle1, vrs1, count1, outputs1)    # fmi2GetReal of b: 1 outputs" in run_step.source


def test_the_same_plan_is_compiled_once():
    """Two runs' functions of the same plan share one compiled maker (one ``linecache`` entry),
    each bound to its own run's objects."""
    log = []
    first = straight_line("test", *reversed(_plan(log, {})[1:3]))
    second = straight_line("test", *reversed(_plan(log, {})[1:3]))
    assert first.source == second.source and first.__code__ is second.__code__
    assert first.__closure__[0].cell_contents is not second.__closure__[0].cell_contents


def test_a_name_cannot_end_its_comment():
    """A component named with a line break stays inside its comment in the generated source."""
    log = []
    (_, _, c), steps, visits, _ = _plan(log, {})
    c.name = "c\nraise SystemExit"
    run_step = straight_line("test", visits, steps)
    run_step(0.0, 0.1)
    assert "# fmi2SetReal of c\\nraise SystemExit: 3 inputs" in run_step.source
    assert not any(line.strip().startswith("raise SystemExit") for line in run_step.source.splitlines())


def test_a_run_with_the_generated_plans_is_the_run_with_the_interpreted_ones(monkeypatch):
    """A whole jacobi-quadratic run: the same traces and FMI calls when every plan is walked
    by the interpreting loops instead."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.02", "experiment.transient=0"])
    generated = run.simulate(spec, master="jacobi-quadratic", step=1e-3)

    def interpreting(self, plan, steps=None):
        if steps is None:
            return lambda: System.interpret(plan)
        return lambda t, h: _interpreted(steps, plan, t, h)

    def calling_the_interpreter(source, plan):
        # the masters' own generated lines kept, the plan in them walked
        source.line(f"interpret({source.name(plan, 'plan')})")
        source.bound["interpret"] = System.interpret

    monkeypatch.setattr(System, "runner", interpreting)
    monkeypatch.setattr("harness.engine.masters.explicit.add_visits", calling_the_interpreter)
    interpreted = run.simulate(spec, master="jacobi-quadratic", step=1e-3)
    assert generated.ok and interpreted.ok
    timed = {"setup_time"}
    assert {k: v for k, v in generated.counters.items() if k not in timed} == \
        {k: v for k, v in interpreted.counters.items() if k not in timed}
    assert generated.counters["calls_by_kind"]["coupling"]["get"] >= 20
    for name, trace in generated.traces.items():
        assert np.array_equal(trace, interpreted.traces[name]), name


def test_the_guards_generated_check_is_its_loop():
    """Every checked output of kavz685 in turn made NaN, +-inf or twice its bound: the
    generated check and the loop raise the same ``Diverged``, and pass the same values."""
    from harness.description import plan as plans
    from harness.engine.guard import Diverged, Guard

    system = System(plans.check(scene.load("kavz685")))
    try:
        system.initialize()
        guard = Guard(system, "jacobi", 1e-3)
        assert len(guard._checks) >= 6
        guard.check(0.0, 0)
        guard.interpret(0.0, 0)
        seen = set()
        for values, i, low, high, k in guard._checks:
            kept = values[i]
            # +-inf fail a bound that only asks for a finite value too
            for bad in (float("nan"), float("inf"), -float("inf"), 2.0 * high if high < 1e300 else None):
                if bad is None:
                    continue
                values[i] = bad
                raised = []
                for check in (guard.check, guard.interpret):
                    with pytest.raises(Diverged) as caught:
                        check(0.5, 7)
                    raised.append((str(caught.value), repr(caught.value.diagnosis)))
                assert raised[0] == raised[1]
                seen.add(caught.value.diagnosis["variable"])
            values[i] = kept
        assert {"tau1", "tau2", "w"} <= seen
    finally:
        system.free()


def _hold_by_loop(master, weights, pasts, h, predict, rest_only):
    """The extrapolating masters' hold as a loop over the inputs and the points: each sum
    from 0.0 over the points in their order."""
    ends = [] if predict else None
    for k, i, values, n, ramped, higher in (master._rest_inputs if rest_only else master._held_inputs):
        mean = change = end = 0.0
        for (w_mean, w_slope, w_end), inputs in zip(weights, pasts):
            u = inputs[k][i]
            mean += w_mean * u
            change += w_slope * u
            end += w_end * u
        if ramped:
            values[i] = mean - 0.5 * change
            values[n + i] = change / h
            for j in higher:
                values[j] = 0.0
        else:
            values[i] = mean
        if predict:
            if i == 0:
                ends.append([])
            ends[-1].append(end)
    return ends


@pytest.mark.parametrize("ramp", [True, False])
def test_the_generated_hold_is_the_loop_bit_for_bit(ramp):
    """Random weights and torques through one to four points, predicted or not, all inputs or
    those not sent ahead: the same writes and end values, bit for bit (the same scalar
    operations in the same order)."""
    import random

    from harness.description import plan as plans
    from harness.engine.masters import registry

    rng = random.Random(11)
    system = System(plans.check(scene.load("kavz685")))
    try:
        system.initialize()
        master = registry.make("jacobi-quadratic", system, 1e-3, ramp=ramp)
        assert bool(master._rest_inputs) is not ramp
        for points in (1, 2, 3, 4):
            for predict in (True, False):
                for rest_only in ((False, True) if master._rest_inputs else (False,)):
                    for _ in range(20):
                        weights = [tuple(rng.uniform(-3.0, 3.0) for _ in range(3)) for _ in range(points)]
                        pasts = [[[rng.uniform(-1e3, 1e3) for _ in range(held.n)] for held in master._held]
                                 for _ in range(points)]
                        h = rng.uniform(1e-5, 1e-2)
                        got = master._holder(points, predict, rest_only)(weights, pasts, h)
                        written = [list(held.values) for held in master._held]
                        for held in master._held:
                            held.values[:] = [0.0] * len(held.values)
                        expected = _hold_by_loop(master, weights, pasts, h, predict, rest_only)
                        assert got == expected
                        assert written == [list(held.values) for held in master._held]
    finally:
        system.free()


def _send_ahead_by_loop(master, history, first, second, scale, squared):
    """The extrapolating masters' end-of-step writes as a loop over the inputs and the past
    points: each sum from 0.0 over the points in their order, then the value now."""
    past = [p[1] for p in history]
    for k, i, values, now, n, higher in master._ahead_inputs:
        rate = curvature = 0.0
        for w_first, w_second, inputs in zip(first, second, past):
            u = inputs[k][i]
            rate += w_first * u
            curvature += w_second * u
        u = now[i]
        rate += first[-1] * u
        curvature += second[-1] * u
        values[i] = u
        values[n + i] = rate / scale
        if higher:
            values[2 * n + i] = curvature / squared


@pytest.mark.parametrize("name", ["jacobi-linear", "jacobi-quadratic"])
def test_the_generated_send_ahead_is_the_loop_bit_for_bit(name):
    import random

    from harness.description import plan as plans
    from harness.engine.masters import registry

    rng = random.Random(5)
    system = System(plans.check(scene.load("kavz685")))
    try:
        system.initialize()
        master = registry.make(name, system, 1e-3)
        assert master._ahead_inputs
        for points in (1, 2, 3):
            writer = master._ahead_writer(points)
            for _ in range(20):
                history = [(rng.uniform(0, 1), [[rng.uniform(-1e3, 1e3) for _ in range(held.n)]
                                                for held in master._held]) for _ in range(points)]
                for live in master._live:
                    live[:] = [rng.uniform(-1e3, 1e3) for _ in range(len(live))]
                first = [rng.uniform(-3, 3) for _ in range(points + 1)]
                second = [rng.uniform(-3, 3) for _ in range(points + 1)]
                scale = rng.uniform(1e-5, 1e-2)
                writer(history, first, second, scale, scale * scale)
                written = [list(held.values) for held in master._held]
                for held in master._held:
                    held.values[:] = [0.0] * len(held.values)
                _send_ahead_by_loop(master, history, first, second, scale, scale * scale)
                assert written == [list(held.values) for held in master._held]
    finally:
        system.free()


def test_calls_are_counted_once_a_run_and_a_stopped_run_counts_what_it_made():
    """A function counts its runs, its components add its calls of each kind a run; a run
    stopped by an exception inside a call (not a status) counts the calls up to and with it."""
    log = []
    (a, b, c), steps, visits, _ = _plan(log, {})
    run_step = straight_line("test", visits, steps)
    for k in range(3):
        run_step(0.1 * k, 0.1)
    assert [(x.gets, x.sets, x.steps) for x in (a, b, c)] == [(3, 0, 3), (3, 0, 3), (0, 6, 0)]
    assert run_step.tally.runs == 3 and a.calls == 6

    def raising(handle, vrs, n, values):
        raise KeyboardInterrupt
    broken = [visits[0], Visit(b, raising, "hb", [3], 1, [0.0], (), visits[1].sends), visits[2]]
    stopped = straight_line("test", broken, steps)
    with pytest.raises(KeyboardInterrupt):
        stopped(0.5, 0.1)
    # made: a's and b's steps, a's read, b's read (it raised): not c's two sets
    assert [(x.gets, x.sets, x.steps) for x in (a, b, c)] == [(4, 0, 4), (4, 0, 4), (0, 6, 0)]
    assert stopped.tally.runs == 0
