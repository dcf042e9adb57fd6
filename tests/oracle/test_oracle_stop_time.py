"""A run ends at its stop time, whatever the step: the last communication point is the
stop time exactly, the last step is the short remainder, and the trace has one row per
point - for every master of the registry, fixed-step and adaptive, from start times
other than 0.

Expected values worked by hand (not by the run loop under test):

* start 0.05 s, stop 0.0623 s, step 1 ms: the span 12.3 ms takes 12 whole steps and one
  of 0.3 ms: 13 steps, 14 rows, points 0.050, 0.051, ..., 0.062, 0.0623.  (A step count
  rounded to the nearest, 12, would end at 0.062 s and drop the 0.3 ms.)
* start 0, stop 0.1 s, step 3 ms (the 10 s / 3 ms of a user, shortened): 33 whole steps
  and one of 1 ms: 34 steps, 35 rows, last step 1 ms.
* start 0.03 s, stop 0.035 s, step 1 ms: the step divides the span, 5 steps, 6 rows, all
  of 1 ms; in binary floating point 0.03 + 5 * 0.001 is 0.034999999999999996, so a loop
  that takes its last point from ``start + n * step`` ends one ulp short of the stop.
"""
from __future__ import annotations

import numpy as np
import pytest

from harness.description import scene as scenes
from harness.engine.masters.registry import MASTERS
from harness.engine.run import simulate

pytestmark = pytest.mark.oracle

#: (start, stop, step, steps, last step), typed from the docstring's arithmetic
EXPERIMENTS = [
    (0.05, 0.0623, 1e-3, 13, 0.3e-3),
    (0.0, 0.1, 3e-3, 34, 1e-3),
    (0.03, 0.035, 1e-3, 5, 1e-3),
]
FIXED = [name for name, cls in MASTERS.items() if not cls.adaptive]
ADAPTIVE = [name for name, cls in MASTERS.items() if cls.adaptive]


def _run(master, start, stop, step):
    spec = scenes.load("kavz685").with_overrides([f"experiment.start={start}", f"experiment.stop={stop}",
                                                  "experiment.transient=0"])
    result = simulate(spec, master=master, step=step)
    assert result.failure is None, result.failure
    return result


def test_the_registry_has_both_kinds_of_master():
    assert len(FIXED) >= 9 and len(ADAPTIVE) >= 2, (FIXED, ADAPTIVE)


@pytest.mark.parametrize("experiment", EXPERIMENTS, ids=lambda e: f"{e[0]}-{e[1]}s@{e[2]:g}")
@pytest.mark.parametrize("master", FIXED)
def test_a_fixed_step_run_ends_exactly_at_its_stop_time(fmu_dir, master, experiment):
    start, stop, step, steps, last = experiment
    result = _run(master, start, stop, step)
    times = result.times
    assert len(times) == steps + 1, (
        f"{master}: {len(times)} rows from {start} to {stop} s at {step:g} s, expected {steps + 1} "
        f"({steps} steps, the last {last:g} s): a partial last step dropped (or one too many)?")
    assert times[0] == start
    assert times[-1] == stop, (f"{master}: the run ended at t = {times[-1]!r} s, its stop time is {stop!r} s "
                               "(the last point must be the stop time exactly)")
    steps_taken = np.diff(times)
    assert steps_taken[-1] == pytest.approx(last, rel=1e-9, abs=1e-15), (
        f"{master}: the last step is {steps_taken[-1]:.6g} s, expected the remainder {last:g} s")
    assert np.allclose(steps_taken[:-1], step, rtol=1e-9, atol=1e-15), (
        f"{master}: steps before the last differ from {step:g} s: {steps_taken[:-1]}")
    assert result.counters["steps"] == steps


@pytest.mark.parametrize("experiment", EXPERIMENTS, ids=lambda e: f"{e[0]}-{e[1]}s@{e[2]:g}")
@pytest.mark.parametrize("master", ADAPTIVE)
def test_an_adaptive_run_ends_exactly_at_its_stop_time(fmu_dir, master, experiment):
    """An adaptive master chooses its steps (the experiment's step is its first): the
    points still start at the start time, rise strictly, end at the stop time exactly,
    one row per accepted step; its last step is clipped to what remains, never beyond
    the step it would have taken."""
    start, stop, step, _, _ = experiment
    result = _run(master, start, stop, step)
    times = result.times
    assert times[0] == start
    assert times[-1] == stop, f"{master}: the run ended at t = {times[-1]!r} s, its stop time is {stop!r} s"
    assert np.all(np.diff(times) > 0.0)
    assert len(times) == result.counters["steps"] + 1
