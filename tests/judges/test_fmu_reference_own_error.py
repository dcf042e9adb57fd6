"""The made reference's own error (harness/judges/fmu_reference.py) against its true error.

Where the monolithic reference exists it is some 1e3 times more accurate than either made
reference (DOP853 at 1e-10), so the made reference's distance from it is its true error.
The promise: the error each made reference states of itself is not zero, is on the high
side of the true one (an estimate from a coarser solution: the looser CVODE run, the
extrapolation from the coarser two runs) and not absurdly so, and is what the report
says in words.  Read at a run's own times off the reference's grid, the spline's error is
added to it, never taken from it."""
from __future__ import annotations

import numpy as np
import pytest

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.judges import fmu_reference


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def plan(fmu_dir):
    return plans.check(scenes.load("kavz685").with_overrides(["experiment.stop=0.1"]), fmu_dir=fmu_dir)


def _grid(plan):
    h = fmu_reference.grid_step(plan)
    return np.linspace(plan.experiment.start, plan.experiment.stop, int(round(0.1 / h)) + 1)


@pytest.mark.parametrize("source", ["model-exchange", "extrapolated"])
def test_the_stated_own_error_is_not_zero_and_bounds_the_true_error(source, plan):
    times = _grid(plan)
    made = fmu_reference.reference(plan, times, source=source)
    truth = fmu_reference.reference(plan, times, source="monolithic")
    own = fmu_reference.own_error(plan.scene, made)
    true_error = fmu_reference.figure(fmu_reference.errors(plan.scene, made.times, made.traces, truth))
    assert own is not None and own > 0
    assert true_error <= own <= 1e3 * true_error, (source, own, true_error)
    # the check is a second solution, not the reference itself
    assert any(not np.array_equal(made.info["check"][k], made.traces[k]) for k in made.traces)
    said = fmu_reference.quality(made, own)
    assert f"about {100 * own:.2g} %" in said and "about 0 %" not in said
    assert fmu_reference.summary(plan.scene, times, truth.traces, made)["reference"]["own_error_relative"] == own


def test_off_its_grid_the_spline_adds_to_the_stated_error(plan):
    on = _grid(plan)
    # the start, then every time half-way between two rows (a reference starts at the first time asked for)
    off = np.concatenate([on[:1], 0.5 * (on[1:] + on[:-1])])
    at_rows = fmu_reference.reference(plan, on, source="model-exchange")
    between = fmu_reference.reference(plan, off, source="model-exchange")
    assert at_rows.info["interpolated"] == 0 and between.info["interpolated"] == len(off) - 1
    own_on = fmu_reference.own_error(plan.scene, at_rows)
    own_off = fmu_reference.own_error(plan.scene, between)
    assert own_off > own_on > 0
    truth = fmu_reference.reference(plan, off, source="monolithic")
    true_off = fmu_reference.figure(fmu_reference.errors(plan.scene, off, between.traces, truth))
    assert true_off <= own_off
