"""The physics' Model Exchange interface (docs/physics.md#model-exchange-interface;
lever.physics.me_*, lever.physics.driveline): derivatives that are the monolithic
reference's right-hand side bit for bit, analytic partials against central differences,
declared dependencies against the sparsity differences find, event indicators that change
sign where the physics switches.

Seeded draws of plain Python floats (the physics' own arithmetic, no numpy vectorised math):
the same numbers on any CPU.
"""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from harness.description import scene as scenes
from harness.judges import monolithic
from lever.physics import component_parameters, driveline
from lever.physics.driveline import HELD, Driveline
from lever.physics.engine import NAMED_CHARACTERISTICS, TabulatedCharacteristic
from lever.physics.freewheel import EVENTS as FREEWHEEL_EVENTS, FREE, N_EDGES, STICK
from lever.physics.me_base import ANGLE_BAND, SPEED_BAND, TORQUE_BAND, der
from lever.physics.me_coupling import CouplingME
from lever.physics.me_engine import EngineME
from lever.physics.me_freewheel import FreewheelME
from lever.physics.me_load import LoadME
from lever.physics.me_misalignment import MisalignmentME
from lever.physics.parameters import ParameterError

TABLE = "0.05:10; 0.1:16; 0.2:16.5; 0.3:26.5; 0.45:50"      # the plateaus scene's elastic law
COUPLINGS = {
    "linear-synchronous": {"transfer_mode": "synchronous"},
    "linear-kinematic": {"transfer_mode": "kinematic", "misalignment": 0.35, "support_deformation": 0.03,
                         "hinge_deformation": 0.05},
    "linear-scaled": {"transfer_mode": "scaled", "misalignment": 0.26, "support_deformation": 0.03},
    "table-scaled": {"transfer_mode": "scaled", "misalignment": 0.26, "support_deformation": 0.03,
                     "elastic_table": TABLE},
    "table-undamped": {"elastic_table": TABLE, "damping": 0.0},
}
ENGINES = {
    "line": {},
    "table": {"characteristic": "kavz685"},
    "lagged-line": {"torque_lag": 0.05, "torque_start": 300.0},
    "lagged-table": {"torque_lag": 0.16, "characteristic": "kavz685"},
}
LOADS = {
    "constant": {"load_kind": "constant"},
    "random": {"load_kind": "random", "random_amplitude": 40.0},
    "spectrum": {"load_kind": "random", "random_amplitude": 40.0, "order_share": 0.4, "order": 2,
                 "narrowband_share": 0.3},
    "fourier": {"load_kind": "fourier", "fourier": "107.5; 12:5; 3:-2; 0.5:1"},
    "table": {"load_kind": "table", "table": "0:100; 0.5:100; 0.5001:300; 2:250"},
    "viscous": {"viscous_damping": 2.5},
    "friction": {"load_kind": "fourier", "fourier": "107.5; 12:5", "friction_torque": 20.0,
                 "breakaway_torque": 35.0, "viscous_damping": 1.5},
    "brake": {"load_direction": "resistive", "friction_torque": 10.0, "breakaway_torque": 15.0},
}


# -- helpers --------------------------------------------------------------------------------------

def unknowns_at(model, t, x, u):
    return model.derivatives(t, x, u) + model.outputs(t, x, u)


def central(model, t, x, u, column, h):
    """Central difference of every unknown with respect to state/input ``column``."""
    x_plus, x_minus, u_plus, u_minus = list(x), list(x), list(u), list(u)
    if column in model.STATES:
        k = model.STATES.index(column)
        x_plus[k] += h
        x_minus[k] -= h
    else:
        k = model.INPUTS.index(column)
        u_plus[k] += h
        u_minus[k] -= h
    return [(a - b) / (2.0 * h) for a, b in zip(unknowns_at(model, t, x_plus, u_plus),
                                                  unknowns_at(model, t, x_minus, u_minus))]


def step_for(value):
    """A central-difference step: 1e-6 relative (truncation ~h^2, rounding ~eps/h)."""
    return 1e-6 * max(1.0, abs(value))


def value_of(model, x, u, column):
    return x[model.STATES.index(column)] if column in model.STATES else u[model.INPUTS.index(column)]


def assert_partials(model, t, x, u, rtol=1e-6):
    """Every analytic partial equals the central difference within ``rtol`` of the row's
    largest entry (a row mixes N.m/rad and N.m.s/rad: an entry is relative to its row)."""
    analytic = model.partials(t, x, u)
    columns = model.STATES + model.INPUTS
    numeric = {c: central(model, t, x, u, c, step_for(value_of(model, x, u, c))) for c in columns}
    for i, row in enumerate(model.unknowns):
        scale = max([1e-300] + [abs(analytic.get((row, c), 0.0)) for c in columns]
                    + [abs(numeric[c][i]) for c in columns])
        for c in columns:
            a, n = analytic.get((row, c), 0.0), numeric[c][i]
            assert abs(a - n) <= rtol * scale, (type(model).__name__, row, c, a, n)


def assert_sparsity(model, t, x, u):
    """What finite differences find non-zero is declared; not everything is."""
    declared = model.dependencies
    assert set(declared) == set(model.unknowns)
    columns = model.STATES + model.INPUTS
    for c in columns:
        numeric = central(model, t, x, u, c, step_for(value_of(model, x, u, c)))
        for row, value in zip(model.unknowns, numeric):
            if value != 0.0:
                assert c in declared[row], (type(model).__name__, row, c, value)
    pairs = sum(len(v) for v in declared.values())
    assert pairs < len(model.unknowns) * len(columns)
    analytic = model.partials(t, x, u)
    assert all(c in declared[row] for (row, c), v in analytic.items() if v != 0.0)


def far_from(value, points, margin):
    return all(abs(value - p) > margin for p in points)


def flange_draw(rng):
    """A point of the coupling's operating range: angles, speeds about 35 rad/s."""
    phi2 = rng.uniform(-20.0, 20.0)
    w2 = rng.uniform(20.0, 45.0)
    return [phi2 + rng.uniform(-0.4, 0.4), w2 + rng.uniform(-5.0, 5.0), phi2, w2]


def coupling_models():
    for name, params in COUPLINGS.items():
        yield name, CouplingME(component_parameters.coupling_from(params))
    yield "family", CouplingME(component_parameters.coupling_family_from(COUPLINGS["table-scaled"]))


def coupling_draw(model, rng, knots=()):
    """Inputs away from the elastic table's points (|theta|) and the family's nodes."""
    while True:
        u = flange_draw(rng)
        if model.family:
            u.append(rng.uniform(0.2, 0.3))
        r = model.coupling_at(u).evaluate(*u[:4])
        fine = far_from(abs(r.deflection), [p[0] for p in knots], 1e-4)
        if model.family:
            node = model.family.NODE
            fine = fine and far_from(u[4] / node, [round(u[4] / node)], 1e-3)
        if fine:
            return u


def engine_draw(model, rng):
    speeds = model.characteristic.speeds if model.EVENTS else []
    while True:
        x = model.start()
        x[0], x[1], x[2] = rng.uniform(-50.0, 50.0), rng.uniform(-5.0, 45.0), rng.uniform(-100.0, 100.0)
        if model.lagged:
            x[3] = rng.uniform(0.0, 600.0)
        if far_from(x[1], speeds, 1e-3):
            return x, [rng.uniform(-600.0, 100.0)]


def load_draw(model, rng):
    x = [rng.uniform(-50.0, 50.0), rng.uniform(-45.0, 45.0), rng.uniform(-100.0, 100.0)]
    u = [rng.uniform(-300.0, 300.0)]
    t = rng.uniform(0.0, 1.9)
    if model.friction:
        model.initialize(t, x, u)
    return t, x, u


# -- (a) one right-hand side -----------------------------------------------------------------------

def me_driveline_derivatives(engine_me, coupling_me, load_me, t, y, alpha=None):
    """The driveline's derivatives assembled from the three ME editions, as a strongly
    coupled master would: the coupling's torques into the shafts' inputs."""
    u = list(y[:4]) + ([alpha] if alpha is not None else [])
    tau1, tau2, _, _, _, dissipation = coupling_me.outputs(t, [], u)
    x1 = [y[0], y[1], y[4]] + ([y[7]] if engine_me.lagged else [])
    d1 = engine_me.derivatives(t, x1, [tau1])
    d2 = load_me.derivatives(t, [y[2], y[3], y[5]], [tau2])
    return [d1[0], d1[1], d2[0], d2[1], d1[2], d2[2], dissipation] + d1[3:]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("load", LOADS)
def test_me_derivatives_are_the_reference_right_hand_side_bit_for_bit(engine, load):
    rng = random.Random(f"{engine}/{load}")
    shaft1, shaft2 = component_parameters.engine_from(ENGINES[engine]), component_parameters.load_from(LOADS[load])
    for coupling_name, params in COUPLINGS.items():
        coupling = component_parameters.coupling_from(params)
        reference = Driveline(shaft1, lambda t: coupling, shaft2)
        e_me, c_me, l_me = EngineME(shaft1), CouplingME(coupling), LoadME(shaft2)
        for _ in range(20):
            y = flange_draw(rng) + [rng.uniform(-9.0, 9.0) for _ in range(3)]
            if e_me.lagged:
                y.append(rng.uniform(0.0, 600.0))
            t = rng.uniform(0.0, 2.0)
            if l_me.friction:
                # every mode of the load, the reference's rhs of that mode
                for mode in (1, -1, HELD):
                    l_me.mode = mode
                    yy = list(y)
                    if mode == HELD:
                        yy[3] = 0.0
                    assert me_driveline_derivatives(e_me, c_me, l_me, t, yy) == reference.derivatives(t, yy, mode)
            else:
                assert me_driveline_derivatives(e_me, c_me, l_me, t, y) == reference.derivatives(t, y)


def test_me_derivatives_with_a_misalignment_source_are_the_reference_right_hand_side():
    family = component_parameters.coupling_family_from(COUPLINGS["linear-scaled"])
    source = component_parameters.misalignment_source_from({"table": "0:0.2; 1:0.3; 2:0.25"})
    shaft1, shaft2 = component_parameters.engine_from({}), component_parameters.load_from({})
    reference = Driveline(shaft1, lambda t: family.at(source.value(t)), shaft2)
    source_me, e_me, c_me, l_me = MisalignmentME(source), EngineME(shaft1), CouplingME(family), LoadME(shaft2)
    rng = random.Random(7)
    for _ in range(50):
        t = rng.uniform(0.0, 2.5)
        y = flange_draw(rng) + [0.0, 0.0, 0.0]
        alpha = source_me.outputs(t, [], [])[0]
        assert me_driveline_derivatives(e_me, c_me, l_me, t, y, alpha) == reference.derivatives(t, y)


def test_the_monolithic_reference_integrates_the_physics_right_hand_side(monkeypatch):
    """solve_driveline's right-hand side is Driveline.derivatives (so the bit-for-bit test
    above holds for the reference's traces)."""
    calls = []
    original = driveline.Driveline.derivatives

    def counted(self, t, y, mode=None):
        calls.append(mode)
        return original(self, t, y, mode)

    monkeypatch.setattr(driveline.Driveline, "derivatives", counted)
    for name in ("kavz685", "kavz685_stall_resistive"):
        scene = scenes.load(name)
        calls.clear()
        solution = monolithic.solve_driveline(scene, np.linspace(0.0, 0.01, 11), use_cache=False)
        assert len(calls) == solution.n_rhs


def test_freewheel_me_derivatives_are_the_rectifier_reference_right_hand_side():
    model = component_parameters.freewheel_from({"resistance_torque": 30.0})
    me = FreewheelME(model)
    y0 = me.start()
    rng = random.Random(3)
    for disc in (STICK, 1, -1):
        for fly in (STICK, 1, -1, FREE):
            me.disc, me.fly = disc, fly
            for _ in range(10):
                t = rng.uniform(0.0, 0.2)
                y = [v + rng.uniform(-0.05, 0.05) for v in y0]
                tau = rng.uniform(-20.0, 20.0)
                assert me.derivatives(t, y, [tau]) == model.derivatives(t, y, disc, fly, tau)
                # the reference's event functions, each banded: the edges on their sides, the
                # modes by the band of what they measure
                me.initialize(t, y, [tau])
                raw = model.event_values(t, y, disc, fly, tau)
                sides = [1.0 if v >= 0.0 else -1.0 for v in raw[:N_EDGES]]
                bands = [ANGLE_BAND * s for s in sides] + [
                    TORQUE_BAND if m == STICK else (0.0 if m == FREE else SPEED_BAND) for m in (disc, fly)]
                assert me.event_indicators(t, y, [tau]) == [v + b for v, b in zip(raw, bands)]


# -- (b) analytic partials against central differences ------------------------------------------

@pytest.mark.parametrize("name,model", list(coupling_models()), ids=lambda v: v if isinstance(v, str) else "")
def test_coupling_partials_equal_central_differences(name, model):
    rng = random.Random(name)
    knots = component_parameters.coupling_from(COUPLINGS["table-scaled"]).law.points if "table" in name or name == "family" else ()
    for _ in range(40):
        assert_partials(model, 0.0, [], coupling_draw(model, rng, knots))


@pytest.mark.parametrize("name", ENGINES)
def test_engine_partials_equal_central_differences(name):
    model = EngineME(component_parameters.engine_from(ENGINES[name]))
    rng = random.Random(name)
    for _ in range(40):
        x, u = engine_draw(model, rng)
        assert_partials(model, rng.uniform(0.0, 2.0), x, u)


@pytest.mark.parametrize("name", LOADS)
def test_load_partials_equal_central_differences(name):
    model = LoadME(component_parameters.load_from(LOADS[name]))
    rng = random.Random(name)
    for _ in range(40):
        t, x, u = load_draw(model, rng)
        if model.friction:
            for mode in (1, -1, HELD):
                model.mode = mode
                assert_partials(model, t, x, u)
        else:
            assert_partials(model, t, x, u)


def test_freewheel_partials_equal_central_differences():
    model = component_parameters.freewheel_from({"resistance_torque": 30.0})
    me = FreewheelME(model)
    y0 = me.start()
    rng = random.Random(11)
    checked = set()
    for disc in (STICK, 1, -1):
        for fly in (STICK, 1, FREE):
            me.disc, me.fly = disc, fly
            for _ in range(15):
                t = rng.uniform(0.0, 0.15)
                y = [v + rng.uniform(-0.06, 0.06) for v in y0]
                for k in (1, 3, 5, 7):
                    y[k] = rng.uniform(-2.0, 2.0)
                values = model.event_values(t, y, disc, fly, 0.0)[:6]
                de = model.rocker(t)[1] - y[1]
                if min(abs(v) for v in values) < 1e-3 or abs(abs(de) - model.vk) < 1e-3:
                    continue            # next to a gap edge or the ball friction's saturation
                checked.add(tuple(int(v > 0) for v in values[::2]) + (abs(de) < model.vk,))
                assert_partials(me, t, y, [rng.uniform(-20.0, 20.0)])
    assert len(checked) >= 6                  # engaged and open gaps, saturated and not


def test_driveline_jacobian_equals_central_differences():
    rng = random.Random(5)
    for engine in ENGINES.values():
        for load in ("constant", "fourier", "spectrum", "viscous", "friction"):
            shaft1, shaft2 = component_parameters.engine_from(engine), component_parameters.load_from(LOADS[load])
            for params in COUPLINGS.values():
                coupling = component_parameters.coupling_from(params)
                system = Driveline(shaft1, lambda t: coupling, shaft2)
                modes = (1, -1, HELD) if shaft2.resisting else (None,)
                for mode in modes:
                    while True:
                        y = flange_draw(rng) + [rng.uniform(-9.0, 9.0) for _ in range(3)]
                        if isinstance(shaft1.external, TabulatedCharacteristic):
                            if not far_from(y[1], shaft1.external.speeds, 1e-3):
                                continue
                        break
                    if system.lagged:
                        y.append(rng.uniform(0.0, 600.0))
                    if mode == HELD:
                        y[3] = 0.0
                    t = rng.uniform(0.0, 2.0)
                    jac = system.jacobian(t, y, mode)
                    for j in range(system.size):
                        h = step_for(y[j])
                        plus, minus = list(y), list(y)
                        plus[j] += h
                        minus[j] -= h
                        column = [(a - b) / (2.0 * h) for a, b in zip(system.derivatives(t, plus, mode),
                                                                       system.derivatives(t, minus, mode))]
                        for i in range(system.size):
                            scale = max(1e-300, max(abs(v) for v in jac[i]), max(abs(column[i]), abs(jac[i][j])))
                            assert abs(jac[i][j] - column[i]) <= 1e-6 * scale, (engine, load, mode, i, j)


def test_the_engine_table_takes_the_right_hand_slope_at_its_points():
    """At a point of the table the characteristic has a kink: the partial is the slope of
    the segment above the point, below the first point and above a held end 0."""
    table = TabulatedCharacteristic.parse(NAMED_CHARACTERISTICS["kavz685"])
    speeds, torques = table.speeds, table.torques
    h = 1e-7
    for k, w in enumerate(speeds):
        right = (table.torque(0.0, 0.0, w + h) - table.torque(0.0, 0.0, w)) / h
        left = (table.torque(0.0, 0.0, w) - table.torque(0.0, 0.0, w - h)) / h
        slope = table.torque_slope(0.0, 0.0, w)
        assert slope == pytest.approx(right, rel=1e-6, abs=1e-6)
        if k + 1 < len(speeds):
            assert slope == (torques[k + 1] - torques[k]) / (speeds[k + 1] - speeds[k])
        if 0 < k < len(speeds) - 1:
            assert abs(slope - left) > 1.0          # a real kink: the sides differ
    assert table.torque_slope(0.0, 0.0, speeds[0] - 1.0) == 0.0                 # start-up torque held
    assert table.torque_slope(0.0, 0.0, speeds[-1] + 1.0) == table.torque_slope(0.0, 0.0, speeds[-1])  # falls: extended
    rising = TabulatedCharacteristic([(0.0, 100.0), (10.0, 200.0)])
    assert rising.torque_slope(0.0, 0.0, 10.0) == 0.0 and rising.torque_slope(0.0, 0.0, 9.0) == 10.0


def test_the_pchip_law_is_differentiable_at_its_points():
    """The elastic table's stiffness is continuous (C1 Hermite; its second derivative
    jumps at the points): at every point, and at 0 where the law is mirrored, the analytic
    stiffness is the limit from either side (one-sided differences, Richardson-extrapolated
    to O(h^2): a central difference across the jump errs by O(h))."""
    law = component_parameters.coupling_from({"elastic_table": TABLE}).law

    def one_sided(theta, h):
        def d(step):
            return (law.torque(theta + step) - law.torque(theta)) / step
        return 2.0 * d(h / 2.0) - d(h)
    for theta in [0.0] + [p[0] for p in law.points[1:]] + [-p[0] for p in law.points[1:]]:
        for h in (1e-5, -1e-5):
            assert law.stiffness_at(theta) == pytest.approx(one_sided(theta, h), rel=1e-6, abs=1e-6)


def test_the_family_takes_the_right_hand_blend_at_a_node():
    family = component_parameters.coupling_family_from(COUPLINGS["linear-scaled"])
    alpha = 300 * family.NODE
    flanges = (0.1, 35.0, 1.3, 34.0)
    h = 1e-9
    right = [(a - b) / h for a, b in zip(family.at(alpha + h).torques(*flanges), family.at(alpha).torques(*flanges))]
    assert family.alpha_partials(alpha, *flanges) == pytest.approx(right, rel=1e-5)
    left = family.alpha_partials(alpha - 0.5 * family.NODE, *flanges)
    assert left != pytest.approx(right, rel=1e-3)         # the blend's slope does jump at a node
    with pytest.raises(ParameterError, match="misalignment"):
        component_parameters.coupling_family_from({"transfer_mode": "kinematic", "misalignment": 0.2,
                                        "support_deformation": 0.03}).alpha_slopes(math.radians(44.99), 0.3)


# -- (c) declared dependencies ---------------------------------------------------------------------

def test_declared_dependencies_contain_what_differences_find():
    rng = random.Random(13)
    for name, model in coupling_models():
        for _ in range(5):
            assert_sparsity(model, 0.0, [], coupling_draw(model, rng))
    for params in ENGINES.values():
        model = EngineME(component_parameters.engine_from(params))
        for _ in range(5):
            x, u = engine_draw(model, rng)
            assert_sparsity(model, 0.0, x, u)
    for params in LOADS.values():
        model = LoadME(component_parameters.load_from(params))
        for _ in range(5):
            t, x, u = load_draw(model, rng)
            for mode in ((1, -1, HELD) if model.friction else (None,)):
                model.mode = mode
                assert_sparsity(model, t, x, u)
    freewheel = FreewheelME(component_parameters.freewheel_from({"resistance_torque": 30.0}))
    y0 = freewheel.start()
    for disc in (STICK, 1):
        for fly in (STICK, 1, FREE):
            freewheel.disc, freewheel.fly = disc, fly
            y = [v + rng.uniform(0.0, 0.05) for v in y0]
            y[1], y[3], y[5], y[7] = 0.3, -0.2, 0.4, 0.1
            assert_sparsity(freewheel, 0.05, y, [3.0])
    source = MisalignmentME(component_parameters.misalignment_source_from({"table": "0:0.2; 1:0.3"}))
    assert source.dependencies == {"misalignment": (), "misalignment_rate": ()}


def test_dependencies_follow_the_parameters():
    """A constant load's acceleration does not depend on its angle, a Fourier load's
    does; an undamped coupling's torques do not depend on the speeds."""
    assert LoadME(component_parameters.load_from({})).dependencies[der("w")] == ("tau",)
    assert LoadME(component_parameters.load_from(LOADS["fourier"])).dependencies[der("w")] == ("phi", "tau")
    undamped = CouplingME(component_parameters.coupling_from(COUPLINGS["table-undamped"])).dependencies
    assert undamped["tau1"] == ("phi1", "phi2") and undamped["dissipated_power"] == ()
    assert EngineME(component_parameters.engine_from({"torque_slope": 0.0})).dependencies[der("w")] == ("tau",)


# -- (d) event indicators --------------------------------------------------------------------------

def test_the_load_stops_sticks_and_breaks_away_where_the_indicator_changes_sign():
    """Coulomb friction, constant load, a braking coupling torque: the shaft decelerates
    uniformly, w(t) = w0 - d t, so it stops at t* = w0 / d; the stick condition holds it;
    a torque ramp breaks it away where |net| reaches the breakaway torque."""
    load = LoadME(component_parameters.load_from({"load_kind": "constant", "mean_torque": 50.0, "friction_torque": 20.0, "breakaway_torque": 35.0,
                                       "inertia": 2.0}))
    tau = 40.0
    x = [0.0, 3.0, 0.0]
    load.initialize(0.0, x, [tau])
    assert load.mode == 1
    deceleration = -load.derivatives(0.0, x, [tau])[1]
    assert deceleration == pytest.approx((50.0 + 20.0 - 40.0) / 2.0)
    stop = 3.0 / deceleration

    def state(t):
        return [3.0 * t - 0.5 * deceleration * t * t, 3.0 - deceleration * t, 0.0]
    # the indicator is banded (me_base.banded): it changes sign once the speed has
    # reversed by SPEED_BAND, and the update puts the shaft at rest exactly
    stop_banded = (3.0 + SPEED_BAND) / deceleration
    assert load.event_indicators(stop, state(stop), [tau])[0] == pytest.approx(SPEED_BAND, abs=1e-15)
    assert load.event_indicators(stop_banded * (1 - 1e-9), state(stop_banded * (1 - 1e-9)), [tau])[0] > 0.0
    assert load.event_indicators(stop_banded * (1 + 1e-9), state(stop_banded * (1 + 1e-9)), [tau])[0] < 0.0
    at_rest = load.event_update(stop_banded, state(stop_banded * (1 + 1e-9)), [tau])
    assert at_rest[1] == 0.0 and load.mode == HELD                    # |40 - 50| <= 35: sticks
    assert load.derivatives(stop, at_rest, [tau]) == [0.0, 0.0, 0.0]
    assert load.outputs(stop, at_rest, [tau])[3] == tau                 # static friction balances the drive
    # breakaway: net = tau - 50 reaches +35 at tau = 85, the indicator TORQUE_BAND later
    assert load.event_indicators(stop, at_rest, [85.0])[0] == pytest.approx(TORQUE_BAND, abs=1e-12)
    assert load.event_indicators(stop, at_rest, [85.0 + TORQUE_BAND - 1e-9])[0] > 0.0
    assert load.event_indicators(stop, at_rest, [85.0 + TORQUE_BAND + 1e-9])[0] < 0.0
    load.event_update(stop, at_rest, [85.0 + TORQUE_BAND + 1e-9])
    assert load.mode == 1
    assert load.event_indicators(stop, at_rest, [86.0])[0] == SPEED_BAND     # a breakaway starts off zero
    assert load.derivatives(stop, at_rest, [86.0])[1] == pytest.approx((86.0 - 50.0 - 20.0) / 2.0)


def test_the_freewheel_engages_where_its_indicator_changes_sign():
    """From the start the half-couplings sit z1 ahead of the rocker: the rocker
    phi1 = phi0 (1 - cos(omega t)) closes the axial gap at phi1 = phi2, i.e. at
    t* = acos(1 - phi2/phi0)/omega, where the engagement indicator (e = phi1 - phi2)
    changes sign and the ramp's torque starts to grow from its springs' T_p."""
    model = component_parameters.freewheel_from({})
    me = FreewheelME(model)
    y = me.start()
    engaged = math.acos(1.0 - y[0] / model.phi0) / model.omega
    index = FREEWHEEL_EVENTS.index("msm_contact")
    # below its edge at the start: the indicator is e - ANGLE_BAND (me_base.banded), and
    # changes sign where e = ANGLE_BAND
    assert me.event_indicators(engaged, y, [0.0])[index] == pytest.approx(-ANGLE_BAND, abs=1e-15)
    located = math.acos(1.0 - (y[0] + ANGLE_BAND) / model.phi0) / model.omega
    assert (me.event_indicators(located * (1 - 1e-9), y, [0.0])[index] < 0.0
            < me.event_indicators(located * (1 + 1e-9), y, [0.0])[index])
    before, after = engaged * (1 - 1e-9), engaged * (1 + 1e-9)
    assert model.forces(before, y, me.disc, me.fly, 0.0)[4] == model.t_p
    later = engaged * 1.05
    assert model.forces(later, y, me.disc, me.fly, 0.0)[4] > model.t_p
    # the slope of T12 in phi2 switches from 0 (gap) to -kappa C_fi (engaged)
    assert me.partials(before, y, [0.0]).get((der("w2"), "phi2"), 0.0) == 0.0
    assert me.partials(after, y, [0.0])[der("w2"), "phi2"] < -model.c_fi / model.J23 * 0.99


def test_the_freewheel_discs_slip_where_their_indicator_changes_sign():
    """Stuck discs (STICK) slip when the torque they pass reaches their capacity: the
    indicator cap - |F| is zero there, and event_update switches to slipping."""
    model = component_parameters.freewheel_from({"resistance_torque": 30.0})
    me = FreewheelME(model)
    y = me.start()
    me.disc, me.fly = STICK, STICK
    y[0] = model.rocker(0.0)[0] - 0.002                # engaged by 2 mrad: a clamp force
    y[2] = y[4] + 0.02                                  # the torsion shaft twisted: it holds back the driven parts
    index = FREEWHEEL_EVENTS.index("disc")

    def indicator(twist):
        z = list(y)
        z[2] = z[4] + twist
        return me.event_indicators(0.0, z, [0.0])[index], z
    low, high = 0.0, 0.05
    assert indicator(low)[0] > 0.0 > indicator(high)[0]
    for _ in range(100):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if indicator(mid)[0] > 0.0 else (low, mid)
    value, z = indicator(high)
    f = model.forces(0.0, z, STICK, STICK, 0.0)
    # |F| = capacity + TORQUE_BAND exactly where it changes sign (me_base.banded)
    assert abs(f[5]) == pytest.approx(f[6] + TORQUE_BAND, rel=1e-13)
    me.event_update(0.0, z, [0.0])
    assert me.disc in (1, -1)
    assert me.event_indicators(0.0, z, [0.0])[index] == SPEED_BAND     # a slip starts at equal speeds, off zero


def test_the_engine_table_points_are_event_indicators():
    model = EngineME(component_parameters.engine_from(ENGINES["table"]))
    speeds = model.characteristic.speeds
    for k, w in enumerate(speeds):
        # a speed at a point is on its upper side: SPEED_BAND off zero, a sign change once
        # the speed is SPEED_BAND below it; the update moves the side there
        x = [0.0, w, 0.0]
        model.initialize(0.0, x, [0.0])
        assert model.event_indicators(0.0, x, [0.0])[k] == SPEED_BAND
        assert model.event_indicators(0.0, [0.0, w - 0.5 * SPEED_BAND, 0.0], [0.0])[k] > 0.0
        below = [0.0, w - 2.0 * SPEED_BAND, 0.0]
        assert model.event_indicators(0.0, below, [0.0])[k] < 0.0
        model.event_update(0.0, below, [0.0])
        assert model.event_indicators(0.0, below, [0.0])[k] == pytest.approx(-3.0 * SPEED_BAND, rel=1e-6)
    assert EngineME(component_parameters.engine_from({})).event_indicators(0.0, [0.0, 30.0, 0.0], [0.0]) == []


def test_the_misalignment_source_has_time_events_at_its_points():
    source = MisalignmentME(component_parameters.misalignment_source_from({"table": "0:0.2; 1:0.3; 2.5:0.25"}))
    assert [source.next_time_event(t) for t in (-1.0, 0.0, 0.5, 1.0, 2.5)] == [0.0, 1.0, 1.0, 2.5, None]
    assert source.outputs(0.5, [], []) == [pytest.approx(0.25), pytest.approx(0.1)]


def test_the_load_starts_in_the_mode_its_state_and_drive_say():
    """At rest the static friction holds while |net| <= hold, else the shaft slips the way
    the net torque turns it; moving, the way it moves.  An active Fourier load,
    Mc = 100 + 80 sin(phi) N*m, friction 5 N*m, breakaway 10 N*m: net = tau - Mc(phi)."""
    def mode(phi, w, tau, t=0.0, **load):
        model = LoadME(component_parameters.load_from({"friction_torque": 5.0, "breakaway_torque": 10.0,
                                                       "inertia": 1.0, **load}))
        model.initialize(t, [phi, w, 7.0], [tau])
        return model.mode
    fourier = {"load_kind": "fourier", "fourier": "100; 0:80"}
    top = math.pi / 2                                   # Mc = 180 N*m there, 100 at phi = 0
    assert mode(top, 0.0, 185.0, **fourier) == HELD     # net 5 <= 10
    assert mode(top, 0.0, 200.0, **fourier) == 1        # net 20: forwards
    assert mode(top, 0.0, 150.0, **fourier) == -1       # net -30: backwards
    assert mode(0.0, 0.0, 185.0, **fourier) == 1        # the angle's load: net 85
    angle = LoadME(component_parameters.load_from({"friction_torque": 5.0, "breakaway_torque": 10.0,
                                                   "inertia": 1.0, **fourier}))
    angle.initialize(0.0, [top, 0.0, 7.0], [185.0])
    assert angle.event_indicators(0.0, [top, 0.0, 7.0], [185.0]) == [pytest.approx(5.0)]    # 10 - |5|
    angle.event_update(0.0, [top, 0.0, 7.0], [185.0])
    assert angle.mode == HELD                                                                # at phi = 0 it would go
    angle.event_update(0.0, [top, 0.0, 7.0], [200.0])
    assert angle.mode == 1                                                                   # |20| > 10
    assert mode(top, 1.0, 185.0, **fourier) == 1        # moving: its direction, whatever the drive
    assert mode(top, -0.5, 300.0, **fourier) == -1
    # a time table's load at its time: Mc = 200 N*m at 0.5 s (100 at 0, 300 at 1 s)
    table = {"load_kind": "table", "table": "0:100; 1:300"}
    assert mode(0.0, 0.0, 205.0, t=0.5, **table) == HELD and mode(0.0, 0.0, 205.0, t=0.0, **table) == 1
    held = LoadME(component_parameters.load_from({"friction_torque": 5.0, "breakaway_torque": 10.0, **table}))
    held.initialize(0.5, [0.0, 0.0, 7.0], [205.0])
    # held: no acceleration, the load torque the drive's, the margin to the breakaway 10 - 5 N*m
    assert held.outputs(0.5, [0.0, 0.0, 7.0], [205.0]) == [0.0, 0.0, 0.0, 205.0, 7.0]
    assert held.event_indicators(0.5, [0.0, 0.0, 7.0], [205.0]) == [pytest.approx(5.0)]
    assert LoadME(component_parameters.load_from({})).EVENTS == ()
    # slipping, the indicator is the speed signed by the direction: zero at the stop
    slipping = LoadME(component_parameters.load_from({"friction_torque": 5.0, "breakaway_torque": 10.0, **table}))
    slipping.initialize(0.5, [0.0, 2.0, 7.0], [205.0])
    assert slipping.mode == 1 and slipping.event_indicators(0.5, [0.0, 2.0, 7.0], [205.0]) == [2.0 + SPEED_BAND]
    # an integrator's state a little past the stop: at rest exactly, held at 0.5 s, and at
    # 0.05 s (Mc = 110 N*m: net 95 > 10) slipping on the way the net torque turns it
    assert slipping.event_update(0.5, [1.5, -1e-3, 7.0], [205.0]) == [1.5, 0.0, 7.0] and slipping.mode == HELD
    slipping.mode = 1
    assert slipping.event_update(0.05, [1.5, -1e-3, 7.0], [205.0]) == [1.5, 0.0, 7.0] and slipping.mode == 1
    # a time event of the table while it slips slowly: nothing changes
    slipping.mode = 1
    assert slipping.event_update(0.3, [1.5, 0.5, 7.0], [205.0]) == [1.5, 0.5, 7.0] and slipping.mode == 1
    # held, a breakaway at the table's time: not at 0.5 s (margin -5), at 0.05 s
    assert held.event_update(0.5, [0.0, 0.0, 7.0], [205.0]) == [0.0, 0.0, 7.0] and held.mode == HELD
    held.event_update(0.05, [0.0, 0.0, 7.0], [205.0])
    assert held.mode == 1
    # the states a run starts from: the angle and speed given, no work done yet
    assert LoadME(component_parameters.load_from({}), 0.3, 39.0).start() == [0.3, 39.0, 0.0]
    assert EngineME(component_parameters.engine_from({}), 0.2, 38.0).start() == [0.2, 38.0, 0.0]


def test_a_time_table_load_has_time_events_at_its_points():
    # active or a brake with friction (held, its breakaway margin follows the table's kinks)
    for extra in ({}, {"load_direction": "resistive", "friction_torque": 5.0, "breakaway_torque": 8.0}):
        load = LoadME(component_parameters.load_from({"load_kind": "table", "table": "0.2:700; 0.3:300; 0.6:700",
                                                      **extra}))
        assert [load.next_time_event(t) for t in (0.0, 0.2, 0.25, 0.3, 0.6, 1.0)] == [0.2, 0.3, 0.3, 0.6, None, None]
    # loads that are not a table: none
    for parameters in ({"load_kind": "constant", "mean_torque": 50.0, "friction_torque": 20.0,
                        "breakaway_torque": 35.0}, {"load_kind": "random", "mean_torque": 100.0}):
        assert LoadME(component_parameters.load_from(parameters)).next_time_event(0.0) is None


def test_directional_derivatives_are_the_jacobian_times_the_seed():
    model = CouplingME(component_parameters.coupling_from(COUPLINGS["linear-kinematic"]))
    u = [0.1, 35.0, 1.3, 34.0]
    seed = [0.0, 0.0, 1.0, 0.0]
    d = model.directional_derivative(0.0, [], u, [], seed)
    assert d == [model.partials(0.0, [], u).get((row, "phi2"), 0.0) for row in model.unknowns]
