"""The engine with a torque lag and the full Fig. 3.9-shaped characteristic:
the physics against scipy, the choice of model, the named table, the FMU's saved state,
the monolithic reference and the stability analysis with the lag's extra state."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from lever.physics import component_parameters
from lever.physics.engine import NAMED_CHARACTERISTICS, LinearCharacteristic, TabulatedCharacteristic, \
    engine_characteristic
from lever.physics.parameters import ParameterError
from lever.physics.shaft import LaggedShaft, Shaft, expm

from harness.description import scene
from harness.engine import run
from harness.judges import monolithic, stability


def _scipy_step(shaft, phi, w, torque, tau, h, rate):
    def rhs(t, y):
        return [y[1], (y[2] + tau + rate * t) / shaft.inertia,
                (shaft.external.torque(t, y[0], y[1]) - y[2]) / shaft.lag]
    sol = solve_ivp(rhs, (0.0, h), [phi, w, torque], method="Radau", rtol=1e-12, atol=1e-12)
    return sol.y[:, -1]


@pytest.mark.parametrize("lag", [1e-5, 0.01, 0.16, 5.0])
def test_the_line_with_a_lag_steps_exactly_at_any_lag(lag):
    # the matrix exponential: exact (to the reference's 1e-9) whether the lag is 1e-5 s,
    # 100 times faster than the step, or 5 s
    shaft = LaggedShaft(0.128, LinearCharacteristic(623.0, 14.06), lag, 0.0)
    phi, w, torque, work = shaft.advance(0.0, 0.1, 3.0, 50.0, -30.0, 1e-3, 2e4)
    np.testing.assert_allclose([phi, w, torque], _scipy_step(shaft, 0.1, 3.0, 50.0, -30.0, 1e-3, 2e4),
                               rtol=1e-9, atol=1e-9)
    # the engine's work from the energy balance is the integral of M*w (within the
    # Hermite quadrature of the ramp's work, O(h^6))
    assert math.isfinite(work) and work > 0.0


def test_a_tabulated_characteristic_with_a_lag_takes_rk4_substeps():
    shaft = LaggedShaft(0.128, TabulatedCharacteristic.parse(NAMED_CHARACTERISTICS["kavz685"]), 0.16, 100.0)
    state = (0.0, 38.0, 100.0)
    for k in range(5):          # across the governor branch's knee at 37.8 rad/s
        phi, w, torque, _ = shaft.advance(k * 1e-3, *state, -20.0, 1e-3)
        expected = _scipy_step(shaft, *state, -20.0, 1e-3, 0.0)
        np.testing.assert_allclose([phi, w, torque], expected, rtol=1e-8, atol=1e-8)
        state = (phi, w, torque)


def test_expm_against_scipy():
    from scipy.linalg import expm as scipy_expm
    a = [[0.0, 1.0, 0.0], [-4e4, -30.0, 2.0], [0.0, -1e3, -1e5]]
    np.testing.assert_allclose(expm(a, 1e-3), scipy_expm(np.array(a) * 1e-3), rtol=1e-10, atol=1e-14)


def test_which_engine_a_parameter_set_builds():
    assert type(component_parameters.engine_from({})) is Shaft                                   # no lag: today's code
    assert type(component_parameters.engine_from({"torque_lag": 0.5e-6})) is Shaft                # below 1 us: none
    lagged = component_parameters.engine_from({"torque_lag": 0.16, "torque_start": 12.0, "characteristic": "kavz685"})
    assert isinstance(lagged, LaggedShaft) and lagged.lag == 0.16 and lagged.torque_start == 12.0
    assert isinstance(lagged.external, TabulatedCharacteristic)


def test_the_fig_3_9_table():
    # start-up torque, nominal point, idle: the monograph's figures (docs/physics.md#the-table)
    table = engine_characteristic(0.0, 0.0, "kavz685")
    assert table.torque(0, 0, 0.0) == 623.0                       # start-up torque (M1 of (3.23))
    assert table.torque(0, 0, 33.6) == 450.0                      # nominal point
    assert table.torque(0, 0, 39.25) == 0.0                       # idle: 374.8 rpm
    assert 39.25 * 30 / math.pi == pytest.approx(374.8, abs=0.05)
    assert table.torque(0, 0, 40.0) < 0.0                         # beyond idle the governor brakes
    with pytest.raises(ParameterError, match="named characteristic") as refused:
        engine_characteristic(0.0, 0.0, "kavz")
    assert refused.value.name == "characteristic"


def test_the_reference_and_the_fmus_agree_on_a_lagged_run_up():
    # the reference's eighth state (the lagged torque) against the FMU's, over the first
    # 0.3 s of the run-up from rest; jacobi-quadratic at 1 ms is ~1e-4 relative on
    # kavz685 (docs/models-and-fmus.md): here measured 4.5e-5 on the speeds, 1.3e-4 on the
    # engine torque, bounded at 3e-4
    spec = scene.load("kavz685_runup_rest").with_overrides(["experiment.stop=0.3", "experiment.transient=0.1"])
    result = run.simulate(spec, "jacobi-quadratic", 1e-3)
    assert result.ok, result.failure
    ref = monolithic.solve(spec, result.times, use_cache=False)
    for name in ("engine.w", "load.w", "engine.engine_torque"):
        scale = np.max(np.abs(ref.traces[name]))
        assert np.max(np.abs(result.traces[name] - ref.traces[name])) < 3e-4 * scale, name
    # the torque builds up from 0 with the lag: after Te/10 it is 1 - e^-0.1 of the start-up
    # torque (measured 0.5 % below: the characteristic falls as the shaft speeds up)
    torque = ref.traces["engine.engine_torque"]
    assert torque[0] == 0.0
    assert torque[16] == pytest.approx(623.0 * (1.0 - math.exp(-0.1)), rel=0.015)


def test_the_lag_is_a_fourth_state_of_the_linear_model():
    model = stability.TwoInertia(0.128, 0.161, 14.06, 715.4, 6.35, engine_lag=0.16)
    values = model.continuous_eigenvalues()
    assert len(values) == 4 and np.all(values.real < 0.0)
    h = 1e-3
    matrix, names = stability.one_step_map(model, "trapezoidal-newton", h)
    assert names == ["theta", "w1", "w2", "M1"]
    # at a small step the map's spectrum is the continuous one's exponential
    found = np.sort(np.abs(np.linalg.eigvals(matrix)))
    # (within the coupling scheme's own error at h*omega_n = 0.1: measured 8.5e-5)
    np.testing.assert_allclose(found, np.sort(np.abs(np.exp(values * h))), rtol=3e-4)
    # and the scene's model carries the lag
    assert stability.model_of(scene.load("kavz685_runup_rest")).engine_lag == 0.16
    assert stability.model_of(scene.load("kavz685")).engine_lag == 0.0


@pytest.mark.parametrize("name", ["jacobi", "jacobi-quadratic"])
def test_stand_in_with_a_lag_steps_like_the_real_fmus(name):
    """As tests/judges/test_stability.py's test for the engine without lag: two runs of the FMUs
    from different starts differ by what the stand-in (lagged torque in its state) makes
    of the difference, step for step."""
    spec = scene.load("kavz685").with_overrides(
        ["coupling.transfer_mode=synchronous", "load.load_kind=constant", "coupling.stiffness=1e4",
         "coupling.damping=0.5", "experiment.transient=0", "engine.torque_lag=0.02", "engine.torque_start=50"])
    model = stability.model_of(spec)
    step, n = model.step_for(0.4), 60
    spec = spec.with_overrides([f"experiment.stop={n * step!r}"])
    runs = [run.simulate(spec.with_overrides(extra), name, step)
            for extra in ([], ["engine.phi_start=0.002", "load.w_start=39.5", "engine.torque_start=80"])]
    assert all(r.ok for r in runs), [r.failure for r in runs]
    real = runs[1].traces["coupling.tau2"][1:] - runs[0].traces["coupling.tau2"][1:]
    system = stability.LinearDriveline(model, step)
    system.set_state(0.002, 0.0, 0.0, 0.5, 30.0)
    from harness.engine import masters
    driver = masters.make(name, system, step)
    linear = []
    for k in range(1, n + 1):
        driver.step(t_next=k * step)
        linear.append(system.value("coupling", "tau2"))
    linear = np.array(linear)
    assert np.max(np.abs(linear)) > 10.0
    assert np.max(np.abs(real - linear)) < 1e-6 * np.max(np.abs(linear))


def test_lever_study_runup_reproduces_the_documented_figures(lever, tmp_path):
    """The figures docs/models-and-fmus.md ("Run-up") quotes for the chosen lag (Te = 0.16 s:
    w1 settles in 0.448 s, w2 in 0.510 s, peak 445.8 rpm) come from `lever study runup`;
    a lag outside [0, 100] s is refused naming the parameter."""
    done = lever("study", "runup", "--scan", "0.16", "--out", str(tmp_path))
    assert done.exit_code == 0, done.output
    assert "| 0.16 | 0.448 | 0.510 | 445.8 |" in done.output
    assert (tmp_path / "runup.md").read_text().startswith("| Te [s] |")
    refused = lever("study", "runup", "--scan", "-1", "--out", str(tmp_path))
    assert refused.exit_code == 2 and "engine.torque_lag must be in [0, 100] s" in refused.output
