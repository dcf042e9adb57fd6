"""The master's own time measured directly (harness.studies.bench.master_time): checked on a
clock that ticks once a read, where every figure is known by counting."""
from __future__ import annotations

import pytest

from harness.description import scene
from harness.engine.masters.explicit import JacobiMaster
from harness.studies.bench import floors, master_time


class Ticks:
    """A clock that advances one unit at each read; ``now`` may be moved on by hand (work
    that takes time)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        self.now += 1.0
        return self.now


def test_the_calibration_counts_the_timings_own_reads():
    # an empty interval spans one read; a wrapped call two reads, one of them outside the
    # interval; the step mark one read
    found = master_time.calibrate(Ticks(), n=50, repeats=2)
    assert found[4] == found[2] == {"inside": 1.0, "outside": 1.0}
    assert found["observer"] == 1.0


def test_each_steps_parts_by_hand():
    calibration = {4: {"inside": 0.1, "outside": 0.5}, 2: {"inside": 0.2, "outside": 0.9}, "observer": 0.3}
    # two steps of 11 four-argument calls: 100 and 120 units, 60 and 64 of them in the calls
    marks = [(0.0, 0.0, 0), (100.0, 60.0, 11), (220.0, 124.0, 22)]
    masters, in_calls, corrections = master_time.step_parts(marks, calibration)
    assert masters == pytest.approx([100 - 60 - 0.3 - 11 * 0.5, 120 - 64 - 0.3 - 11 * 0.5])
    assert in_calls == pytest.approx([60 - 11 * 0.1, 64 - 11 * 0.1])
    assert corrections == pytest.approx([0.3 + 5.5, 0.3 + 5.5])
    # two of the 22 calls saved or restored a state (two arguments): their own costs
    masters, in_calls, _ = master_time.step_parts(marks, calibration, state_calls=2)
    assert masters[0] == pytest.approx(100 - 60 - 0.3 - 10 * 0.5 - 1 * 0.9)
    assert in_calls[0] == pytest.approx(60 - 10 * 0.1 - 1 * 0.2)


def test_an_interrupted_step_is_set_aside():
    # whole steps 50, 52, 49.5, 290, 410, 190 and 51: those above 4 x the median (52) are set aside
    masters, in_calls = [10.0, 11.0, 10.5, 250.0, 10.0, 150.0, 11.0], [40.0, 41.0, 39.0, 40.0, 400.0, 40.0, 40.0]
    assert master_time.kept_steps(masters, in_calls) == [0, 1, 2, 5, 6]


@pytest.mark.parametrize("work, quoted", [(30.0, True), (7.0, False)])
def test_a_runs_master_time_is_what_the_master_spent(fmu_dir, monkeypatch, work, quoted):
    """Every step of a jacobi run takes ``work`` units of the master's own (the clock moved
    on inside its step) and the FMI calls none: the measurement finds exactly that, the
    timing's reads taken off.  With 7 units against 12 taken off (11 calls and the step
    mark) the correction outweighs the figure, which is then not quoted."""
    clock = Ticks()
    step_impl = JacobiMaster._step_impl

    def working(self, t, h):
        clock.now += work
        return step_impl(self, t, h)

    monkeypatch.setattr(JacobiMaster, "_step_impl", working)
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.01"])
    timed = master_time.measure(spec, "jacobi", 1e-3, fmu_dir=fmu_dir, runs=2, timer=clock,
                                calibration=master_time.calibrate(clock, n=50, repeats=2))
    # the stepping loop's calls alone: a jacobi step makes 11
    assert timed.steps == 10 and sum(sum(kinds.values()) for kinds in timed.calls.values()) == 110
    assert timed.masters == [work, work] and timed.in_calls == [0.0, 0.0]
    assert timed.corrections == [12.0, 12.0] and timed.dropped == [0.0, 0.0]
    assert timed.trusted is quoted
    if not quoted:
        assert timed.problems == ["the timing's own cost taken off (12000000.00 us a step) is 63 % of the raw "
                                  "master time (at most 50 % quoted)"]
    summary = timed.summary()
    assert summary["master_per_step_s"] == work and summary["share"] == 1.0
    # the split: the master's share of the run, nothing priced into the calls
    free = {name: {"get": 0.0, "set": 0.0, "step": 0.0} for name in ("engine", "coupling", "load")}
    split, problem = master_time.split(summary, free, wall=2.0)
    assert split == ({"crossing": 0.0, "slave": 0.0, "master": 2.0} if quoted else None)
    assert problem == (None if quoted else timed.problems[0])
    if quoted:
        # twins' prices above what was measured in the calls (none here): no split, and why
        priced = {**free, "load": {"get": 0.0, "set": 0.0, "step": 1.0}}
        assert master_time.split(summary, priced, wall=2.0) == (
            None, "load's step calls priced at the do-nothing twins' (1000000.0 us a call) come to more than "
                  "the time measured in them (0.0 us)")


def test_a_split_by_hand():
    # 100 steps of 20 us in the master and 80 us in 11 calls; the twins price the calls at 30 us a step
    timed = {"problems": [], "steps": 100, "master_per_step_s": 20e-6, "in_calls_per_step_s": 80e-6,
             "calls": {"c": {"get": 500, "step": 600}}, "in_call_s": {"c": {"get": 2e-3, "step": 6e-3}}}
    twins = {"c": {"get": 2e-6, "step": 3.333e-6}}
    split, problem = master_time.split(timed, twins, wall=0.02)
    crossing = (500 * 2e-6 + 600 * 3.333e-6) / 100                  # 29.998 us a step
    assert problem is None
    assert split == pytest.approx({"crossing": 0.02 * crossing / 100e-6, "slave": 0.02 * (80e-6 - crossing) / 100e-6,
                                   "master": 0.02 * 0.2})


def test_a_model_exchange_master_is_not_timed_call_by_call():
    timed = master_time.measure(scene.load("kavz685"), "me-cvode", 1e-3)
    assert not timed.trusted and "Model Exchange" in timed.problems[0]
    assert timed.summary() == {"problems": timed.problems}


@pytest.mark.parametrize("state_price_us, quoted", [(12.0, True), (60.0, False)])
def test_prices_above_a_few_calls_measured_time_refuse_the_split_only_where_a_share_would_move(state_price_us,
                                                                                              quoted):
    """100 steps of 100 us: 20 us the master's, 80 us in the calls (11 step calls a step priced
    at 3 us each). A start-up's 4 state calls measured at 10 us each and priced at 12 us: 8 us
    too many in the whole run, 0.08 us a step, 0.08 % of a step - the split
    stands with those calls all crossing (by hand: crossing (3300 + 40) us / 100 steps =
    33.4 us a step, slave 80 - 33.4 = 46.6 us, master 20 us, of 100 us). Priced at 60 us:
    200 us too many, 2 % of a step - refused, naming those calls."""
    timed = {"problems": [], "steps": 100, "master_per_step_s": 20e-6, "in_calls_per_step_s": 80e-6,
             "calls": {"load": {"step": 1100, "state": 4}},
             "in_call_s": {"load": {"step": 7960e-6, "state": 40e-6}}}
    twins = {"load": {"step": 3e-6, "state": state_price_us * 1e-6}}
    split, problem = master_time.split(timed, twins, wall=1.0)
    if quoted:
        assert problem is None
        assert split["crossing"] == pytest.approx(0.334) and split["slave"] == pytest.approx(0.466)
        assert split["master"] == pytest.approx(0.2)
    else:
        assert split is None
        assert problem == ("load's state calls priced at the do-nothing twins' (60.0 us a call) come to more than "
                           "the time measured in them (10.0 us)")


def test_reads_and_sets_priced_above_their_measured_time_refuse_the_split_as_any_kind():
    """The do-nothing twins cross by our FMUs' own path (a set kept and a read answered in
    their native entry, as ours are), so a read or a set has no exception: 100 steps, 50 us a
    step (10 us the master's, 40 us in the calls), reads measured at 1 us a call and priced
    at 4 us: 50 reads x 3 us = 150 us too many, 1.5 us a step, 3 % of a step - refused,
    naming those calls; priced at 1 us the split stands (by hand: crossing (100 + 50 + 600) us
    / 100 steps = 7.5 us a step, slave 40 - 7.5 = 32.5 us, master 10 us, of 50 us)."""
    timed = {"problems": [], "steps": 100, "master_per_step_s": 10e-6, "in_calls_per_step_s": 40e-6,
             "calls": {"load": {"set": 100, "get": 50, "step": 100}},
             "in_call_s": {"load": {"set": 100e-6, "get": 50e-6, "step": 3850e-6}}}
    split, problem = master_time.split(timed, {"load": {"set": 1e-6, "get": 4e-6, "step": 6e-6}}, wall=1.0)
    assert split is None
    assert problem == ("load's get calls priced at the do-nothing twins' (4.0 us a call) come to more than the "
                       "time measured in them (1.0 us)")
    split, problem = master_time.split(timed, {"load": {"set": 1e-6, "get": 1e-6, "step": 6e-6}}, wall=1.0)
    assert problem is None
    assert split == pytest.approx({"crossing": 0.15, "slave": 0.65, "master": 0.2})
    # the split from prices alone: the twins' prices times the calls, ours less theirs the slave's
    assert floors.time_split(1.0, {"load": {"set": 100, "get": 10}}, {"load": {"set": 2e-6, "get": 5e-6}},
                             {"load": {"set": 1.5e-6, "get": 4e-6}}) == \
        pytest.approx({"crossing": 190e-6, "slave": 60e-6, "master": 1.0 - 250e-6})
