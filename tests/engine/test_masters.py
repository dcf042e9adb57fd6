"""The master family: each master converges to the monolithic reference at the order it
promises, and the extrapolation weights are the ones the theory gives."""
from __future__ import annotations

import numpy as np
import pytest

from harness.engine import masters
from harness.judges import metrics
from harness.judges import monolithic
from harness.engine import run
from harness.engine.interface import CallCounts
from harness.description import scene

# 0.4 s: the start-up from 39 rad/s, where the errors are made (the observed orders are
# those of a 1 s run to the third decimal, within the same margins of at least 0.216)
SMOOTH = ["experiment.stop=0.4", "experiment.transient=0", "load.load_kind=constant"]


def test_extrapolation_weights_are_adams_bashforth_for_uniform_steps():
    assert np.allclose(masters.extrapolation_weights([0.9, 1.0], 1.0, 0.1)[0], [-0.5, 1.5])
    assert np.allclose(masters.extrapolation_weights([0.8, 0.9, 1.0], 1.0, 0.1)[0], np.array([5, -16, 23]) / 12)
    assert masters.extrapolation_weights([1.0], 1.0, 0.1) == ([1.0], [0.0], [1.0])   # zero-order hold


def test_extrapolation_weights_are_exact_for_polynomials_of_their_degree():
    # u = t^2 sampled at three (uneven) times, extrapolated over [1, 1.5]
    times = [0.2, 0.7, 1.0]
    mean, slope, end = masters.extrapolation_weights(times, 1.0, 0.5)
    u = np.square(times)
    assert np.dot(mean, u) == pytest.approx((1.5 ** 3 - 1.0) / 3 / 0.5, rel=1e-12)
    assert np.dot(end, u) == pytest.approx(1.5 ** 2, rel=1e-12)
    # The ramp with the same mean and first moment as t^2 on [1, 1.5] has the slope of
    # its least-squares line: for a parabola, its derivative at the midpoint.
    assert np.dot(slope, u) / 0.5 == pytest.approx(2 * 1.25, rel=1e-12)


# (the Model Exchange master takes no communication step: its error is CVODE's, whatever the
# output grid; tests/engine/test_model_exchange_master.py holds it to its tolerance)
@pytest.mark.parametrize("name", sorted(n for n, m in masters.MASTERS.items()
                                        if not m.adaptive and m.interface == "co-simulation"))
def test_master_converges_at_its_promised_order(name):
    spec = scene.load("kavz685").with_overrides(SMOOTH)
    errors = []
    for h in (2e-3, 1e-3, 5e-4):
        result = run.simulate(spec, master=name, step=h)
        assert result.ok, result.failure
        ref = monolithic.solve(spec, result.times)
        scales = metrics.error_scales(spec, ref.traces)
        e = metrics.errors(result.times, result.traces, ref.times, ref.traces, ["coupling.tau2"], scales)
        errors.append(e["coupling.tau2"]["rms"])
    observed = [np.log2(a / b) for a, b in zip(errors, errors[1:])]
    promised = masters.MASTERS[name].order
    assert all(promised - 0.25 <= o <= promised + 0.35 for o in observed), (
        f"{name} converges at order {observed}, it promises {promised} (errors {errors}): its scheme lost an order "
        "(e.g. an extrapolating master's weights of a lower degree)")


def test_linear_extrapolation_beats_zero_order_hold_on_kavz():
    spec = scene.load("kavz685").with_overrides(["experiment.stop=3"])
    out = {}
    for name in ("jacobi", "jacobi-linear"):
        result = run.simulate(spec, master=name, step=2e-3)
        ref = monolithic.solve(spec, result.times)
        e = metrics.errors(result.times, result.traces, ref.times, ref.traces, ["coupling.tau2"],
                           metrics.error_scales(spec, ref.traces))
        out[name] = e["coupling.tau2"]["rms_relative"]
    assert out["jacobi-linear"] < out["jacobi"] / 4, out


def test_derivative_weights_are_the_polynomials_derivatives_at_the_last_point():
    first, second = masters.derivative_weights([0.8, 0.9, 1.0], 0.1)
    assert np.allclose(first, [0.5, -2.0, 1.5]) and np.allclose(second, [1.0, -2.0, 1.0])
    # exact for a quadratic sampled at uneven times: u = 3 + 2 t - 5 t^2 at t = 1.3
    times = [0.2, 0.9, 1.3]
    u = [3.0 + 2.0 * x - 5.0 * x * x for x in times]
    first, second = masters.derivative_weights(times, 0.4)
    assert np.dot(first, u) / 0.4 == pytest.approx(2.0 - 10.0 * 1.3, rel=1e-12)
    assert np.dot(second, u) / 0.4 ** 2 == pytest.approx(-10.0, rel=1e-12)
    first, second = masters.derivative_weights([0.9, 1.0], 0.1)
    assert np.allclose(first, [-1.0, 1.0], rtol=1e-14) and second == [0.0, 0.0]


def _torques_and_calls(spec, name, step):
    result = run.simulate(spec, master=name, step=step)
    assert result.ok, result.failure
    return result.traces["coupling.tau2"], result.counters["calls_by_kind"], result.counters["steps"]


@pytest.mark.parametrize("name", ["jacobi-linear", "jacobi-quadratic"])
def test_extrapolating_masters_send_the_polynomial_ahead_in_the_calls_of_jacobi(name, monkeypatch):
    # With tau_rate and tau_accel declared, the next step's polynomial goes out with the
    # torque that makes the recorded accelerations consistent: no write before the step,
    # after the start-up the 11 calls of a jacobi step (3 doSteps, 3 reads, 3 sets - one
    # to the coupling, one to each shaft - and the accelerations read again).  The shafts
    # reduce it to the ramp the hold would have written: the same run, to rounding.
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.5", "experiment.transient=0.1"])
    ahead, calls, steps = _torques_and_calls(spec, name, 2e-3)
    made = sum(c["step"] for c in calls.values())
    sets = sum(c["set"] for c in calls.values())
    # (the start-up steps roll back and step again, up to four passes each)
    assert 3 * steps <= made <= 3 * steps + 20 and 3 * steps <= sets <= 3 * steps + 40, (made, sets, steps)
    # the same master holding the ramp instead (what FMUs without the derivative inputs get)
    original = masters.ExtrapolatingJacobiMaster.__init__

    def holding(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.sends_ahead = False

    monkeypatch.setattr(masters.ExtrapolatingJacobiMaster, "__init__", holding)
    held, calls_held, _ = _torques_and_calls(spec, name, 2e-3)
    assert sum(c["set"] for c in calls_held.values()) - sets >= 2 * (steps - 3)
    np.testing.assert_allclose(ahead, held, rtol=1e-10, atol=1e-9)
    assert not np.array_equal(ahead, held) or name == "jacobi-linear"


def test_a_refused_dostep_in_a_step_plan_is_named_as_component_do_step_names_it():
    from harness.engine.component import step_call
    from harness.engine.system import StepCall, System
    failures = []

    class Refusing(CallCounts):
        time = 0.0

        def __init__(self):
            self._start_counts()

        def fail(self, call, status):
            failures.append((call, status))

    component = Refusing()
    System.step_with((StepCall(component, lambda handle, t, h, flag: 3, None),), 0.25, 1e-3)
    assert failures == [("fmi2DoStep(t = 0.25, h = 0.001)", 3)] == [(step_call(0.25, 1e-3), 3)]
    assert component.steps == 1
