"""Hand-derived values for the pieces the mutation run (``make mutants``, docs/testing.md)
found weakly tested: each expected number below is worked out in the docstring, not
recomputed with the code under test."""
from __future__ import annotations

import math

import pytest

from harness.engine import masters
from lever.physics import component_parameters
from lever.physics.coupling import build_coupling, coupling_mode
from lever.physics.elastic import LinearElasticLaw, TabulatedElasticLaw
from lever.physics.engine import LinearCharacteristic, TabulatedCharacteristic, engine_characteristic
from lever.physics.kinematics import TransferFunction
from lever.physics.parameters import ParameterError

pytestmark = pytest.mark.oracle

# -- the masters' extrapolation weights ------------------------------------------------------------------------


def test_extrapolation_weights_of_every_degree_on_uniform_steps():
    """Nodes x = (t_j - t)/h.  The polynomial p through the past values, on the step x in [0, 1]:
    mean = integral_0^1 p, slope = 12 integral_0^1 p (x - 1/2) (the least-squares line's slope,
    times h), end = p(1).  By Lagrange's basis:

    degree 0 (x = 0): p = u0: mean 1, slope 0, end 1.
    degree 1 (x = -1, 0): L0 = -x, L1 = x + 1: means (-1/2, 3/2), slopes (-1, 1), ends (-1, 2).
    degree 2 (x = -2, -1, 0): L0 = x(x+1)/2, L1 = -x(x+2), L2 = (x+1)(x+2)/2: means
      (5/12, -16/12, 23/12); a quadratic's least-squares slope on [0, 1] is p'(1/2):
      L0' = x + 1/2 -> 1, L1' = -2x - 2 -> -3, L2' = x + 3/2 -> 2; ends L(1) = (1, -3, 3)."""
    h = 0.25
    expected = {
        1: ([1.0], [0.0], [1.0]),
        2: ([-0.5, 1.5], [-1.0, 1.0], [-1.0, 2.0]),
        3: ([5 / 12, -16 / 12, 23 / 12], [1.0, -3.0, 2.0], [1.0, -3.0, 3.0]),
    }
    for n, (means, slopes, ends) in expected.items():
        past = [2.0 - (n - 1 - j) * h for j in range(n)]
        found = masters.extrapolation_weights(past, 2.0, h)
        for what, got, want in zip(("mean", "slope", "end"), found, (means, slopes, ends)):
            assert got == pytest.approx(want, abs=1e-12), (
                f"extrapolation weights of degree {n - 1}, {what}: {got}, by hand {want}: the extrapolating "
                f"masters' weights are wrong (jacobi-{('zero-order', 'linear', 'quadratic')[n - 1]})")


def test_extrapolation_weights_on_uneven_steps():
    """Past points at x = -3, -1 and 0 (a step of 3h, then h): for u = 1 + x + x^2 the mean
    over [0, 1] is 1 + 1/2 + 1/3 = 11/6, the slope 12 int (x - 1/2)(1 + x + x^2) = 1 + 1 = 2
    (for a quadratic p'(1/2) = 1 + 2 * 1/2), the end 3."""
    h = 0.1
    past = [1.0 - 3 * h, 1.0 - h, 1.0]
    u = [1 + x + x * x for x in (-3.0, -1.0, 0.0)]
    means, slopes, ends = masters.extrapolation_weights(past, 1.0, h)
    assert sum(m * v for m, v in zip(means, u)) == pytest.approx(11 / 6, rel=1e-12)
    assert sum(s * v for s, v in zip(slopes, u)) == pytest.approx(2.0, rel=1e-12)
    assert sum(e * v for e, v in zip(ends, u)) == pytest.approx(3.0, rel=1e-12)
    # the weights of a polynomial through the points reproduce constants
    assert sum(means) == pytest.approx(1.0) and sum(ends) == pytest.approx(1.0) and sum(slopes) == pytest.approx(0.0,
                                                                                                              abs=1e-12)


def test_lagrange_weights_extrapolate_a_parabola():
    """Nodes 0, 1, 2, value at 3: L0 = (3-1)(3-2)/((0-1)(0-2)) = 1, L1 = (3-0)(3-2)/((1-0)(1-2)) = -3,
    L2 = (3-0)(3-1)/((2-0)(2-1)) = 3; at 0.5: (3/8, 3/4, -1/8)."""
    assert masters.lagrange_weights([0.0, 1.0, 2.0], 3.0) == pytest.approx([1.0, -3.0, 3.0], abs=1e-12)
    assert masters.lagrange_weights([0.0, 1.0, 2.0], 0.5) == pytest.approx([0.375, 0.75, -0.125], abs=1e-12)
    assert masters.lagrange_weights([5.0], 7.0) == [1.0]


# -- the engine's characteristics ---------------------------------------------------------------------------------

def test_linear_characteristic_through_an_operating_point_and_back():
    """docs/physics.md#the-line: K1 = 14.06 puts the steady speed at 37.2 rad/s under 100 N*m, so
    M1 = Mc + K1 w = 100 + 14.06 * 37.2 = 623.032 N*m (the monograph's 623), and back
    (M1 - Mc)/K1 = 37.2.  Mg(w) = M1 - K1 w: at 30 rad/s 623.032 - 421.8 = 201.232."""
    line = LinearCharacteristic.through(37.2, 100.0, 14.06)
    assert line.stall_torque == pytest.approx(623.032, rel=1e-12) and line.slope == 14.06
    assert line.steady_speed(100.0) == pytest.approx(37.2, rel=1e-12)
    assert line.steady_speed(623.032) == pytest.approx(0.0, abs=1e-12)
    assert line.torque(0.0, 0.0, 30.0) == pytest.approx(201.232, rel=1e-12)


def test_tabulated_characteristic_between_and_beyond_its_points():
    """Points (speed, torque): (10, 300), (20, 500), (30, 560), (40, 600) - rising to the end:
    linear between points (at 25: 530; at 35: 580), the first torque held below 10 (300),
    the last held above 40 (600: a rising end is not extended).  Falling end (40, 400):
    extended with its slope (400 - 560)/10 = -16 per rad/s: at 45, 320.  Steepest slope
    |dMg/dw| = 20 (first segment); rate = 20 / I."""
    rising = TabulatedCharacteristic([(30, 560), (10, 300), (40, 600), (20, 500)])   # any order
    expected = {0.0: 300.0, 10.0: 300.0, 15.0: 400.0, 25.0: 530.0, 35.0: 580.0, 40.0: 600.0, 50.0: 600.0}
    for w, torque in expected.items():
        assert rising.torque(0.0, 0.0, w) == pytest.approx(torque, rel=1e-12), (w, rising.torque(0.0, 0.0, w))
    assert rising.speed_stiffness == pytest.approx(20.0) and rising.rate(0.5) == pytest.approx(40.0)
    falling = TabulatedCharacteristic([(10, 300), (20, 500), (30, 560), (40, 400)])
    for w, torque in {35.0: 480.0, 40.0: 400.0, 45.0: 320.0}.items():
        assert falling.torque(0.0, 0.0, w) == pytest.approx(torque, rel=1e-12), (w, falling.torque(0.0, 0.0, w))
    assert falling.speed_stiffness == pytest.approx(20.0)


def test_engine_characteristic_chooses_the_table_only_when_one_is_given():
    assert isinstance(engine_characteristic(623.0, 14.06), LinearCharacteristic)
    for blank in ("", "   ", "linear", " linear "):
        line = engine_characteristic(623.0, 14.06, blank)
        assert isinstance(line, LinearCharacteristic) and (line.stall_torque, line.slope) == (623.0, 14.06)
    table = engine_characteristic(623.0, 14.06, "10:300; 20:500")
    assert isinstance(table, TabulatedCharacteristic) and table.points == [(10.0, 300.0), (20.0, 500.0)]


# -- the coupling mode used for step-size and stability advice -------------------------------------------------------

def test_coupling_mode_of_the_kavz685_chain():
    """docs/masters-and-stability.md "Linear analysis": omega_n = sqrt(c / I_red), I_red = I1 I2/(I1 + I2),
    zeta = (b + K1 (I2/(I1 + I2))^2) / (2 sqrt(c I_red)).  KAVZ-685: I_red = 0.128*0.161/0.289
    = 0.0713080 kg*m2, omega_n = sqrt(715.4/0.0713080) = 100.1626 rad/s; 2 sqrt(c I_red) =
    14.2848, so without the engine zeta = 6.35/14.2848 = 0.44453; with K1 = 14.06 the share
    (0.161/0.289)^2 = 0.310353 adds 4.36356 N*m*s/rad: zeta = 10.71356/14.2848 = 0.75000
    (the docs' "zeta 0.75")."""
    omega, zeta = coupling_mode(715.4, 6.35, 0.128, 0.161)
    assert omega == pytest.approx(100.1626, rel=1e-6) and zeta == pytest.approx(0.44453, rel=1e-4)
    omega, zeta = coupling_mode(715.4, 6.35, 0.128, 0.161, engine_slope=14.06)
    assert omega == pytest.approx(100.1626, rel=1e-6) and zeta == pytest.approx(0.75000, rel=1e-4)
    coupling = build_coupling("synchronous", 0.0, 0.0, 0.0, 715.4, 6.35)
    assert coupling.eigen_estimate(0.128, 0.161) == pytest.approx((100.1626, 0.44453), rel=1e-4)
    table = build_coupling("synchronous", 0.0, 0.0, 0.0, 715.4, 6.35, "0.1:10; 0.2:40")
    # a table's nominal stiffness is its secant over the table: 40/0.2 = 200 N*m/rad
    assert table.eigen_estimate(0.128, 0.161)[0] == pytest.approx(math.sqrt(200.0 / 0.0713080), rel=1e-5)


# -- a monotone cubic elastic law ------------------------------------------------------------------------------------

def test_tabulated_law_slopes_energy_and_extension_by_hand():
    """Points (0, 0), (1, 1), (2, 3): secants d = (1, 2), steps h = (1, 1).  Fritsch-Butland
    slope at the inner knot: w1 = 2h1 + h0 = 3, w2 = h1 + 2h0 = 3, m1 = (w1 + w2)/(w1/d0 + w2/d1)
    = 6/4.5 = 4/3.  Ends, one-sided three-point: m0 = ((2h0 + h1) d0 - h0 d1)/(h0 + h1) = 1/2,
    m2 = ((2h1 + h0) d1 - h1 d0)/(h0 + h1) = 5/2.  Energy at a knot, exact for the cubic:
    sum h (y0 + y1)/2 + h^2 (m0 - m1)/12 = (1/2 - 5/72) + (2 - 7/72) = 7/3.  Beyond the last
    point the last slope: T(3) = 3 + 5/2 = 5.5, V(3) = 7/3 + 3*1 + 5/4; odd: T(-3) = -5.5."""
    law = TabulatedElasticLaw([(1.0, 1.0), (2.0, 3.0)])
    for theta, stiffness in ((0.0, 0.5), (1.0, 4.0 / 3.0), (2.0, 2.5), (3.0, 2.5)):
        assert law.stiffness_at(theta) == pytest.approx(stiffness, rel=1e-12), (theta, law.stiffness_at(theta))
    for theta, torque in ((1.0, 1.0), (2.0, 3.0), (3.0, 5.5), (-3.0, -5.5)):
        assert law.torque(theta) == pytest.approx(torque, rel=1e-12), (theta, law.torque(theta))
    assert law.energy(2.0) == pytest.approx(7.0 / 3.0, rel=1e-12)
    assert law.energy(-3.0) == law.energy(3.0) == pytest.approx(7.0 / 3.0 + 3.0 + 1.25, rel=1e-12)
    assert law.nominal_stiffness == pytest.approx(1.5)
    # mid-segment, the cubic Hermite form: s = 1/2 on [0, 1]: (y0 + y1)/2 + h (m0 - m1)/8
    assert law.torque(0.5) == pytest.approx(0.5 + (0.5 - 4.0 / 3.0) / 8.0, rel=1e-12)


def test_tabulated_law_flattens_at_a_plateau_and_at_a_steep_rise():
    """Monotone cubic: where the secants change sign or one is zero the inner slope is 0
    (a plateau stays flat); an end slope whose three-point formula turns against its
    secant is 0.  (0,0), (1,1), (2,1), (3,2): inner slopes 0, 0; ends (3*1 - 0)/2 = 1.5 both.
    (0,0), (1,0.1), (2,10): m0 = (3*0.1 - 9.9)/2 < 0 -> 0."""
    plateau = TabulatedElasticLaw([(1.0, 1.0), (2.0, 1.0), (3.0, 2.0)])
    assert [plateau.stiffness_at(x) for x in (0.0, 1.0, 2.0, 3.0)] == pytest.approx([1.5, 0.0, 0.0, 1.5], abs=1e-12)
    assert plateau.torque(1.5) == pytest.approx(1.0, abs=1e-12)
    steep = TabulatedElasticLaw([(1.0, 0.1), (2.0, 10.0)])
    assert steep.stiffness_at(0.0) == 0.0


# -- a misalignment that varies in time: the blended transfer function ---------------------------------------------

def test_coupling_family_is_exact_at_nodes_and_blends_linearly_between():
    """``CouplingFamily`` at alpha between the 0.05 deg nodes a_k < alpha < a_k+1 uses
    U12 = U_k + w (U_k+1 - U_k), w = (alpha - a_k)/(a_k+1 - a_k); at a node the exact one;
    at its start alpha the exact coupling of that alpha."""
    node = math.radians(0.05)
    start = math.radians(15.0)
    family = component_parameters.coupling_family_from({"misalignment": start})
    assert family.at(start) is family.start
    phi = [0.0, 0.7, 2.0, 4.4]

    def exact(alpha):
        return TransferFunction("kinematic", alpha, 0.03, 0.03)

    k = 300                                                    # 15 deg is node 300
    alpha = (k + 0.3) * node
    lower, upper = exact(k * node), exact((k + 1) * node)
    blended = family.at(alpha).transfer
    for x in phi:
        p0, u0 = lower.evaluate(x)
        p1, u1 = upper.evaluate(x)
        p, u = blended.evaluate(x)
        assert u == pytest.approx(u0 + 0.3 * (u1 - u0), rel=1e-12, abs=1e-15)
        assert p == pytest.approx(p0 + 0.3 * (p1 - p0), rel=1e-12)
    on_node = family.at(301 * node).transfer
    for x in phi:
        assert on_node.evaluate(x) == pytest.approx(exact(301 * node).evaluate(x), rel=1e-12)
    assert family.at(alpha).damping == 6.35 and family.at(alpha).law.stiffness == 715.4


# -- refusals that name the parameter and its range (docs/physics.md#linear-law-and-damping) ----------------------

def test_stiffness_and_damping_bounds_in_the_physics():
    """c > 0 and b >= 0, each refused outside with a ParameterError naming it and its
    range; values at the edge (the smallest positive double, zero damping) accepted."""
    tiny = math.nextafter(0.0, 1.0)
    assert LinearElasticLaw(tiny).stiffness == tiny and LinearElasticLaw(0.5).torque(2.0) == 1.0
    assert build_coupling("synchronous", 0.0, 0.0, 0.0, 0.5, 0.0).damping == 0.0
    for bad in (0.0, -tiny, math.inf, math.nan):
        with pytest.raises(ParameterError) as refused:
            LinearElasticLaw(bad)
        assert refused.value.name == "stiffness" and "(0, inf) N.m/rad" in str(refused.value), str(refused.value)
    for bad in (-tiny, -1.0, math.inf, math.nan):
        with pytest.raises(ParameterError) as refused:
            build_coupling("synchronous", 0.0, 0.0, 0.0, 715.4, bad)
        assert refused.value.name == "damping" and "[0, inf) N.m.s/rad" in str(refused.value), str(refused.value)


@pytest.mark.parametrize("make,name,says", [
    (lambda: TabulatedCharacteristic([(10.0, 300.0)]), "characteristic", "needs at least 2 (speed, torque) points, got 1"),
    (lambda: TabulatedCharacteristic([(10.0, 300.0), (10.0, 400.0)]), "characteristic", "speeds must be distinct"),
    (lambda: TabulatedCharacteristic([(0.0, 0.0), (1e-300, 1e300)]), "characteristic", "slopes overflow"),
    (lambda: TabulatedElasticLaw([(0.1, 1.0)]), "elastic_table", "needs at least 2 points with theta > 0, got 1"),
    (lambda: TabulatedElasticLaw([(0.0, 1.0), (0.1, 2.0), (0.2, 3.0)]), "elastic_table", "torque at zero deflection"),
    (lambda: TabulatedElasticLaw([(0.2, 1.0), (0.1, 2.0)]), "elastic_table", "strictly increasing"),
    (lambda: TabulatedElasticLaw([(0.1, 2.0), (0.2, 1.0)]), "elastic_table", "non-decreasing"),
    (lambda: TabulatedElasticLaw([(0.1, 0.0), (0.2, 0.0)]), "elastic_table", "carries no torque"),
])
def test_bad_tables_are_refused_naming_the_parameter(make, name, says):
    with pytest.raises(ParameterError) as refused:
        make()
    assert refused.value.name == name and f"'{name}'" in str(refused.value) and says in str(refused.value), (
        refused.value.name, str(refused.value))


def test_the_smallest_tables_are_accepted():
    """Two points are enough for a characteristic, two beyond zero for an elastic law (the
    zero point is added); a law whose torque reaches 1e-3 N*m only still carries torque."""
    assert TabulatedCharacteristic([(10.0, 300.0), (20.0, 200.0)]).torque(0.0, 0.0, 15.0) == pytest.approx(250.0)
    law = TabulatedElasticLaw([(0.1, 0.0), (0.2, 1e-3)])
    assert law.points == [(0.0, 0.0), (0.1, 0.0), (0.2, 1e-3)] and law.torque(0.2) == pytest.approx(1e-3)
    assert TabulatedElasticLaw([(0.0, 0.0), (0.1, 1.0), (0.2, 3.0)]).points[0] == (0.0, 0.0)


def test_misalignment_limits_of_the_transfer_function():
    """docs/physics.md#the-half-coupling-function: g exists for alpha < 45 deg, and the kinematic and scaled modes
    evaluate it at alpha + asin(D2s/l2) (the support's tilt): asin(0.1) = 5.739 deg, so
    alpha = 39.2 deg (44.939) is accepted and 39.3 deg (45.039) refused; the working range
    ends at 75 deg for every mode; a scaled U12 that falls to 0.05 locks the coupling and
    is refused (alpha = 20 deg with both deformations 0.4: the reported amplitude's law
    gives about 1.04) - each naming the misalignment."""
    TransferFunction("kinematic", math.radians(39.2), 0.1, 0.03)
    for mode in ("kinematic", "scaled"):
        with pytest.raises(ParameterError) as refused:
            TransferFunction(mode, math.radians(39.3), 0.1, 0.03)
        assert refused.value.name == "misalignment" and "45 deg" in str(refused.value), str(refused.value)
    TransferFunction("synchronous", math.radians(74.9))
    for mode in ("synchronous", "kinematic", "scaled"):
        with pytest.raises(ParameterError) as refused:
            TransferFunction(mode, math.radians(75.0), 0.03, 0.03)
        assert refused.value.name == "misalignment" and "75 deg" in str(refused.value), str(refused.value)
    with pytest.raises(ParameterError) as refused:
        TransferFunction("scaled", math.radians(20.0), 0.4, 0.4)
    assert refused.value.name == "misalignment" and "would lock" in str(refused.value), str(refused.value)


def test_tabulated_law_on_uneven_steps_by_hand():
    """Points (0, 0), (1, 1), (3, 5): h = (1, 2), secants d = (1, 2).  Inner slope:
    w1 = 2 h1 + h0 = 5, w2 = h1 + 2 h0 = 4, m1 = (w1 + w2)/(w1/d0 + w2/d1) = 9/7; ends
    m0 = ((2 h0 + h1) d0 - h0 d1)/(h0 + h1) = 2/3, m2 = ((2 h1 + h0) d1 - h1 d0)/(h0 + h1) = 8/3;
    energy at 3: (1/2 + (2/3 - 9/7)/12) + (6 + 4 (9/7 - 8/3)/12) = 6.5 - 129/252."""
    law = TabulatedElasticLaw([(1.0, 1.0), (3.0, 5.0)])
    assert [law.stiffness_at(x) for x in (0.0, 1.0, 3.0)] == pytest.approx([2 / 3, 9 / 7, 8 / 3], rel=1e-12)
    assert law.energy(3.0) == pytest.approx(6.5 - 129 / 252, rel=1e-12)


# -- the monotone cubic's slopes against an independent implementation -----------------------------------------

def test_monotone_cubic_slopes_are_scipys_pchip_on_uneven_tables():
    """The elastic table's slopes are Fritsch-Butland's (weighted harmonic mean inside, the
    limited three-point formula at the ends): what scipy.interpolate.PchipInterpolator
    computes, written independently there.  Uneven steps, sign changes, flat stretches and
    tables of 3 to 9 points, seeded: the mutation run left the uneven-step weights
    (2 h[k-1] for 2/h[k-1]) and the end formula's step (h[1] for h[-1]) alive."""
    import random

    from scipy.interpolate import PchipInterpolator

    from lever.physics.elastic import _pchip_slopes

    rng = random.Random(20261123)
    for _ in range(300):
        n = rng.randint(3, 9)
        x = [0.0]
        for _ in range(n - 1):
            x.append(x[-1] + rng.choice((0.01, 0.1, 1.0, 3.0)) * rng.uniform(0.2, 1.0))
        y = [rng.choice((0.0, 1.0, -1.0, 2.5)) * rng.uniform(0.0, 5.0) for _ in range(n)]
        expected = PchipInterpolator(x, y).derivative()(x)
        got = _pchip_slopes(x, y)
        assert got == pytest.approx(list(expected), rel=1e-12, abs=1e-12), (
            f"the monotone cubic's slopes differ from scipy's PCHIP at x = {x}, y = {y}")


@pytest.mark.parametrize("cls,name,later", [
    (TabulatedCharacteristic, "engine_table", "10:300; 10:200"),     # speeds not distinct
    (TabulatedElasticLaw, "coupling_table", "0:0; 0.2:5; 0.1:6"),    # angles not increasing
])
def test_a_parsed_table_is_refused_under_the_name_it_was_given(cls, name, later):
    """parse() passes its name on: a row that is no number (refused while parsing) and a table
    refused by the model afterwards both name the parameter the user set."""
    for text in ("0:0; x:1", later):
        with pytest.raises(ParameterError) as refused:
            cls.parse(text, name)
        assert refused.value.name == name and f"'{name}'" in str(refused.value), (text, refused.value)
