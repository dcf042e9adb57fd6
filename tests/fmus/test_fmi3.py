"""The FMI 3.0 editions of our FMUs (build/fmus3, built by build/fmi3.py behind
build/shim/lever_fmi3_shim.c): fmpy validates them with no finding; in fmpy's Co-Simulation
and Model Exchange simulations they give the FMI 2.0 editions' outputs; their directional
and adjoint derivatives agree with central differences, their output derivatives with the
motion, their dependency queries with the ModelStructure; a serialized state continues in a
fresh instance bit for bit; a Co-Simulation instance reads the event-indicator variables the
Model Exchange instance gives at the same state; refused calls return fmi3Error with a message
in FMI 3 terms and leave the instance usable.
"""
from __future__ import annotations

import ctypes
import math
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu
from lever.physics.me_base import SPEED_BAND

from harness.compliance import check_fmu

NAMES = ("LeverCoupling", "EngineShaft", "LoadShaft", "MisalignmentSource", "FreewheelRectifier")
FMI3_ERROR = 3


@pytest.fixture(scope="module")
def fmu3_dir(fmu_dir) -> Path:
    """The FMI 3.0 editions, built with the FMI 2.0 ones (build/fmus.py)."""
    here = Path(fmu_dir).resolve()
    out = here.parent / "fmus3" if here.name == "fmus" else here / "fmi3"
    for name in NAMES:
        assert (out / f"{name}.fmu").exists(), name
    return out


@pytest.fixture(scope="module")
def unpacked(fmu3_dir, tmp_path_factory):
    out = {}
    for name in NAMES:
        path = str(fmu3_dir / f"{name}.fmu")
        out[name] = (fmpy.read_model_description(path), fmpy.extract(path, unzipdir=str(tmp_path_factory.mktemp(name))))
    return out


class Log(list):
    """The messages an instance logs: (status, message)."""

    def callback(self, env, status, category, message):
        self.append((status, message.decode()))


def slave(unpacked, name, log=None, **instantiate):
    md, unzipdir = unpacked[name]
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=name, instanceName=name)
    fmu.instantiate(logMessage=(Log() if log is None else log).callback, **instantiate)
    return fmu, md, {v.name: v for v in md.modelVariables}


def model(unpacked, name, log=None):
    md, unzipdir = unpacked[name]
    fmu = FMU3Model(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=name, instanceName=name)
    fmu.instantiate(logMessage=(Log() if log is None else log).callback)
    return fmu, md, {v.name: v for v in md.modelVariables}


def inputs_of(md):
    return [v for v in md.modelVariables if v.causality == "input"]


def input_values(md) -> dict[int, float]:
    """A point off the start values for every input (zero is where laws have kinks), inside
    its range."""
    values = {}
    for k, v in enumerate(inputs_of(md)):
        if "rate" in v.name or "accel" in v.name:
            continue          # the hold's slopes stay 0: the partials are of the held input
        low = float(v.min) if v.min is not None else -math.inf
        high = float(v.max) if v.max is not None else math.inf
        values[v.valueReference] = min(max(float(v.start or 0.0) + 0.05 * (k + 1), low), high)
    return values


def array_of(getter, n):
    """An ME array getter's values (fmpy's fill a ctypes array)."""
    values = (ctypes.c_double * n)()
    getter(values, n)
    return np.array(values)


def run_me_to_continuous_time(fmu, md):
    fmu.enterInitializationMode(startTime=0.0)
    for vr, value in input_values(md).items():
        fmu.setFloat64([vr], [value])
    fmu.exitInitializationMode()
    while fmu.updateDiscreteStates()[0]:
        pass
    fmu.enterContinuousTimeMode()


# -- validation and the same outputs as FMI 2 -------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_every_fmi3_edition_passes_fmpys_validation_and_lever_compliance(fmu3_dir, name):
    path = fmu3_dir / f"{name}.fmu"
    assert validate_fmu(str(path)) == []
    assert check_fmu(path) == []
    md = fmpy.read_model_description(str(path))
    assert md.fmiVersion == "3.0" and md.coSimulation and md.modelExchange
    assert md.coSimulation.maxOutputDerivativeOrder == 1


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("name", NAMES)
def test_fmi3_edition_gives_the_fmi2_editions_outputs(fmu_dir, fmu3_dir, name, kind):
    common = dict(fmi_type=kind, stop_time=0.3, output_interval=1e-3, step_size=1e-3)
    r3 = fmpy.simulate_fmu(str(fmu3_dir / f"{name}.fmu"), **common)
    r2 = fmpy.simulate_fmu(str(Path(fmu_dir) / f"{name}.fmu"), **common)
    assert r3.dtype.names == r2.dtype.names and len(r3) == len(r2)
    for column in r2.dtype.names:
        scale = max(1.0, float(np.max(np.abs(r2[column]))))
        # the same model and the same master: equal to rounding (in practice bit for bit)
        assert np.max(np.abs(r3[column] - r2[column])) <= 1e-12 * scale, column


# -- derivatives ------------------------------------------------------------------------------------

def _jacobian_by_differences(fmu, md, unknowns, knowns, states):
    """Central differences of the unknowns (state derivatives, outputs) over the knowns
    (states, inputs) of a Model Exchange instance in Continuous-Time Mode."""
    derivative_vrs = [d.variable.valueReference for d in md.derivatives]
    state_vrs = [d.variable.derivative.valueReference for d in md.derivatives]

    def evaluate():
        out = fmu.getFloat64([vr for vr in unknowns if vr not in derivative_vrs])
        dx = array_of(fmu.getContinuousStateDerivatives, len(states))
        values, k = [], 0
        for vr in unknowns:
            if vr in derivative_vrs:
                values.append(dx[derivative_vrs.index(vr)])
            else:
                values.append(out[k])
                k += 1
        return np.array(values, dtype=float)

    columns = []
    for vr in knowns:
        if vr in state_vrs:
            j = state_vrs.index(vr)
            h = 1e-6 * max(1.0, abs(states[j]))
            sides = []
            for sign in (1, -1):
                x = states.copy()
                x[j] += sign * h
                fmu.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))
                sides.append(evaluate())
            fmu.setContinuousStates((ctypes.c_double * len(states))(*states), len(states))
        else:
            value = fmu.getFloat64([vr])[0]
            h = 1e-6 * max(1.0, abs(value))
            sides = []
            for sign in (1, -1):
                fmu.setFloat64([vr], [value + sign * h])
                sides.append(evaluate())
            fmu.setFloat64([vr], [value])
        columns.append((sides[0] - sides[1]) / (2 * h))
    return np.array(columns).T


@pytest.mark.parametrize("name", NAMES)
def test_directional_and_adjoint_derivatives_are_central_differences(unpacked, name):
    fmu, md, _ = model(unpacked, name)
    try:
        run_me_to_continuous_time(fmu, md)
        nx = len(md.derivatives)
        # The start sits on event surfaces (a freewheel's gap is 0): move the states off
        # them and let an event update settle the modes, so that differences see one law.
        if nx:
            moved = array_of(fmu.getContinuousStates, nx) + 0.01 * np.arange(1, nx + 1)
            fmu.setContinuousStates((ctypes.c_double * nx)(*moved), nx)
            fmu.enterEventMode()
            while fmu.updateDiscreteStates()[0]:
                pass
            fmu.enterContinuousTimeMode()
        nz = md.numberOfEventIndicators
        assert nz == 0 or np.min(np.abs(array_of(fmu.getEventIndicators, nz))) > 1e-3
        states = array_of(fmu.getContinuousStates, nx)
        unknowns = [d.variable.valueReference for d in md.derivatives]
        unknowns += [o.variable.valueReference for o in md.outputs if o.variable.valueReference not in unknowns]
        knowns = [d.variable.derivative.valueReference for d in md.derivatives]
        knowns += [v.valueReference for v in inputs_of(md) if v.valueReference in input_values(md)]
        if not knowns:      # nothing to differentiate by: the derivative along no seed is 0
            assert fmu.getDirectionalDerivative(unknowns, [], []) == [0.0] * len(unknowns)
            return
        expected = _jacobian_by_differences(fmu, md, unknowns, knowns, states)
        rows = np.maximum(np.max(np.abs(expected), axis=1, keepdims=True), 1e-300)
        for j, vr in enumerate(knowns):
            column = np.array(fmu.getDirectionalDerivative(unknowns, [vr], [1.0]))
            assert np.all(np.abs(column - expected[:, j]) <= 1e-6 * rows[:, 0]), (vr, column, expected[:, j])
        seed = np.linspace(0.3, 1.7, len(unknowns))
        adjoint = np.array(fmu.getAdjointDerivative(unknowns, knowns, list(seed), nSensitivity=len(knowns)))
        want = expected.T @ seed
        scale = np.abs(expected.T) @ np.abs(seed)
        assert np.all(np.abs(adjoint - want) <= 1e-6 * np.maximum(scale, 1e-300)), (adjoint, want)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def _init_slave(fmu, md, start=0.0):
    fmu.enterInitializationMode(startTime=start)
    for vr, value in input_values(md).items():
        fmu.setFloat64([vr], [value])
    fmu.exitInitializationMode()


@pytest.mark.parametrize("name", NAMES)
def test_output_derivatives_are_the_slope_of_the_motion(unpacked, name):
    """dy/dt at the communication point against the one-sided second-order difference of
    two short steps from a saved state (inputs held)."""
    fmu, md, _ = slave(unpacked, name)
    try:
        _init_slave(fmu, md)
        t, h = 0.0, 1e-3
        for _ in range(20):
            fmu.doStep(t, h)
            t += h
        outputs = [o.variable.valueReference for o in md.outputs]
        rates = np.array(fmu.getOutputDerivatives(outputs, [1] * len(outputs)))
        state = fmu.getFMUState()
        y0 = np.array(fmu.getFloat64(outputs))
        d = 2e-5
        fmu.doStep(t, d)
        y1 = np.array(fmu.getFloat64(outputs))
        fmu.doStep(t + d, d)
        y2 = np.array(fmu.getFloat64(outputs))
        fmu.setFMUState(state)
        fmu.freeFMUState(state)
        slope = (4 * y1 - y2 - 3 * y0) / (2 * d)
        scale = np.maximum(np.abs(slope), np.abs(y0) / t)
        assert np.all(np.abs(rates - slope) <= 1e-3 * scale + 1e-7 * np.maximum(1.0, np.abs(y0))), \
            list(zip(outputs, rates, slope))
        with pytest.raises(FMICallException):
            fmu.getOutputDerivatives(outputs[:1], [2])
        assert fmu.getOutputDerivatives(outputs, [1] * len(outputs)) == list(rates)
    finally:
        fmu.terminate()
        fmu.freeInstance()


# -- dependencies -----------------------------------------------------------------------------------

def _dependencies(fmu, vr):
    n = ctypes.c_size_t()
    fmu.fmi3GetNumberOfVariableDependencies(fmu.component, vr, ctypes.byref(n))
    count = n.value
    arrays = [(ctypes.c_size_t * count)(), (ctypes.c_uint * count)(), (ctypes.c_size_t * count)(),
              (ctypes.c_int * count)()]
    fmu.fmi3GetVariableDependencies(fmu.component, vr, *arrays, count)
    assert list(arrays[0]) == [0] * count and list(arrays[2]) == [0] * count
    assert list(arrays[3]) == [5] * count            # fmi3Dependent
    return sorted(arrays[1])


@pytest.mark.parametrize("name", NAMES)
def test_dependency_queries_answer_the_model_structure(unpacked, name):
    fmu, md, _ = slave(unpacked, name)
    try:
        fmu.enterInitializationMode(startTime=0.0)
        for unknown in md.initialUnknowns:
            declared = sorted(v.valueReference for v in (unknown.dependencies or []))
            assert _dependencies(fmu, unknown.variable.valueReference) == declared, unknown.variable.name
        fmu.exitInitializationMode()
        for unknown in list(md.outputs) + list(md.derivatives):
            declared = sorted(v.valueReference for v in (unknown.dependencies or []))
            assert _dependencies(fmu, unknown.variable.valueReference) == declared, unknown.variable.name
        parameter = next(v for v in md.modelVariables if v.causality == "parameter")
        n = ctypes.c_size_t()
        with pytest.raises(FMICallException):
            fmu.fmi3GetNumberOfVariableDependencies(fmu.component, parameter.valueReference, ctypes.byref(n))
    finally:
        fmu.terminate()
        fmu.freeInstance()


# -- states -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_serialized_state_continues_in_a_fresh_instance_bit_for_bit(unpacked, name):
    fmu, md, _ = slave(unpacked, name)
    fresh, _, _ = slave(unpacked, name)
    outputs = [o.variable.valueReference for o in md.outputs]
    try:
        _init_slave(fmu, md)
        t, h = 0.0, 1e-3
        for _ in range(37):
            fmu.doStep(t, h)
            t += h
        state = fmu.getFMUState()
        blob = fmu.serializeFMUState(state)
        fmu.freeFMUState(state)
        # the model's part names the instantiation token (a state of another build is refused)
        assert f'"guid": "{md.guid}"'.encode() in blob
        restored = fresh.deserializeFMUState(blob)
        fresh.setFMUState(restored)
        assert fresh.serializeFMUState(restored) == blob
        fresh.freeFMUState(restored)
        for _ in range(25):
            a, b = fmu.doStep(t, h), fresh.doStep(t, h)
            assert a == b == (False, False, False, t + h)
            t += h
            assert fmu.getFloat64(outputs) == fresh.getFloat64(outputs)
        assert [v.hex() for v in fmu.getFloat64(outputs)] == [v.hex() for v in fresh.getFloat64(outputs)]
        broken = bytearray(blob)
        broken[12] = 32                                   # a header that contradicts the state
        with pytest.raises(FMICallException):
            fresh.deserializeFMUState(bytes(broken))
        fresh.doStep(t, h)                                # still usable
    finally:
        for f in (fmu, fresh):
            f.terminate()
            f.freeInstance()


# -- event indicators in Co-Simulation --------------------------------------------------------------

#: parameters and inputs under which each FMU's indicators change sign within 0.3 s: the
#: engine's tabulated characteristic crossed, the load stopping and sticking; the freewheel's
#: contacts and clutches at their defaults
INDICATOR_CASES = {
    "EngineShaft": ({"characteristic": "0:600; 40:620; 80:0"}, {"tau": -100.0}),
    "LoadShaft": ({"friction_torque": 3000.0, "breakaway_torque": 4000.0}, {"tau": 0.5}),
    "FreewheelRectifier": ({}, {}),
}
#: outputs that name an FMU's discrete modes (the shafts' follow from their states)
MODE_OUTPUTS = {"FreewheelRectifier": ("disc_slip", "flywheel_stuck")}


def _with_parameters(fmu, variables, parameters, inputs):
    for name, value in parameters.items():
        setter = fmu.setString if isinstance(value, str) else fmu.setFloat64
        setter([variables[name].valueReference], [value])
    fmu.enterInitializationMode(startTime=0.0)
    for name, value in inputs.items():
        fmu.setFloat64([variables[name].valueReference], [value])


@pytest.mark.parametrize("name", sorted(INDICATOR_CASES))
def test_a_co_simulation_instance_reads_the_event_indicators_of_model_exchange_at_its_state(unpacked, name):
    """FMI 3.0 declares the event indicators as local variables, which fmi3GetFloat64 of a
    Co-Simulation instance returns like any other: the physics' indicators at its state,
    inputs and modes.  The Model Exchange instance, set to the same time and states (with an
    event iteration where an indicator changes sign, as a Model Exchange host does), gives
    the same values bit for bit wherever its modes are the co-simulation's."""
    parameters, inputs = INDICATOR_CASES[name]
    log = Log()
    cs, md, variables = slave(unpacked, name, log)
    me, _, _ = model(unpacked, name, log)
    indicators = [v.valueReference for v in md.modelVariables if v.name.startswith("event_indicator_")]
    states = [u.variable.derivative.valueReference for u in md.derivatives]
    modes = [variables[n].valueReference for n in MODE_OUTPUTS.get(name, ())]
    nx, nz = len(states), len(indicators)
    assert nz == md.numberOfEventIndicators > 0
    try:
        _refused(lambda: cs.getFloat64(indicators), log, "fmi3GetFloat64", "event indicator", "Instantiated")
        for fmu in (cs, me):
            _with_parameters(fmu, variables, parameters, inputs)
        assert cs.getFloat64(indicators) == me.getFloat64(indicators)       # Initialization Mode
        cs.exitInitializationMode()
        me.exitInitializationMode()
        assert cs.getFloat64(indicators) == me.getFloat64(indicators)       # Step Mode / Event Mode
        while me.updateDiscreteStates()[0]:
            pass
        me.enterContinuousTimeMode()
        before = array_of(me.getEventIndicators, nz)
        t, h, compared, events, events_compared = 0.0, 1e-3, 0, 0, 0
        for _ in range(300):
            cs.doStep(t, h)
            t += h
            x = cs.getFloat64(states)
            me.setTime(t)
            me.setContinuousStates((ctypes.c_double * nx)(*x), nx)
            z = array_of(me.getEventIndicators, nz)
            crossed = any((a > 0) != (b > 0) for a, b in zip(before, z))
            # the states set from outside jump: an event iteration at every point (the
            # indicators are banded, me_base.banded: a mode the co-simulation ended, a slip
            # at equal speeds, may leave no sign change behind); a mode switched there is
            # reported as changed states
            me.enterEventMode()
            switched = False
            while True:
                info = me.updateDiscreteStates()
                switched = switched or info[3]
                if not info[0]:
                    break
            me.enterContinuousTimeMode()
            events += crossed or switched
            z = array_of(me.getEventIndicators, nz)
            before = z
            read = cs.getFloat64(indicators)
            if cs.getFloat64(modes) == me.getFloat64(modes):
                assert read == list(z), (t, read, list(z))
                assert me.getFloat64(indicators) == read
                compared += 1
                events_compared = events
        # the co-simulation's modes switch between communication points at times, which the
        # Model Exchange instance, stepped at those points only, does not see: not compared
        # (an event compared after: the modes switched and the values still agree)
        assert compared >= 250 and events_compared >= 1, (compared, events_compared)
        # at the current inputs: a new input value reaches the indicators before the next step
        if inputs:
            tau = variables["tau"].valueReference
            cs.setFloat64([tau], [-inputs["tau"]])
            me.setFloat64([tau], [-inputs["tau"]])
            assert cs.getFloat64(indicators) == me.getFloat64(indicators) == list(array_of(me.getEventIndicators, nz))
        cs.terminate()
        me.terminate()
        assert cs.getFloat64(indicators) == me.getFloat64(indicators)       # Terminated
        assert not [m for s, m in log if s >= FMI3_ERROR and "Instantiated" not in m], log
    finally:
        cs.freeInstance()
        me.freeInstance()


@pytest.mark.parametrize("start", [1e3, 1e6])
def test_output_derivatives_are_right_at_large_times(unpacked, start):
    """The explicit time part of dy/dt (a load's tones up to 450 rad/s) takes a step that
    does not grow with |t|: at t = 1e6 s a step of 1e-6 |t| gave d load_torque / dt 995.6
    against 298.2.  Against a central difference of fmi3DoStep outputs over
    1e-5 s and 2e-5 s from a saved state (second order)."""
    fmu, md, variables = slave(unpacked, "LoadShaft")
    try:
        fmu.enterInitializationMode(startTime=start)
        fmu.setString([variables["load_kind"].valueReference], ["random"])
        for name, value in (("random_amplitude", 40.0), ("order_share", 0.5)):
            fmu.setFloat64([variables[name].valueReference], [value])
        fmu.exitInitializationMode()
        t, h = start, 1e-3
        for _ in range(5):
            fmu.doStep(t, h)
            t += h
        outputs = [variables[n].valueReference for n in ("load_torque", "a", "w")]
        rates = np.array(fmu.getOutputDerivatives(outputs, [1] * len(outputs)))
        state = fmu.getFMUState()
        y0 = np.array(fmu.getFloat64(outputs))
        d = 1e-5
        fmu.doStep(t, d)
        y1 = np.array(fmu.getFloat64(outputs))
        fmu.doStep(t + d, d)
        y2 = np.array(fmu.getFloat64(outputs))
        fmu.setFMUState(state)
        fmu.freeFMUState(state)
        slope = (4 * y1 - y2 - 3 * y0) / (2 * d)        # second order, one-sided
        assert np.all(np.abs(rates - slope) <= 2e-3 * np.abs(slope) + 1e-6), list(zip(rates, slope))
    finally:
        fmu.terminate()
        fmu.freeInstance()


@pytest.mark.parametrize("make", [slave, model])
def test_an_indicator_read_in_initialization_mode_follows_the_parameters_set_there(unpacked, make):
    """A parameter set in Initialization Mode makes the model the indicators are read from
    (read there, they are computed), not the one of the values before."""
    log = Log()
    fmu, md, variables = make(unpacked, "EngineShaft", log)
    indicator = [variables["event_indicator_1"].valueReference]
    try:
        fmu.enterInitializationMode(startTime=0.0)
        assert fmu.getFloat64(indicator) == [1.0]          # a linear characteristic: no event
        # points at 0, 38.5 and 80 rad/s around w_start = 39 rad/s: 0.5 rad/s to the nearest,
        # above it, so banded by + SPEED_BAND (me_base.banded)
        fmu.setString([variables["characteristic"].valueReference], ["0:600; 38.5:620; 80:0"])
        assert fmu.getFloat64(indicator) == [0.5 + SPEED_BAND]
        fmu.exitInitializationMode()
        assert fmu.getFloat64(indicator) == [0.5 + SPEED_BAND]
        assert not [m for s, m in log if s >= FMI3_ERROR], log
    finally:
        fmu.terminate()
        fmu.freeInstance()


# -- refusals ---------------------------------------------------------------------------------------

def _refused(call, log, *words):
    before = len(log)
    with pytest.raises(FMICallException) as error:
        call()
    assert error.value.status == FMI3_ERROR
    messages = " ".join(m for s, m in log[before:] if s == FMI3_ERROR)
    for word in words:
        assert word in messages, (word, messages)
    assert "fmi2" not in messages, messages


@pytest.mark.parametrize("name", NAMES)
def test_refused_calls_are_fmi3_errors_and_the_instance_stays_usable(unpacked, name):
    log = Log()
    fmu, md, variables = slave(unpacked, name, log)
    outputs = [o.variable.valueReference for o in md.outputs]
    try:
        _refused(lambda: fmu.doStep(0.0, 1e-3), log, "fmi3DoStep", "Instantiated")
        _refused(lambda: fmu.fmi3SetTime(fmu.component, 0.0), log, "fmi3SetTime", "Model Exchange")
        _refused(lambda: fmu.enterConfigurationMode(), log, "structural")
        _refused(lambda: fmu.getFloat64([999_999]), log, "fmi3GetFloat64", "999999")
        _refused(lambda: fmu.getFloat32([0]), log, "fmi3GetFloat32", "Float32")
        _refused(lambda: fmu.setFloat64([variables["time"].valueReference], [1.0]), log, "time")
        _init_slave(fmu, md)
        _refused(lambda: fmu.exitInitializationMode(), log, "fmi3ExitInitializationMode", "Step Mode")
        first = inputs_of(md)[0] if inputs_of(md) else None
        if first is not None:
            before = fmu.getFloat64([first.valueReference])
            _refused(lambda: fmu.setFloat64([first.valueReference], [math.nan]), log, first.name)
            assert fmu.getFloat64([first.valueReference]) == before
        _refused(lambda: fmu.doStep(0.0, math.nan), log, "fmi3DoStep")
        _refused(lambda: fmu.doStep(0.5, 1e-3), log, "fmi3DoStep")
        assert fmu.doStep(0.0, 1e-3) == (False, False, False, 1e-3)
        assert fmu.getFloat64([variables["time"].valueReference]) == [1e-3]
        assert all(math.isfinite(v) for v in fmu.getFloat64(outputs))
        fmu.terminate()
        _refused(lambda: fmu.doStep(1e-3, 1e-3), log, "fmi3DoStep", "Terminated")
        fmu.reset()
        _init_slave(fmu, md)
        assert fmu.doStep(0.0, 1e-3)[3] == 1e-3
    finally:
        fmu.terminate()
        fmu.freeInstance()


@pytest.mark.parametrize("name", NAMES)
def test_model_exchange_refusals_and_event_mode(unpacked, name):
    log = Log()
    fmu, md, variables = model(unpacked, name, log)
    nx = len(md.derivatives)
    try:
        assert fmu.getNumberOfContinuousStates() == nx
        assert fmu.getNumberOfEventIndicators() == md.numberOfEventIndicators
        _refused(lambda: fmu.getFMUState(), log, "fmi3GetFMUState", "Co-Simulation")
        _refused(lambda: fmu.enterContinuousTimeMode(), log, "fmi3EnterContinuousTimeMode", "Instantiated")
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        _refused(lambda: fmu.setContinuousStates((ctypes.c_double * nx)(), nx), log, "fmi3SetContinuousStates", "Event Mode")
        while fmu.updateDiscreteStates()[0]:
            pass
        fmu.enterContinuousTimeMode()
        if nx:
            x = array_of(fmu.getContinuousStates, nx)
            bad = x.copy()
            bad[0] = math.nan
            _refused(lambda: fmu.setContinuousStates((ctypes.c_double * nx)(*bad), nx), log, "fmi3SetContinuousStates")
            assert list(array_of(fmu.getContinuousStates, nx)) == list(x)
        _refused(lambda: fmu.setTime(math.inf), log, "fmi3SetTime")
        fmu.setTime(1e-3)
        assert fmu.getFloat64([variables["time"].valueReference]) == [1e-3]
        nz = md.numberOfEventIndicators
        if nz:
            z = list(array_of(fmu.getEventIndicators, nz))
            vrs = [v.valueReference for v in md.modelVariables if v.name.startswith("event_indicator_")]
            assert fmu.getFloat64(vrs) == z
        assert fmu.completedIntegratorStep() == (False, False)
        fmu.enterEventMode()
        assert fmu.updateDiscreteStates()[1] is False
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_lever_compliance_on_the_fmi3_folder_finds_nothing(lever, fmu3_dir):
    done = lever("compliance", fmu3_dir)
    assert done.exit_code == 0, done.output
    assert done.output.splitlines() == [f"{fmu3_dir / name}.fmu: 0 findings" for name in sorted(NAMES)]


def test_lever_compliance_checks_the_fmi3_variables(fmu3_dir):
    """Our own checks read FMI 3.0 descriptions too: a variable without description or
    unit is found."""
    import xml.etree.ElementTree as ET
    import zipfile

    from harness.compliance import variable_findings
    with zipfile.ZipFile(fmu3_dir / "LoadShaft.fmu") as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    assert variable_findings(root) == []
    tau = root.find("ModelVariables/Float64[@name='tau']")
    del tau.attrib["description"]
    del tau.attrib["unit"]
    del tau.attrib["declaredType"]
    findings = variable_findings(root)
    assert any("'tau': no description" in f for f in findings)
    assert any("'tau': a Real without a unit" in f for f in findings)
