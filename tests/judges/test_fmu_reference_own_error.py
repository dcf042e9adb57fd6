"""The made reference's own error (harness/judges/fmu_reference.py) against its true error.

Where the monolithic reference exists it is some 1e3 times more accurate than either made
reference (DOP853 at 1e-10), so the made reference's distance from it is its true error.
The promise: the error each made reference states of itself is not zero, is on the high
side of the true one (an estimate from a coarser solution: the looser CVODE run, the
extrapolation from the coarser two runs) and not absurdly so, and is what the report
says in words.  Read at a run's own times off the reference's grid, the spline's error is
added to it, never taken from it."""
from __future__ import annotations

import time

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


def _runs_seen(monkeypatch) -> list:
    """The runs a made reference is made of, as each came back (master, step, options, result)."""
    seen = []
    run = fmu_reference._grid_run

    def watched(plan, master, step, options=None):
        result = run(plan, master, step, options)
        seen.append((master, step, options, result))
        return result
    monkeypatch.setattr(fmu_reference, "_grid_run", watched)
    return seen


@pytest.mark.parametrize("source", ["model-exchange", "extrapolated"])
def test_the_stated_own_error_is_not_zero_and_bounds_the_true_error(source, plan, monkeypatch):
    times = _grid(plan)
    seen = _runs_seen(monkeypatch)
    made = fmu_reference.reference(plan, times, source=source)
    # what it says it is and what it cost: the runs it was made of
    h = fmu_reference.grid_step(plan)
    assert made.wall_time == pytest.approx(sum(result.wall_time for *_, result in seen), rel=1e-12)
    if source == "model-exchange":
        assert [(m, s, o) for m, s, o, _ in seen] == [("me-cvode", h, {"tolerance": fmu_reference.ME_TOLERANCE}),
                                                     ("me-cvode", h, {"tolerance": fmu_reference.ME_CHECK_TOLERANCE})]
        assert made.method == f"me-cvode rtol={fmu_reference.ME_TOLERANCE:g}" == "me-cvode rtol=1e-10"
        assert made.n_rhs == seen[0][3].counters["rhs"] > 0
    else:
        assert [(m, s) for m, s, *_ in seen] == [(fmu_reference.EXTRAPOLATED_MASTER, h / 2 ** k) for k in range(3)]
        assert made.method == (f"jacobi-linear at steps {h:.4g}, {h / 2:.4g}, {h / 4:.4g} s, "
                               "Richardson-extrapolated with order 2")
        assert made.n_rhs == sum(int(round(0.1 / (h / 2 ** k))) for k in range(3))
    truth = fmu_reference.reference(plan, times, source="monolithic")
    own = fmu_reference.own_error(plan.scene, made)
    true_error = fmu_reference.figure(fmu_reference.errors(plan.scene, made.times, made.traces, truth))
    assert own is not None and own > 0
    assert true_error <= own <= 1e3 * true_error, (source, own, true_error)
    # the check is a second solution, not the reference itself
    assert any(not np.array_equal(made.info["check"][k], made.traces[k]) for k in made.traces)
    said = fmu_reference.quality(made, own)
    assert f"about {100 * own:.2g} %" in said and "about 0 %" not in said
    how = {"model-exchange": f"the same run at rtol={fmu_reference.ME_CHECK_TOLERANCE:g}",
           "extrapolated": "the extrapolation from the coarser two runs"}[source]
    assert said == f"{made.method}; its own error about {100 * own:.2g} % (RMS, relative: {how})"
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


@pytest.mark.parametrize("master", ["adaptive", "me-cvode"])
def test_a_master_without_a_fixed_order_is_not_extrapolated(master, plan):
    """Richardson's step needs the order the runs converge with: an adaptive master (whose
    order is its local one, not what halving its output step buys) and the Model Exchange
    master are refused with the sentence, before any run."""
    with pytest.raises(fmu_reference.ReferenceUnavailable) as refused:
        fmu_reference.reference(plan, _grid(plan), source="extrapolated", master=master, use_cache=False)
    assert str(refused.value) == (f"master '{master}' has no fixed convergence order to extrapolate with "
                                  "(an adaptive or Model Exchange master)")


def test_a_third_order_master_is_extrapolated_with_its_own_order(fmu_dir):
    """jacobi-quadratic converges at order 3: the extrapolation fine + (fine - middle) / (2**3 - 1)
    cancels the leading error term, so the made reference is at least ten times closer to the
    monolithic one than the finest of its runs (step h / 4) on its own."""
    from harness.engine.run import simulate

    short = plans.check(scenes.load("kavz685").with_overrides(["experiment.stop=0.02"]), fmu_dir=fmu_dir)
    h = fmu_reference.grid_step(short)
    times = np.linspace(0.0, 0.02, int(round(0.02 / h)) + 1)
    started = time.perf_counter()
    made = fmu_reference.reference(short, times, source="extrapolated", master="jacobi-quadratic", use_cache=False)
    elapsed = time.perf_counter() - started
    assert made.info["order"] == 3 and made.method.endswith("Richardson-extrapolated with order 3")
    assert made.info["master"] == "jacobi-quadratic"
    assert all(abs(o - 3.0) <= fmu_reference.ORDER_SLACK for o in made.info["observed_orders"].values())
    # its cost: the three runs' steps (0.02 s at h, h / 2, h / 4) and their time, within the call's
    assert made.n_rhs == sum(int(round(0.02 / (h / 2 ** k))) for k in range(3))
    assert 0.0 < made.wall_time <= elapsed
    assert made.method.startswith(f"jacobi-quadratic at steps {h:.4g}, {h / 2:.4g}, {h / 4:.4g} s")
    truth = fmu_reference.reference(short, times, source="monolithic", use_cache=False)
    finest = simulate(short, "jacobi-quadratic", h / 4)
    assert np.allclose(finest.times[::4], times, rtol=0.0, atol=1e-12)
    alone = fmu_reference.figure(fmu_reference.errors(short.scene, times, {k: v[::4] for k, v in finest.traces.items()},
                                                      truth))
    extrapolated = fmu_reference.figure(fmu_reference.errors(short.scene, times, made.traces, truth))
    assert extrapolated <= 0.1 * alone, (extrapolated, alone)


def test_runs_off_their_order_are_refused_with_the_steps_and_orders_seen(fmu_dir):
    """The freewheel's own integrator, not the master, sets its error: its runs converge
    faster than the master's order 2.  The refusal names the steps (the grid's, by
    ``grid_step``, halved twice) and each signal's observed order."""
    short = plans.check(scenes.load("freewheel_rectifier").with_overrides(["experiment.stop=0.02"]), fmu_dir=fmu_dir)
    h = fmu_reference.grid_step(short)
    with pytest.raises(fmu_reference.ReferenceUnavailable) as refused:
        fmu_reference.reference(short, np.linspace(0.0, 0.02, 101), source="extrapolated", use_cache=False)
    said = str(refused.value)
    assert said.startswith(f"no extrapolated reference: jacobi-linear at steps {h:.4g}, {h / 2:.4g}, {h / 4:.4g} s "
                           "does not show its order 2 (observed: ")
    assert said.endswith("; the runs are not in their asymptotic range")
    observed = dict(item.rsplit(" ", 1) for item in said.split("(observed: ")[1].split(")")[0].split(", "))
    assert observed and all(abs(float(o) - 2.0) > fmu_reference.ORDER_SLACK for o in observed.values())
