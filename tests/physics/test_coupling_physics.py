"""The coupling as a compliant element: torques, power balance, elastic laws
(docs/physics.md#elastic-element; lever.physics.coupling, lever.physics.elastic)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, simpson

from lever.physics import component_parameters
from lever.physics.coupling import CouplingResult, LeverCoupling, build_coupling
from lever.physics.elastic import LinearElasticLaw, TabulatedElasticLaw, elastic_law
from lever.physics.kinematics import TransferFunction
from lever.physics.parameters import ParameterError

DEG = math.pi / 180.0
# docs/physics.md#nonlinear-elastic-law-the-plateaus-scene: the cam-shaped characteristic with two plateaus.
TABLE = "0.05:10; 0.1:16; 0.2:16.5; 0.3:26.5; 0.45:50"
TABLE_POINTS = [(0.0, 0.0), (0.05, 10.0), (0.1, 16.0), (0.2, 16.5), (0.3, 26.5), (0.45, 50.0)]


def over(method):
    """A scalar method of the physics mapped over numpy arrays (the physics takes scalars:
    it runs in the FMUs on the standard library alone)."""
    return np.vectorize(method)


def evaluate_over(coupling, *arrays) -> CouplingResult:
    """``coupling.evaluate`` element by element: a CouplingResult of arrays."""
    rows = [coupling.evaluate(*row) for row in zip(*np.broadcast_arrays(*arrays))]
    return CouplingResult(*(np.array(column) for column in zip(*rows)))


def trajectory(seed: int, n: int = 40001, duration: float = 1.0):
    """A smooth random motion of both flanges: a ramp at about 39 rad/s plus sines, the
    drive flange wandering +-0.6 rad about the driven one.  Returns t, phi1, w1, phi2, w2."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, duration, n)

    def wave(count, amplitude, top):
        a = rng.uniform(0.3, 1.0, count) * amplitude / count
        f = rng.uniform(1.0, top, count)
        p = rng.uniform(0.0, 2.0 * np.pi, count)
        return (np.sum(a[:, None] * np.sin(np.outer(f, t) + p[:, None]), axis=0),
                np.sum((a * f)[:, None] * np.cos(np.outer(f, t) + p[:, None]), axis=0))

    speed = rng.uniform(30.0, 45.0)
    x2, v2 = wave(3, 0.4, 40.0)
    d, vd = wave(4, 0.5, 60.0)
    offset, drift = rng.uniform(-0.1, 0.1), rng.uniform(-0.3, 0.3)
    phi2 = speed * t + x2
    w2 = speed + v2
    phi1 = phi2 + offset + drift * t + d
    w1 = w2 + drift + vd
    return t, phi1, w1, phi2, w2


def couplings():
    yield "linear-kinematic", build_coupling("kinematic", 20 * DEG, 0.03, 0.05, 715.4, 6.35)
    yield "linear-scaled", build_coupling("scaled", 15 * DEG, 0.03, 0.03, 715.4, 6.35)
    yield "table-kinematic", build_coupling("kinematic", 20 * DEG, 0.05, 0.03, 1.0, 2.0, TABLE)
    yield "table-synchronous", build_coupling("synchronous", 20 * DEG, 0.05, 0.03, 1.0, 0.5, TABLE)


COUPLINGS = dict(couplings())


# --------------------------------------------------------------------------------------
# Torques and power balance
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(COUPLINGS))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_power_balance_along_a_trajectory(name, seed):
    """int (tau1*w1 + tau2*w2) dt = -(V(end) - V(start)) - int b*thetadot^2 dt."""
    coupling = COUPLINGS[name]
    t, phi1, w1, phi2, w2 = trajectory(seed)
    r = evaluate_over(coupling, phi1, w1, phi2, w2)
    power_in = r.tau1 * w1 + r.tau2 * w2
    stored = r.energy[-1] - r.energy[0]
    dissipated = simpson(r.dissipation, x=t)
    exchanged = simpson(power_in, x=t)
    scale = simpson(np.abs(power_in), x=t)
    assert abs(stored) > 1e-3 * scale  # the test sees the elastic energy, not only the damping
    assert abs(exchanged - (-stored - dissipated)) <= 1e-6 * scale
    # The same balance point by point: P_in + b*thetadot^2 = -T_el(theta) * thetadot = -dV/dt.
    elastic = over(coupling.law.torque)(r.deflection)
    np.testing.assert_allclose(power_in + r.dissipation, -elastic * r.deflection_rate,
                               rtol=1e-9, atol=1e-9 * np.max(np.abs(power_in)))


@pytest.mark.parametrize("name", list(COUPLINGS))
def test_deflection_rate_is_the_time_derivative_of_the_deflection(name):
    coupling = COUPLINGS[name]
    t, phi1, w1, phi2, w2 = trajectory(5, n=100001)     # central differences within 2e-6 of it
    r = evaluate_over(coupling, phi1, w1, phi2, w2)
    derivative = np.gradient(r.deflection, t)
    inner = slice(2, -2)
    np.testing.assert_allclose(derivative[inner], r.deflection_rate[inner], rtol=0, atol=1e-5)


@pytest.mark.parametrize("name", list(COUPLINGS))
def test_torques_are_minus_t_and_u12_t(name):
    coupling = COUPLINGS[name]
    t, phi1, w1, phi2, w2 = trajectory(3, n=2001)
    r = evaluate_over(coupling, phi1, w1, phi2, w2)
    # Independently from the parts: theta = phi1 - Phi(phi2), thetadot = w1 - U12*w2.
    position, ratio = over(coupling.transfer.evaluate)(phi2)
    theta = phi1 - position
    theta_dot = w1 - ratio * w2
    torque = over(coupling.law.torque)(theta) + coupling.damping * theta_dot
    assert np.array_equal(r.ratio, ratio)
    assert np.array_equal(r.deflection, theta)
    assert np.array_equal(r.deflection_rate, theta_dot), "the damping does not act on thetadot = w1 - U12*w2"
    assert np.array_equal(r.torque, torque), "T is not T_el(theta) + b*(w1 - U12*w2)"
    assert np.array_equal(r.tau1, -torque), "tau1 is not -T (sign of the drive shaft's torque)"
    assert np.array_equal(r.tau2, ratio * torque), "tau2 is not +U12*T (sign of the driven shaft's torque flipped?)"
    assert np.array_equal(r.energy, over(coupling.law.energy)(theta))
    np.testing.assert_allclose(r.dissipation, coupling.damping * theta_dot ** 2, rtol=1e-14, atol=0)
    # Scalar evaluation and the hot-path torques() agree with it.
    for k in range(0, len(t), 250):
        one = coupling.evaluate(float(phi1[k]), float(w1[k]), float(phi2[k]), float(w2[k]))
        assert one.tau1 == pytest.approx(r.tau1[k], rel=1e-12, abs=1e-12)
        assert one.tau2 == pytest.approx(r.tau2[k], rel=1e-12, abs=1e-12)
        assert coupling.torques(float(phi1[k]), float(w1[k]), float(phi2[k]), float(w2[k])) == (one.tau1, one.tau2)


def test_linear_law_numbers():
    coupling = build_coupling("synchronous", 0.0, 0.0, 0.0, 700.0, 5.0)
    r = coupling.evaluate(1.1, 40.0, 1.0, 38.0)
    theta = 1.1 - 1.0
    assert r.deflection == pytest.approx(theta, abs=1e-15)
    assert r.torque == pytest.approx(700.0 * theta + 5.0 * 2.0, rel=1e-14)
    assert r.tau1 == -r.torque and r.tau2 == r.torque and r.ratio == 1.0
    assert r.energy == pytest.approx(0.5 * 700.0 * theta ** 2, rel=1e-14)
    assert r.dissipation == pytest.approx(5.0 * 4.0, rel=1e-14)


def test_component_parameters_build_the_same_coupling():
    values = {"stiffness": 715.4, "damping": 6.35, "support_deformation": 0.03, "hinge_deformation": 0.03,
              "transfer_mode": "kinematic", "misalignment": 15 * DEG}
    a = component_parameters.coupling_from(values)
    b = build_coupling("kinematic", 15 * DEG, 0.03, 0.03, 715.4, 6.35)
    args = (12.3, 39.5, 12.1, 38.7)
    assert a.evaluate(*args) == b.evaluate(*args)
    # misalignment given separately overrides the value in the dict
    c = component_parameters.coupling_from(values, misalignment=25 * DEG)
    assert c.transfer.alpha == 25 * DEG


@pytest.mark.parametrize("damping", [-1.0, math.nan, math.inf])
def test_bad_damping_is_refused(damping):
    with pytest.raises(ParameterError):
        LeverCoupling(TransferFunction("synchronous", 0.0), LinearElasticLaw(700.0), damping)


@pytest.mark.parametrize("stiffness", [0.0, -5.0, math.nan, math.inf])
def test_bad_stiffness_is_refused(stiffness):
    with pytest.raises(ParameterError):
        LinearElasticLaw(stiffness)


# --------------------------------------------------------------------------------------
# The tabulated law
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def law() -> TabulatedElasticLaw:
    return TabulatedElasticLaw.parse(TABLE)


def test_table_selects_the_tabulated_law():
    assert isinstance(elastic_law(715.4, TABLE), TabulatedElasticLaw)
    assert isinstance(elastic_law(715.4, ""), LinearElasticLaw)
    assert isinstance(elastic_law(715.4, "   "), LinearElasticLaw)
    coupling = build_coupling("synchronous", 0.0, 0.0, 0.0, 715.4, 0.0, TABLE)
    assert coupling.evaluate(0.1, 0.0, 0.0, 0.0).torque == pytest.approx(16.0, abs=1e-12)


def test_tabulated_law_passes_through_its_points(law):
    for theta, torque in TABLE_POINTS:
        assert law.torque(theta) == pytest.approx(torque, abs=1e-12)
        assert law.torque(-theta) == pytest.approx(-torque, abs=1e-12)
    assert law.torque(0.0) == 0.0
    assert law.nominal_stiffness == pytest.approx(50.0 / 0.45)


def test_tabulated_law_is_monotone(law):
    theta = np.linspace(-0.8, 0.8, 64001)
    torque = over(law.torque)(theta)
    assert np.all(np.diff(torque) >= 0.0)
    # The first plateau stays between its end points (no overshoot of the cubic).
    plateau = over(law.torque)(np.linspace(0.1, 0.2, 1001))
    assert plateau.min() >= 16.0 - 1e-12 and plateau.max() <= 16.5 + 1e-12
    assert np.all(over(law.stiffness_at)(theta) >= 0.0)


def test_tabulated_law_is_odd(law):
    theta = np.linspace(0.0, 0.8, 4001)
    assert np.array_equal(over(law.torque)(-theta), -over(law.torque)(theta))
    assert np.array_equal(over(law.energy)(-theta), over(law.energy)(theta))
    assert np.array_equal(over(law.stiffness_at)(-theta), over(law.stiffness_at)(theta))


@pytest.mark.parametrize("x", [0.0, 0.01, 0.05, 0.07, 0.1, 0.15, 0.2, 0.299, 0.3, 0.44, 0.45, 0.5, 0.7, -0.33, -0.6])
def test_energy_is_the_integral_of_the_torque(law, x):
    knots = [p[0] for p in TABLE_POINTS if 0.0 < p[0] < abs(x)]
    integral, _ = quad(lambda u: law.torque(u), 0.0, abs(x), points=knots or None, epsabs=1e-13, epsrel=1e-12)
    assert law.energy(x) == pytest.approx(integral, rel=1e-10, abs=1e-13)


def test_stiffness_is_the_derivative_of_the_torque(law):
    theta = np.linspace(0.003, 0.7, 701)
    theta = theta[np.min(np.abs(theta[:, None] - np.array([p[0] for p in TABLE_POINTS])[None, :]), axis=1) > 1e-4]
    e = 1e-7
    derivative = (over(law.torque)(theta + e) - over(law.torque)(theta - e)) / (2.0 * e)
    np.testing.assert_allclose(over(law.stiffness_at)(theta), derivative, rtol=1e-5, atol=1e-4)


def test_missing_origin_is_added_and_explicit_origin_accepted():
    with_origin = TabulatedElasticLaw.parse("0:0; " + TABLE)
    without = TabulatedElasticLaw.parse(TABLE)
    theta = np.linspace(-0.6, 0.6, 1201)
    assert np.array_equal(over(with_origin.torque)(theta), over(without.torque)(theta))
    # other separators of parse_table
    assert np.array_equal(over(TabulatedElasticLaw.parse("0.05, 10\n0.1 16\n0.2:16.5;0.3:26.5;0.45:50").torque)(theta),
                          over(without.torque)(theta))


@pytest.mark.parametrize("table", [
    "0.05:10; 0.1:8; 0.2:16",          # torque decreases
    "0.2:10; 0.1:16; 0.3:20",          # angles decrease
    "0.1:10; 0.1:16",                  # repeated angle
    "0.1:10",                          # one point beyond zero
    "0:0; 0.1:10",                     # one point beyond zero, origin given
    ";",                               # no points at all
    "0:5; 0.1:10; 0.2:20",             # nonzero torque at zero deflection
    "0.1:ten; 0.2:20",                 # not numeric
    "0.1:10:3; 0.2:20",                # three values in a row
    "0.1:nan; 0.2:20",                 # not finite
    "-0.1:-10; 0.1:10",                # negative angle
    "0.1:0; 0.2:0",                    # carries no torque
])
def test_malformed_tables_are_refused_naming_the_parameter(table):
    for make in (lambda: TabulatedElasticLaw.parse(table), lambda: elastic_law(715.4, table),
                 lambda: build_coupling("kinematic", 15 * DEG, 0.03, 0.03, 715.4, 6.35, table),
                 lambda: component_parameters.coupling_from({"elastic_table": table})):
        with pytest.raises(ParameterError) as info:
            make()
        assert info.value.name == "elastic_table"
        assert "elastic_table" in str(info.value)
