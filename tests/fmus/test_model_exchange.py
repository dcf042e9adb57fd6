"""The FMUs' Model Exchange interface (fmu_src/lever/fmus/model_exchange.py and me_*.py, the native
entry's ME state machine in build/shim): the same FMU files run in fmpy's Model Exchange
simulation with CVode as they run in co-simulation; their directional derivatives (both
interfaces) are the physics' analytic partials and their declared dependencies hold the
sparsity that finite differences find; ME calls out of order, NaN states and wrong sizes
are refused with fmi2Error and the instance stays usable.
"""
from __future__ import annotations

import ctypes
import math
import random
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.validation import validate_fmu

ME_FMUS = ("LeverCoupling", "EngineShaft", "LoadShaft", "MisalignmentSource", "FreewheelRectifier")
CHANNEL = 0x40000000   # the native entry's own value references (lever.fmus.me_channel.CHANNEL)
FMI2_ERROR = 3


@pytest.fixture(scope="module")
def unpacked(fmu_dir, tmp_path_factory):
    """name -> (model description, extracted directory)."""
    out = {}
    for name in ME_FMUS:
        path = str(Path(fmu_dir) / f"{name}.fmu")
        out[name] = (fmpy.read_model_description(path),
                     fmpy.extract(path, unzipdir=str(tmp_path_factory.mktemp(name))))
    return out


def open_model(unpacked, name, kind=FMU2Model, parameters=None):
    md, unzipdir = unpacked[name]
    fmu = kind(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=name, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    for key, value in (parameters or {}).items():
        if isinstance(value, str):
            fmu.setString([vr[key]], [value])
        else:
            fmu.setReal([vr[key]], [float(value)])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    if kind is FMU2Model:
        while fmu.newDiscreteStates()[0]:
            pass
        fmu.enterContinuousTimeMode()
    return fmu, md, vr


def free(fmu):
    fmu.terminate()
    fmu.freeInstance()


def raw(fmu, function, argtypes, *args) -> int:
    """The status of an FMI function called straight from the library (one fmpy does not
    wrap for this interface)."""
    entry = getattr(fmu.dll, function)
    entry.argtypes, entry.restype = [ctypes.c_void_p, *argtypes], ctypes.c_int
    return entry(fmu.component, *args)


def refused(call, *args):
    with pytest.raises(FMICallException) as caught:
        call(*args)
    assert caught.value.status == FMI2_ERROR


# --------------------------------------------------------------------------------------
# The model descriptions
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ME_FMUS)
def test_model_description_offers_both_interfaces(fmu_dir, name):
    path = str(Path(fmu_dir) / f"{name}.fmu")
    assert validate_fmu(path) == []
    md = fmpy.read_model_description(path)
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.modelExchange.providesDirectionalDerivative and md.coSimulation.providesDirectionalDerivative
    states = {"LeverCoupling": 0, "EngineShaft": 4, "LoadShaft": 3, "MisalignmentSource": 0,
              "FreewheelRectifier": 11}[name]
    assert md.numberOfContinuousStates == states
    assert md.numberOfEventIndicators == {"EngineShaft": 1, "LoadShaft": 1, "FreewheelRectifier": 8}.get(name, 0)
    for unknown in md.derivatives:
        assert unknown.variable.derivative is not None
    # never "everything depends on everything": each unknown names what it depends on
    knowns = {v.name for v in md.modelVariables if v.causality == "input"} | {
        u.variable.derivative.name for u in md.derivatives}
    for unknown in md.outputs + md.derivatives:
        assert unknown.dependencies is not None, unknown.variable.name
        assert {d.name for d in unknown.dependencies} <= knowns
    if states:
        assert any(len(u.dependencies) < len(knowns) for u in md.outputs + md.derivatives)


# --------------------------------------------------------------------------------------
# Model Exchange runs against the co-simulation edition
# --------------------------------------------------------------------------------------

def both_runs(fmu_dir, name, inputs, outputs, parameters=None, stop=1.0, rtol=1e-10, interval=None):
    path = str(Path(fmu_dir) / f"{name}.fmu")
    runs = {}
    for kind in ("CoSimulation", "ModelExchange"):
        runs[kind] = fmpy.simulate_fmu(path, fmi_type=kind, solver="CVode", stop_time=stop,
                                       output_interval=interval or stop / 20,
                                       step_size=1e-3, relative_tolerance=rtol, input=inputs, output=outputs,
                                       start_values=parameters or {})
    return runs["CoSimulation"], runs["ModelExchange"]


def constant_input(**values):
    dtype = [("time", float)] + [(k, float) for k in values]
    return np.array([(0.0, *values.values()), (10.0, *values.values())], dtype=dtype)


# CVode at rtol 1e-10 against the co-simulation's closed forms (the engine's linear
# characteristic, a constant load) or its RK4 substeps of 2.5e-4 s (error ~1e-12 here):
# both are within 1e-7 relative of the exact solution, so 1e-6 holds on any machine and
# still catches a wrong derivative (which moves the result by percents).
@pytest.mark.parametrize("name, parameters, tau", [
    ("EngineShaft", {}, -100.0),
    ("EngineShaft", {"torque_lag": 0.05, "torque_start": 200.0}, -300.0),
    ("EngineShaft", {"characteristic": "0:600; 30:640; 45:300; 60:0"}, -200.0),
    ("LoadShaft", {"load_kind": "constant", "mean_torque": 50.0}, 20.0),
    ("LoadShaft", {"load_kind": "fourier", "fourier": "40; 10:5; 3:-2"}, 10.0),
])
def test_me_run_matches_co_simulation(fmu_dir, name, parameters, tau):
    outputs = ["phi", "w", "a", "engine_work" if name == "EngineShaft" else "load_work"]
    cs, me = both_runs(fmu_dir, name, constant_input(tau=tau, tau_rate=0.0, tau_accel=0.0), outputs, parameters)
    for out in outputs:
        scale = max(np.max(np.abs(cs[out])), 1.0)
        # the ME result has rows of its own at events: read it at the output points
        assert np.max(np.abs(cs[out] - np.interp(cs["time"], me["time"], me[out]))) <= 1e-6 * scale, (
            out, cs[out][-1], me[out][-1])


@pytest.mark.parametrize("name, parameters, live", [
    ("EngineShaft", {}, 0),                                            # linear characteristic: no edges
    ("EngineShaft", {"characteristic": "0:600; 40:620; 80:0"}, 1),     # the table's points are edges
    ("LoadShaft", {}, 0),                                              # no friction: no stops
    ("LoadShaft", {"friction_torque": 1.0, "breakaway_torque": 2.0}, 1),
    ("FreewheelRectifier", {}, None),                                  # every contact and stop: all
])
def test_live_event_indicators_say_which_can_change_sign(unpacked, name, parameters, live):
    md = unpacked[name][0]
    variable = next(v for v in md.modelVariables if v.name == "live_event_indicators")
    assert (variable.type, variable.causality, variable.variability) == ("Integer", "calculatedParameter", "fixed")
    for kind in (FMU2Model, FMU2Slave):
        fmu, md, vr = open_model(unpacked, name, kind, parameters)
        try:
            value = fmu.getInteger([vr["live_event_indicators"]])[0]
            assert value == (md.numberOfEventIndicators if live is None else live)
            if kind is FMU2Model and value < md.numberOfEventIndicators:
                # the ones left out stay positive while the model moves
                fmu.setTime(0.5)
                n = md.numberOfEventIndicators
                z = (ctypes.c_double * n)()
                fmu.getEventIndicators(z, n)
                assert all(v > 0.0 for v in z[value:])
        finally:
            free(fmu)


def test_me_friction_stop_and_hold(fmu_dir):
    # Coulomb friction brakes the shaft from 39 rad/s to rest (at t = 39*0.161/20 s =
    # 0.314 s): the stop is an event, after which static friction holds it.  The
    # co-simulation edition locates the stop inside its step; the closed form is exact.
    parameters = {"load_kind": "constant", "mean_torque": 0.0, "friction_torque": 20.0, "breakaway_torque": 30.0}
    cs, me = both_runs(fmu_dir, "LoadShaft", constant_input(tau=0.0, tau_rate=0.0, tau_accel=0.0),
                       ["phi", "w"], parameters)
    stop = 39.0 * 0.161 / 20.0
    assert me["w"][-1] == 0.0 and cs["w"][-1] == 0.0
    exact = 39.0 * stop / 2.0
    assert me["phi"][-1] == pytest.approx(exact, rel=1e-6)
    assert cs["phi"][-1] == pytest.approx(exact, rel=1e-6)


def test_me_freewheel_matches_co_simulation(fmu_dir):
    # The rectifier's gaps and stick/slip are events (8 indicators); its co-simulation
    # edition steps RK4 with located events.  At CVode's rtol 1e-9 both agree within
    # 2e-6 of the largest value over 0.1 s of engagements and releases (the half-couplings'
    # speed, which rings at the contacts, 1.6e-5 at one output point); 1e-4 leaves room for
    # another machine's last bits in the event location and still catches a wrong
    # derivative or a missed event (which move the result by percents).  The output interval is short:
    # between output points fmpy's CVode may take at most 500 steps, and the contacts
    # (2000-5000 rad/s) need many.
    outputs = ["phi", "w", "half_coupling_speed", "driven_speed", "input_work", "dissipated_energy"]
    cs, me = both_runs(fmu_dir, "FreewheelRectifier", None, outputs, stop=0.1, rtol=1e-9, interval=1e-3)
    for out in outputs:
        scale = max(np.max(np.abs(cs[out])), 1e-3)
        assert np.max(np.abs(cs[out] - np.interp(cs["time"], me["time"], me[out]))) <= 1e-4 * scale, (
            out, cs[out][-1], me[out][-1])


def test_me_stateless_models_match_co_simulation(fmu_dir):
    t = np.linspace(0.0, 1.0, 11)
    inputs = np.array(list(zip(t, 0.1 * np.sin(3 * t), 40 + t, 0.05 * t, 39 + 2 * t, np.full_like(t, 0.2))),
                      dtype=[("time", float), ("phi1", float), ("w1", float), ("phi2", float), ("w2", float),
                             ("misalignment", float)])
    outputs = ["tau1", "tau2", "U12", "theta", "elastic_energy", "dissipated_power"]
    cs, me = both_runs(fmu_dir, "LeverCoupling", inputs, outputs, {"transfer_mode": "kinematic"})
    for out in outputs:
        # fmpy's co-simulation records the outputs after each step, from the inputs at its
        # start: its row k + 1 is Model Exchange's row k
        assert np.allclose(cs[out][1:], me[out][:-1], rtol=1e-12, atol=1e-12), out
    cs, me = both_runs(fmu_dir, "MisalignmentSource", None, ["misalignment", "misalignment_rate"],
                       {"table": "0:0.1; 0.33:0.2; 0.71:0.05"})
    # the rate jumps at the table's times: time events, rows of their own in the ME result
    assert {0.33, 0.71} <= set(me["time"])
    for out in ("misalignment", "misalignment_rate"):
        at_points = np.interp(cs["time"], me["time"], me[out])
        assert np.allclose(cs[out], at_points, rtol=1e-12, atol=1e-12), out


# --------------------------------------------------------------------------------------
# Directional derivatives: the analytic partials against central differences
# --------------------------------------------------------------------------------------

def me_unknowns(fmu, md, vr, nx):
    """The derivatives, then the outputs, at the point set."""
    dx = (ctypes.c_double * max(nx, 1))()
    if nx:
        fmu.getDerivatives(dx, nx)
    return list(dx)[:nx] + fmu.getReal([vr[u.variable.name] for u in md.outputs])


def set_point(fmu, md, vr, x, u):
    names = [v.name for v in md.modelVariables if v.causality == "input"]
    fmu.setReal([vr[n] for n in names], [u[n] for n in names])
    if x:
        fmu.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))


def shaft_inputs(r):
    return {"tau": r.uniform(-500, 500), "tau_rate": r.uniform(-1e3, 1e3), "tau_accel": r.uniform(-1e4, 1e4)}


def freewheel_states(r):
    angles = [r.uniform(-0.05, 0.05) for _ in range(4)]
    speeds = [r.uniform(-3.0, 3.0) for _ in range(4)]
    return [v for pair in zip(angles, speeds) for v in pair] + [r.uniform(0, 10) for _ in range(3)]


POINTS = {
    "FreewheelRectifier": ({}, lambda r: {"tau": r.uniform(-20, 20), "tau_rate": r.uniform(-100, 100)},
                           freewheel_states),
    "LeverCoupling": ({"transfer_mode": "kinematic"}, lambda r: {
        "phi1": r.uniform(-3, 3), "w1": r.uniform(-50, 50), "phi2": r.uniform(-3, 3), "w2": r.uniform(-50, 50),
        "misalignment": r.uniform(0.05, 0.35)}, lambda r: []),
    "EngineShaft": ({"torque_lag": 0.05}, lambda r: shaft_inputs(r),
                    lambda r: [r.uniform(-5, 5), r.uniform(1, 60), r.uniform(0, 100), r.uniform(-300, 600)]),
    "LoadShaft": ({"load_kind": "fourier", "fourier": "40; 10:5; 3:-2", "viscous_damping": 0.3},
                  lambda r: shaft_inputs(r),
                  lambda r: [r.uniform(-5, 5), r.uniform(1, 60), r.uniform(0, 100)]),
}


@pytest.mark.parametrize("name", sorted(POINTS))
def test_directional_derivatives_are_central_differences(unpacked, name):
    parameters, draw_u, draw_x = POINTS[name]
    fmu, md, vr = open_model(unpacked, name, parameters=parameters)
    try:
        nx = md.numberOfContinuousStates
        states = [u.variable.derivative.name for u in md.derivatives]
        inputs = [v.name for v in md.modelVariables if v.causality == "input"]
        unknowns = [u.variable.name for u in md.derivatives] + [u.variable.name for u in md.outputs]
        declared = [{d.name for d in u.dependencies} for u in list(md.derivatives) + list(md.outputs)]
        rng = random.Random(31)
        for _ in range(5):
            x, u = draw_x(rng), draw_u(rng)
            for k, known in enumerate(states + inputs):
                analytic, centrals = analytic_and_central(fmu, md, vr, x, u, unknowns, k, known, 1e-6)
                for j, name_j in enumerate(unknowns):
                    central = centrals[j]
                    scale = max(abs(central), abs(analytic[j]), 1.0)
                    assert abs(analytic[j] - central) <= 1e-6 * scale, (name_j, known, analytic[j], central)
                    if abs(central) > 1e-9 * scale:
                        # the sparsity finite differences find is declared
                        assert known in declared[j], (name_j, known)
    finally:
        free(fmu)


def analytic_and_central(fmu, md, vr, x, u, unknowns, k, known, relative_step):
    """The FMU's directional derivative of ``unknowns`` along the ``k``-th of its states and
    then inputs (``known``) at ``(x, u)``, and the central difference of the same, its step
    ``relative_step`` of the value differentiated (at least of 1)."""
    nx = md.numberOfContinuousStates
    set_point(fmu, md, vr, x, u)
    analytic = fmu.getDirectionalDerivative([vr[n] for n in unknowns], [vr[known]], [1.0])
    value = x[k] if k < nx else u[known]
    h = relative_step * max(abs(value), 1.0)
    sides = []
    for sign in (1.0, -1.0):
        xs, us = list(x), dict(u)
        if k < nx:
            xs[k] = value + sign * h
        else:
            us[known] = value + sign * h
        set_point(fmu, md, vr, xs, us)
        sides.append(me_unknowns(fmu, md, vr, nx))
    return analytic, [(plus - minus) / (2 * h) for plus, minus in zip(*sides)]


#: every FMU with states or inputs at the edges of what users pass: large times (a load's
#: time series), port torques of 1e5 N*m, speeds of 1e3 rad/s, a stiffness of 1e9
EXTREMES = {
    "LeverCoupling": ({"transfer_mode": "kinematic", "stiffness": 1e9, "damping": 1e7},
                      {"phi1": 1e3 + 0.01, "w1": 1e3, "phi2": 1e3, "w2": -1e3, "misalignment": 0.3}, []),
    "EngineShaft": ({"torque_lag": 0.05, "characteristic": "0:600; 40:620; 80:0"},
                    {"tau": -1e5, "tau_rate": 0.0, "tau_accel": 0.0}, [1e4, 1e3, 1e7, -1e5]),
    "LoadShaft": ({"load_kind": "random", "random_amplitude": 40.0, "order_share": 0.5},
                  {"tau": 1e5, "tau_rate": 0.0, "tau_accel": 0.0}, [1e4, 1e3, 1e7]),
}


@pytest.mark.parametrize("name", sorted(EXTREMES))
@pytest.mark.parametrize("t", [0.0, 1e6])
def test_directional_derivatives_hold_at_extreme_inputs_and_large_times(unpacked, name, t):
    """The analytic partials at the edges (large times, torques, speeds, stiffness) against
    central differences with a step scaled to the variable differentiated."""
    parameters, u, x = EXTREMES[name]
    fmu, md, vr = open_model(unpacked, name, parameters=parameters)
    try:
        nx = md.numberOfContinuousStates
        states = [u_.variable.derivative.name for u_ in md.derivatives]
        inputs = [k for k in u if "rate" not in k and "accel" not in k]
        unknowns = [u_.variable.name for u_ in md.derivatives] + [u_.variable.name for u_ in md.outputs]
        fmu.setTime(t)
        for k, known in enumerate(states + inputs):
            analytic, centrals = analytic_and_central(fmu, md, vr, x, u, unknowns, k, known, 1e-7)
            for j, name_j in enumerate(unknowns):
                central = centrals[j]
                scale = max(abs(central), abs(analytic[j]), 1.0)
                assert abs(analytic[j] - central) <= 1e-5 * scale, (t, name_j, known, analytic[j], central)
    finally:
        free(fmu)


def test_the_freewheels_outputs_have_exact_derivatives_at_extreme_inputs(unpacked):
    """Every output of the freewheel (its torques, flags and energies too) against a central
    difference whose step is scaled to the variable differentiated and stays inside the
    contact it is in, at port torques up to 1e5 N*m and next to a gap edge: analytic, within
    1e-6.  A difference quotient inside the FMU with a step grown by the large input gave
    d mesh_torque / d phi -18,750 for -25,000 and d mesh_contact / d phi 2,677 for 0."""
    fmu, md, vr = open_model(unpacked, "FreewheelRectifier")
    try:
        nx = md.numberOfContinuousStates
        states = [u.variable.derivative.name for u in md.derivatives]
        unknowns = [u.variable.name for u in md.derivatives] + [u.variable.name for u in md.outputs]
        x0 = [0.01, 0.4, 0.02, 0.3, 0.015, 0.2, 0.0, 0.1, 1.0, 2.0, 3.0]   # every contact closed
        mesh = states.index("torsion_end_angle")
        cases = []
        for tau in (0.0, 1e4, 1e5, -1e5):
            x = list(x0)
            x[mesh] = x[states.index("phi")] + 0.005                        # mesh 5 mrad into contact
            cases.append((x, tau))
        edge = list(x0)
        edge[mesh] = edge[states.index("phi")] + 2e-6                       # 2 urad from the mesh's edge
        cases.append((edge, 200.0))
        for x, tau in cases:
            u = {"tau": tau, "tau_rate": 0.0}
            for k, known in enumerate(states + ["tau"]):
                set_point(fmu, md, vr, x, u)
                analytic = fmu.getDirectionalDerivative([vr[n] for n in unknowns], [vr[known]], [1.0])
                h = 1e-8 if k < nx and k % 2 == 0 and k < 8 else 1e-6 * max(1.0, abs(x[k] if k < nx else tau))
                sides = []
                for sign in (1.0, -1.0):
                    xs, us = list(x), dict(u)
                    if k < nx:
                        xs[k] += sign * h
                    else:
                        us["tau"] += sign * h
                    set_point(fmu, md, vr, xs, us)
                    sides.append(me_unknowns(fmu, md, vr, nx))
                for j, name_j in enumerate(unknowns):
                    central = (sides[0][j] - sides[1][j]) / (2 * h)
                    scale = max(abs(central), abs(analytic[j]), 1.0)
                    assert abs(analytic[j] - central) <= 1e-6 * scale, (tau, name_j, known, analytic[j], central)
    finally:
        free(fmu)


def test_co_simulation_directional_derivative(unpacked):
    """In co-simulation: the outputs with respect to the inputs, from the same partials."""
    fmu, md, vr = open_model(unpacked, "LeverCoupling", FMU2Slave, {"transfer_mode": "kinematic"})
    try:
        inputs = {"phi1": 0.3, "w1": 40.0, "phi2": 0.1, "w2": 39.0, "misalignment": 0.2}
        outputs = ["tau1", "tau2", "U12", "theta"]
        for known in inputs:
            fmu.setReal([vr[n] for n in inputs], list(inputs.values()))
            analytic = fmu.getDirectionalDerivative([vr[n] for n in outputs], [vr[known]], [1.0])
            h = 1e-6 * max(abs(inputs[known]), 1.0)
            sides = []
            for sign in (1.0, -1.0):
                fmu.setReal([vr[known]], [inputs[known] + sign * h])
                sides.append(fmu.getReal([vr[n] for n in outputs]))
            for j, out in enumerate(outputs):
                central = (sides[0][j] - sides[1][j]) / (2 * h)
                assert abs(analytic[j] - central) <= 1e-6 * max(abs(central), 1.0), (out, known)
        # a state is no known in co-simulation; an output no known at all
        refused(fmu.getDirectionalDerivative, [vr["tau1"]], [vr["tau2"]], [1.0])
        assert fmu.getDirectionalDerivative([vr["U12"]], [vr["w1"]], [1.0]) == [0.0]
    finally:
        free(fmu)


# --------------------------------------------------------------------------------------
# The ME state machine and bad calls: fmi2Error, the instance usable
# --------------------------------------------------------------------------------------

def test_me_calls_out_of_order_are_refused(unpacked):
    md, unzipdir = unpacked["LoadShaft"]
    fmu = FMU2Model(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="LoadShaft", instanceName="order")
    fmu.instantiate()
    nx = md.numberOfContinuousStates
    x = (ctypes.c_double * nx)()
    try:
        refused(fmu.getDerivatives, x, nx)                 # instantiated: not yet
        refused(fmu.setTime, 0.5)
        refused(fmu.enterEventMode)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        refused(fmu.setContinuousStates, x, nx)            # initialization mode
        refused(fmu.newDiscreteStates)
        fmu.getContinuousStates(x, nx)                     # allowed there
        fmu.exitInitializationMode()                       # -> event mode
        refused(fmu.setContinuousStates, x, nx)            # event mode: only in continuous time
        refused(fmu.completedIntegratorStep)
        assert raw(fmu, "fmi2DoStep", [ctypes.c_double, ctypes.c_double, ctypes.c_int], 0.0, 0.1, 1) == FMI2_ERROR
        state = ctypes.c_void_p()
        assert raw(fmu, "fmi2GetFMUstate", [ctypes.c_void_p], ctypes.byref(state)) == FMI2_ERROR
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        refused(fmu.newDiscreteStates)                     # continuous time: enter event mode first
        refused(fmu.enterContinuousTimeMode)
        refused(fmu.exitInitializationMode)
        # still usable: a full round of continuous-time calls
        fmu.setTime(0.1)
        fmu.getContinuousStates(x, nx)
        fmu.setContinuousStates(x, nx)
        dx = (ctypes.c_double * nx)()
        fmu.getDerivatives(dx, nx)
        assert dx[0] == x[1]
        assert fmu.completedIntegratorStep() == (False, False)
        fmu.enterEventMode()
        fmu.newDiscreteStates()
        fmu.terminate()
        refused(fmu.setTime, 0.2)                          # terminated
        fmu.getDerivatives(dx, nx)                         # still readable
    finally:
        fmu.freeInstance()


def test_me_bad_arguments_are_refused(unpacked):
    fmu, md, vr = open_model(unpacked, "EngineShaft")
    nx, nz = md.numberOfContinuousStates, md.numberOfEventIndicators
    try:
        x = (ctypes.c_double * nx)()
        fmu.getContinuousStates(x, nx)
        before = list(x)
        for k in range(nx):
            for bad in (math.nan, math.inf):
                y = (ctypes.c_double * nx)(*before)
                y[k] = bad
                refused(fmu.setContinuousStates, y, nx)
        big = (ctypes.c_double * (nx + 1))()
        refused(fmu.setContinuousStates, big, nx + 1)     # wrong sizes
        refused(fmu.setContinuousStates, x, nx - 1)
        refused(fmu.getDerivatives, big, nx + 1)
        refused(fmu.getContinuousStates, big, nx - 1)
        refused(fmu.getEventIndicators, big, nz + 1)
        refused(fmu.getNominalsOfContinuousStates, big, nx + 1)
        refused(fmu.setContinuousStates, None, nx)         # NULL
        refused(fmu.getDerivatives, None, nx)
        refused(fmu.fmi2NewDiscreteStates, fmu.component, None)
        refused(fmu.setTime, math.nan)
        refused(fmu.getReal, [CHANNEL])                    # the native entry's own references
        refused(fmu.setReal, [CHANNEL + 1], [0.0])
        refused(fmu.getDirectionalDerivative, [vr["a"]], [vr["tau"]], [math.nan])
        refused(fmu.getDirectionalDerivative, [vr["a"]], [CHANNEL], [1.0])
        refused(fmu.getDirectionalDerivative, [vr["tau"]], [vr["w"]], [1.0])   # an input is no unknown
        refused(fmu.setReal, [vr["inertia"]], [1.0])       # a parameter after initialisation
        # nothing changed, the instance is usable
        after = (ctypes.c_double * nx)()
        fmu.getContinuousStates(after, nx)
        assert list(after) == before
        dx = (ctypes.c_double * nx)()
        fmu.getDerivatives(dx, nx)
        assert all(math.isfinite(v) for v in dx)
        z = (ctypes.c_double * nz)()
        fmu.getEventIndicators(z, nz)
    finally:
        free(fmu)


def test_me_functions_are_refused_in_co_simulation(unpacked):
    fmu, md, vr = open_model(unpacked, "EngineShaft", FMU2Slave)
    try:
        for function, argtypes, args in (("fmi2SetTime", [ctypes.c_double], (0.1,)), ("fmi2EnterEventMode", [], ()),
                                         ("fmi2EnterContinuousTimeMode", [], ())):
            assert raw(fmu, function, argtypes, *args) == FMI2_ERROR, function
        x = (ctypes.c_double * 4)()
        assert raw(fmu, "fmi2GetDerivatives", [ctypes.c_void_p, ctypes.c_size_t], x, 4) == FMI2_ERROR
        fmu.doStep(0.0, 1e-3)                              # Co-Simulation goes on
        assert fmu.getReal([vr["w"]])[0] > 0.0
    finally:
        free(fmu)


def test_me_instances_reset_and_reuse(unpacked):
    """fmi2Reset and a freed instance's reuse keep the interface: Model Exchange again."""
    fmu, md, vr = open_model(unpacked, "LoadShaft")
    nx = md.numberOfContinuousStates
    fmu.reset()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.newDiscreteStates()
    fmu.enterContinuousTimeMode()
    x = (ctypes.c_double * nx)()
    fmu.getContinuousStates(x, nx)
    assert list(x)[:2] == [0.0, 39.0]
    free(fmu)
    cs, _, cvr = open_model(unpacked, "LoadShaft", FMU2Slave)   # the kept inner instance, now co-simulation
    cs.doStep(0.0, 1e-3)
    assert cs.getReal([cvr["phi"]])[0] > 0.0
    free(cs)


# --------------------------------------------------------------------------------------
# The point block: what the native entry keeps until the model's next call
# --------------------------------------------------------------------------------------

def read_back(fmu, md, vr, kind):
    """One way a host reads the model at the point it set."""
    arrays = {"derivatives": (fmu.getDerivatives, md.numberOfContinuousStates),
              "states": (fmu.getContinuousStates, md.numberOfContinuousStates),
              "indicators": (fmu.getEventIndicators, md.numberOfEventIndicators)}
    if kind in arrays:
        getter, n = arrays[kind]
        out = (ctypes.c_double * max(n, 1))()
        if n:
            getter(out, n)
        return list(out)[:n]
    if kind == "outputs":
        return fmu.getReal([u.variable.valueReference for u in md.outputs])
    if kind == "state outputs":         # answered by the native entry from the states set
        states = {u.variable.derivative.name for u in md.derivatives}
        return fmu.getReal([u.variable.valueReference for u in md.outputs if u.variable.name in states])
    if kind == "inputs":
        return fmu.getReal([v.valueReference for v in md.modelVariables if v.causality == "input"])
    known = [v.valueReference for v in md.modelVariables if v.causality == "input"][:1]
    return fmu.getDirectionalDerivative([u.variable.valueReference for u in md.outputs], known, [1.0])


def a_refused_set_keeps_what_was_set(fmu, vr, inputs):
    """A refused set (a NaN input) is refused at once: what was set before it stays set,
    the refused input keeps its value."""
    before = fmu.getReal([vr[n] for n in inputs])
    fmu.setReal([vr[inputs[-1]]], [before[-1] + 0.125])
    refused(fmu.setReal, [vr[inputs[0]]], [float("nan")])
    after = fmu.getReal([vr[n] for n in inputs])
    assert after[-1] == before[-1] + 0.125 and after[0] == before[0]


@pytest.mark.parametrize("name", sorted(POINTS))
def test_the_model_computes_with_what_the_host_set_in_any_order(unpacked, name):
    """fmi2SetTime, fmi2SetContinuousStates and fmi2SetReal of inputs in range are kept in
    the native entry's point block until the model's next call (build/shim): whatever the
    order of the sets, however the inputs are split between calls and whichever call reads
    first, the model computes with exactly what was set, bit for bit the values of an
    instance that took each set at once (a read after each).  A set refused (a NaN input)
    is refused at once, with what was set before it kept."""
    parameters, draw_u, draw_x = POINTS[name]
    lazy, md, vr = open_model(unpacked, name, parameters=parameters)
    eager, _, _ = open_model(unpacked, name, parameters=parameters)
    nx = md.numberOfContinuousStates
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    probe = [md.outputs[0].variable.valueReference]
    rng = random.Random(11)
    try:
        for trial in range(12):
            t, x, u = rng.uniform(0.0, 5.0), draw_x(rng), draw_u(rng)
            chosen = [n for n in inputs if rng.random() < 0.7] or inputs[:1]
            eager.setTime(t)
            eager.getReal(probe)
            if nx:
                eager.setContinuousStates((ctypes.c_double * nx)(*x), nx)
                eager.getReal(probe)
            for n in chosen:
                eager.setReal([vr[n]], [u[n]])
                eager.getReal(probe)
            sets = ["time"] + (["states"] if nx else [])
            rest = list(chosen)
            while rest:                 # the inputs in random groups
                k = rng.randint(1, len(rest))
                sets.append(rest[:k])
                rest = rest[k:]
            rng.shuffle(sets)
            for what in sets:
                if what == "time":
                    lazy.setTime(t)
                elif what == "states":
                    lazy.setContinuousStates((ctypes.c_double * nx)(*x), nx)
                else:
                    lazy.setReal([vr[n] for n in what], [u[n] for n in what])
            if rng.random() < 0.5:      # what was set reads back as it was set
                assert read_back(lazy, md, vr, "states") == x
                held = dict(zip(inputs, read_back(lazy, md, vr, "inputs")))
                assert [held[n] for n in chosen] == [u[n] for n in chosen]
            kinds = ["derivatives", "states", "indicators", "outputs", "inputs", "directional", "state outputs"]
            rng.shuffle(kinds)
            for kind in kinds:
                assert read_back(lazy, md, vr, kind) == read_back(eager, md, vr, kind), (trial, kind, sets)
        a_refused_set_keeps_what_was_set(lazy, vr, inputs)
    finally:
        free(lazy)
        free(eager)


@pytest.mark.parametrize("name", sorted(POINTS))
def test_a_co_simulation_step_takes_what_the_host_set_in_any_order(unpacked, name):
    """In Co-Simulation too, fmi2SetReal of inputs in range is kept in the native entry's
    point block until the model's next fmi2GetReal, fmi2SetReal or fmi2DoStep (build/shim):
    an instance whose sets wait there - stepped, its state saved and restored, read in any
    order - gives bit for bit the values of one that reads after every set (each set taken
    at once).  A state saved holds the inputs set before it; a state restored replaces the
    inputs set before it; a refused set (a NaN input) is refused at once.  The outputs a
    step leaves in the block, read alone, are the model's own, which a read that mixes in
    the inputs gets from the model: after a step, a set, a save or a restore."""
    parameters, draw_u, _ = POINTS[name]
    lazy, md, vr = open_model(unpacked, name, kind=FMU2Slave, parameters=parameters)
    eager, _, _ = open_model(unpacked, name, kind=FMU2Slave, parameters=parameters)
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [u.variable.valueReference for u in md.outputs]
    probe = outputs[:1]
    rng = random.Random(7)
    t, h, saved = 0.0, 1e-3, None
    try:
        for trial in range(16):
            u = draw_u(rng)
            chosen = [n for n in inputs if rng.random() < 0.7] or inputs[:1]
            for n in chosen:
                eager.setReal([vr[n]], [u[n]])
                eager.getReal(probe)
            rest = list(chosen)
            while rest:                 # the inputs in random groups, no read in between
                k = rng.randint(1, len(rest))
                lazy.setReal([vr[n] for n in rest[:k]], [u[n] for n in rest[:k]])
                rest = rest[k:]
            what = rng.choice(["step", "save", "restore", "restore only", "read"])
            if what == "save":          # a state saved with the inputs just set waiting
                states = [fmu.getFMUstate() for fmu in (lazy, eager)]
                if saved is not None:
                    for fmu, state in zip((lazy, eager), saved[0]):
                        fmu.freeFMUstate(state)
                saved = (states, t)
            elif what.startswith("restore") and saved is not None:
                for fmu, state in zip((lazy, eager), saved[0]):
                    fmu.setFMUstate(state)
                t = saved[1]
            if what not in ("read", "restore only"):    # a step straight after the sets
                for fmu in (lazy, eager):
                    fmu.doStep(t, h)
                t += h
            held = [vr[n] for n in inputs]
            both = eager.getReal(outputs + held)        # the model answers: the inputs are no outputs
            order = [(outputs, both[:len(outputs)]), (held, both[len(outputs):])]
            rng.shuffle(order)
            for refs, expected in order:
                assert lazy.getReal(refs) == expected, (trial, what, chosen)
        a_refused_set_keeps_what_was_set(lazy, vr, inputs)
    finally:
        if saved is not None:
            for fmu, state in zip((lazy, eager), saved[0]):
                fmu.freeFMUstate(state)
        free(lazy)
        free(eager)


def test_states_read_after_an_event_are_the_models(unpacked):
    """The native entry answers a read of outputs that are states from the states the host
    set in Continuous-Time Mode, and never after an event moved them: a friction stop puts
    the load shaft at rest exactly, and that is what a read of its speed says."""
    fmu, md, vr = open_model(unpacked, "LoadShaft", parameters={"friction_torque": 1.0, "breakaway_torque": 2.0})
    try:
        nx = md.numberOfContinuousStates
        x = (ctypes.c_double * nx)()
        fmu.getContinuousStates(x, nx)
        assert x[1] > 0.0                       # slipping forward
        x[1] = -1e-3                            # past the stop
        fmu.setContinuousStates(x, nx)
        assert fmu.getReal([vr["w"]]) == [-1e-3]
        fmu.enterEventMode()
        while fmu.newDiscreteStates()[0]:
            pass
        fmu.enterContinuousTimeMode()
        fmu.getContinuousStates(x, nx)
        assert x[1] == 0.0
        assert fmu.getReal([vr["phi"], vr["w"]]) == [x[0], 0.0]
    finally:
        free(fmu)


def test_a_directional_derivative_after_an_event_is_the_new_modes(unpacked):
    """The partials are kept for the next directional derivative at the same point (one per
    state and input in a Jacobian), never across an event: a breakaway switches the load
    shaft from held to slipping at the same states and inputs, and da/dtau with it."""
    fmu, md, vr = open_model(unpacked, "LoadShaft",
                             parameters={"friction_torque": 1.0, "breakaway_torque": 2.0, "w_start": 0.0})
    try:
        def da_dtau():
            return fmu.getDirectionalDerivative([vr["a"]], [vr["tau"]], [1.0])[0]

        fmu.setReal([vr["tau"]], [5.0])         # beyond the breakaway torque, still held
        held = da_dtau()
        assert held == da_dtau() == 0.0
        fmu.enterEventMode()
        while fmu.newDiscreteStates()[0]:
            pass
        fmu.enterContinuousTimeMode()
        assert da_dtau() > 0.0                  # slipping: 1/I
    finally:
        free(fmu)


def test_a_read_in_initialization_mode_is_the_new_parameters_whatever_it_reads(unpacked):
    """After a parameter is set in Initialization Mode every read comes from the model it
    makes: a state derivative read alone equals the same derivative read after an output
    (it read 0.0 alone), and live_event_indicators counts the new model's events."""
    md, unzipdir = unpacked["EngineShaft"]
    vr = {v.name: v.valueReference for v in md.modelVariables}
    readings = []
    for reads in ([vr["der(engine_work)"]], [vr["phi"], vr["der(engine_work)"]]):
        fmu = FMU2Model(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="EngineShaft", instanceName="e")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vr["w_start"]], [20.0])
        readings.append(fmu.getReal(reads)[-1])
        live = fmu.getInteger([vr["live_event_indicators"]])[0]
        fmu.freeInstance()
        assert live == 0                        # a linear characteristic: no point to cross
    assert readings[0] == readings[1] != 0.0
