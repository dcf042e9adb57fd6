"""Property-based fuzzing (hypothesis) of the physics and of the built FMUs over the
whole allowed parameter space (every value the declared parameter ranges admit, the extremes
included): no exception escapes, outputs are finite, the coupling's energy balance holds.

The CI run is derandomised (the same examples every time) and takes a few thousand
examples.  A longer, randomised run:

    LEVER_FUZZ_SCALE=20 .venv/bin/python -m pytest tests/physics/test_fuzz.py     (make fuzz)

multiplies every test's example count by 20 and draws fresh examples (hypothesis prints
the seed and the smallest failing example of any failure).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from lever.physics import component_parameters
from lever.physics.parameters import Parameter, ParameterError
from lever.physics.shaft import LaggedShaft

SCALE = float(os.environ.get("LEVER_FUZZ_SCALE", "1"))


def fuzz(examples: int):
    return settings(max_examples=max(1, int(examples * SCALE)), derandomize=SCALE == 1, deadline=None,
                    database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# -- strategies: values the declared ranges admit ------------------------------------------------------------

@st.composite
def monotone_table(draw, first: float = 0.0, columns_positive=True):
    """A well-formed 'x:y; ...' table: strictly increasing x from ``first``, non-decreasing y."""
    n = draw(st.integers(2, 8))
    gaps = draw(st.lists(st.floats(1e-4, 1.0), min_size=n, max_size=n))
    rises = draw(st.lists(st.floats(0.0, 1e4), min_size=n, max_size=n))
    x = first + np.cumsum(gaps)
    y = np.cumsum(rises) + draw(st.floats(0.0, 1.0))
    return "; ".join(f"{a!r}:{b!r}" for a, b in zip(x.tolist(), y.tolist()))


table_noise = st.text(alphabet="0123456789.:;e-+ nai", max_size=30)
TABLES = {
    "elastic_table": st.one_of(st.just(""), monotone_table(), table_noise),
    "characteristic": st.one_of(st.just(""), monotone_table(), table_noise),
    "table": st.one_of(monotone_table(), table_noise),
    "fourier": st.one_of(st.builds(lambda m, pairs: "; ".join([repr(m)] + [f"{a!r}:{b!r}" for a, b in pairs]),
                                   st.floats(-1e3, 1e3), st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)),
                                                                  min_size=1, max_size=6)), table_noise),
}


def allowed(p: Parameter):
    if p.kind == "real":
        return st.floats(min_value=p.low if math.isfinite(p.low) else None,
                         max_value=p.high if math.isfinite(p.high) else None, exclude_min=p.low_open,
                         exclude_max=p.high_open, allow_nan=False, allow_infinity=False)
    if p.kind == "integer":
        return st.integers(int(p.low), int(p.high))
    if p.choices:
        return st.sampled_from(p.choices)
    return TABLES[p.name]


def parameters(declared):
    return st.fixed_dictionaries({p.name: allowed(p) for p in declared})


def build(make, values):
    """The physics object, or None when the values do not fit together (ParameterError,
    naming a declared parameter); any other exception fails the test."""
    try:
        built = make(values)
        event("built")
        return built
    except ParameterError as error:
        event(f"refused: {error.name}")
        assert error.name in {p.name for p in component_parameters.COUPLING + component_parameters.ENGINE + component_parameters.LOAD} | {
            "misalignment"}, error
        assert f"'{error.name}'" in str(error)
        return None


angle = st.floats(-1e6, 1e6)
speed = st.floats(-1e4, 1e4)
misalignment = allowed(component_parameters.MISALIGNMENT)


# -- physics -----------------------------------------------------------------------------------------------

@fuzz(600)
@given(parameters(component_parameters.COUPLING), misalignment, angle, speed, angle, speed)
def test_coupling_outputs_are_finite_and_its_power_balances(values, alpha, phi1, w1, phi2, w2):
    coupling = build(lambda v: component_parameters.coupling_from(v, misalignment=alpha), values)
    if coupling is None:
        return
    r = coupling.evaluate(phi1, w1, phi2, w2)
    assert all(math.isfinite(x) for x in r), r
    assert r.energy >= 0.0 and r.dissipation >= 0.0 and r.ratio > 0.0
    # tau1*w1 + tau2*w2 = -(T_el(theta)*thetadot + b*thetadot^2): what the shafts give is
    # stored or lost.  The right side is built from the elastic law and the inputs, not from
    # the coupling's T (T - b*thetadot would make it hold for any T): thetadot = w1 - U12*w2,
    # T_el = c*theta for the linear law (c, b: the drawn parameters), the table's law else.
    theta_dot = w1 - r.ratio * w2
    damping = float(values["damping"])
    linear = not values["elastic_table"].strip()
    elastic = float(values["stiffness"]) * r.deflection if linear else coupling.law.torque(r.deflection)
    power = r.tau1 * w1 + r.tau2 * w2
    stored, lost = elastic * theta_dot, damping * theta_dot * theta_dot
    scale = abs(r.tau1 * w1) + abs(r.tau2 * w2) + abs(stored) + lost + 1e-300
    assert abs(power + stored + lost) <= 1e-12 * scale, (
        f"coupling power identity broken: tau1*w1 + tau2*w2 = {power!r}, -(T_el*thetadot + b*thetadot^2) = "
        f"{-(stored + lost)!r}: the coupling's torque is not T_el(theta) + b*(w1 - U12*w2)")
    assert r.dissipation == pytest.approx(lost, rel=1e-12, abs=1e-300), "dissipation is not b*thetadot^2"


NODES, WEIGHTS = np.polynomial.legendre.leggauss(8)


def gauss(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of 8-point Gauss-Legendre on each panel between ``edges``."""
    half = 0.5 * np.diff(edges)[:, None]
    return (0.5 * (edges[1:, None] + edges[:-1, None]) + half * NODES).ravel(), (half * WEIGHTS).ravel()


@fuzz(300)
@given(parameters(component_parameters.COUPLING), misalignment, st.floats(-10, 10), st.floats(-100, 100), st.floats(-10, 10),
       st.floats(-100, 100))
def test_coupling_energy_balance_along_a_motion(values, alpha, a1, w1, a2, w2):
    """Over a motion phi1 = a1 + w1 t, phi2 = a2 + w2 t (t in [0, 0.05] s) the work the
    shafts do on the coupling equals the change of its elastic energy plus what it
    dissipates.  The three pieces behind it are checked apart, each by quadrature exact
    to rounding: the position function's derivative is the transfer function
    (Phi' = U12), the potential's is the elastic law (V' = T_el), and along the motion
    work = dV + dissipation (linear law: a smooth integrand)."""
    coupling = build(lambda v: component_parameters.coupling_from(v, misalignment=alpha), values)
    if coupling is None:
        return
    # Phi(phi2(T)) - Phi(phi2(0)) = int U12(phi2(t)) w2 dt
    t, weights = gauss(np.linspace(0.0, 0.05, 41))
    transfer = coupling.transfer
    moved = transfer.position(a2 + w2 * 0.05) - transfer.position(a2)
    assert moved == pytest.approx(np.dot(weights, [transfer.ratio(x) for x in a2 + w2 * t]) * w2, rel=1e-9, abs=1e-12)
    # V(b) - V(a) = int_a^b T_el, on panels split at the table's knots (cubic pieces: Gauss is exact)
    law, b = coupling.law, abs(a1) / 10.0 + 1e-3
    knots = [x for x, _ in getattr(law, "points", []) if 0.0 < x < b]
    theta, weights_theta = gauss(np.array([0.0] + knots + [b]))
    integral = float(np.dot(weights_theta, [law.torque(x) for x in theta]))
    assert law.energy(b) - law.energy(0.0) == pytest.approx(integral, rel=1e-9, abs=1e-12)
    # work = dV + dissipation along the motion
    if getattr(law, "points", None) is None:
        # the physics takes scalars: evaluated node by node
        rows = [coupling.evaluate(p1, w1, p2, w2) for p1, p2 in zip(a1 + w1 * t, a2 + w2 * t)]
        work = float(np.dot(weights, [-(r.tau1 * w1 + r.tau2 * w2) for r in rows]))
        lost = float(np.dot(weights, [r.dissipation for r in rows]))
        start, end = coupling.evaluate(a1, w1, a2, w2), coupling.evaluate(a1 + w1 * 0.05, w1, a2 + w2 * 0.05, w2)
        gained = end.energy - start.energy
        scale = abs(work) + abs(lost) + start.energy + end.energy
        # theta = phi1 - Phi(phi2) carries the rounding of the angles: an energy error c*theta*ulp(phi)
        angles = max(1.0, abs(a1) + abs(w1) * 0.05, abs(a2) + abs(w2) * 0.05)
        ulp = 2.2e-16 * angles
        rounding = 1e3 * law.nominal_stiffness * (max(abs(r.deflection) for r in rows) + ulp) * ulp
        assert abs(work - gained - lost) <= 1e-9 * scale + rounding + 1e-300, (work, gained, lost)


steps = st.tuples(st.floats(-1e4, 1e4), st.floats(-1e6, 1e6), st.floats(1e-5, 0.05))


def _steps_stay_finite(make, values, t, phi, w, moves):
    shaft = build(make, values)
    if shaft is None:
        return
    lagged = isinstance(shaft, LaggedShaft)
    torque = shaft.torque_start if lagged else None     # a lagged engine's torque is state too
    for tau, rate, h in moves:
        try:
            if lagged:
                phi, w, torque, work = shaft.advance(t, phi, w, torque, tau, h, rate)
            else:
                phi, w, work = shaft.advance(t, phi, w, tau, h, rate)
        except ParameterError as error:        # too many substeps asked for: refused, saying why
            assert error.name == "max_substep" and "'max_substep'" in str(error)
            return
        assert math.isfinite(phi) and math.isfinite(w) and math.isfinite(work)
        assert not lagged or math.isfinite(torque)
        t += h
    assert all(math.isfinite(x) for x in (shaft.rates(t, phi, w, 0.0, torque) if lagged else shaft.rates(t, phi, w, 0.0)))


# 400 examples: about 300 of them build an engine (three in four); the load below keeps 800,
# one in six building a load, shared among its kinds (at 400 only five random loads)
@fuzz(400)
@given(parameters(component_parameters.ENGINE), st.floats(0.0, 1e3), angle, speed, st.lists(steps, min_size=1, max_size=3))
def test_engine_shaft_steps_stay_finite(values, t, phi, w, moves):
    _steps_stay_finite(component_parameters.engine_from, values, t, phi, w, moves)


@fuzz(800)
@given(parameters(component_parameters.LOAD), st.floats(0.0, 1e3), angle, speed, st.lists(steps, min_size=1, max_size=3))
def test_load_shaft_steps_stay_finite(values, t, phi, w, moves):
    _steps_stay_finite(component_parameters.load_from, values, t, phi, w, moves)


# -- the FMUs, through FMI -----------------------------------------------------------------------------------

class Instance:
    """One FMU2Slave instance per FMU for a whole test, reset (fmi2Reset) for every example."""

    def __init__(self, fmu_dir: Path, fmu: str):
        from harness.formats import badinputs
        self.slave = badinputs.co_simulation.Slave(fmu, fmu_dir)
        badinputs.common.listen()

    def reset(self):
        self.slave.log.clear()
        self.slave.fmu.reset()

    def set_all(self, values: dict) -> int:
        return max((self.slave.set(n, v) for n, v in values.items()), default=0)


@pytest.fixture(scope="module")
def instances(fmu_dir):
    made = {f: Instance(fmu_dir, f) for f in ("LeverCoupling", "EngineShaft", "LoadShaft")}
    yield made
    for instance in made.values():
        instance.slave.free()


def _no_fatal_and_errors_say_why(instance, status):
    log = instance.slave.log
    assert status != 4 and all(level != 4 for level, _ in log), log
    if status >= 2:
        assert any(level >= 2 and text for level, text in log), "an error without a message"


def _outputs(instance):
    slave = instance.slave
    refs = [v.valueReference for v in slave.md.modelVariables if v.causality == "output"]
    from fmpy.fmi1 import FMICallException
    try:
        return 0, slave.fmu.getReal(refs)
    except FMICallException as error:
        return error.status, None


def _initialised(instance, values) -> bool:
    """Set ``values`` and initialise; False when the FMU refused (having said why)."""
    from fmpy.fmi1 import FMICallException
    status = instance.set_all(values)
    _no_fatal_and_errors_say_why(instance, status)
    fmu2 = instance.slave.fmu
    try:
        fmu2.setupExperiment(startTime=0.0)
        fmu2.enterInitializationMode()
        fmu2.exitInitializationMode()
    except FMICallException as error:
        _no_fatal_and_errors_say_why(instance, error.status)
        return False
    return True


@pytest.mark.parametrize("fmu,declared,inputs", [
    ("EngineShaft", component_parameters.ENGINE, ("tau", "tau_rate", "tau_accel")),
    ("LoadShaft", component_parameters.LOAD, ("tau", "tau_rate", "tau_accel")),
])
@fuzz(150)
@given(data=st.data())
def test_shaft_fmus_never_fail_fatally_and_report_finite_outputs(instances, fmu, declared, inputs, data):
    instance = instances[fmu]
    instance.reset()
    if not _initialised(instance, data.draw(parameters(declared))):
        return                         # refused (the values do not fit together): said why
    t = 0.0
    for _ in range(data.draw(st.integers(1, 4))):
        instance.set_all({"tau": data.draw(st.floats(-1e12, 1e12)), "tau_rate": data.draw(st.floats(-1e15, 1e15)),
                          "tau_accel": data.draw(st.floats(-1e18, 1e18))})
        h = data.draw(st.floats(1e-6, 0.1))
        status = instance.slave.call("doStep", t, h)
        _no_fatal_and_errors_say_why(instance, status)
        if status >= 2:
            break
        t += h
        status, values = _outputs(instance)
        _no_fatal_and_errors_say_why(instance, status)
        if status == 0:
            assert all(math.isfinite(v) for v in values), values


@fuzz(100)
@given(parameters(component_parameters.COUPLING), misalignment,
       st.lists(st.tuples(*[st.floats(-1e12, 1e12)] * 4), min_size=1, max_size=3))
def test_coupling_fmu_never_fails_fatally_and_reports_finite_outputs(instances, values, alpha, inputs):
    instance = instances["LeverCoupling"]
    instance.reset()
    if not _initialised(instance, {**values, "misalignment": alpha}):
        return
    for k, (phi1, w1, phi2, w2) in enumerate(inputs):
        status = instance.set_all({"phi1": phi1, "w1": w1, "phi2": phi2, "w2": w2})
        _no_fatal_and_errors_say_why(instance, status)
        status, outputs = _outputs(instance)
        _no_fatal_and_errors_say_why(instance, status)
        if status == 0:
            assert all(math.isfinite(v) for v in outputs)
        status = instance.slave.call("doStep", k * 1e-3, 1e-3)
        _no_fatal_and_errors_say_why(instance, status)
