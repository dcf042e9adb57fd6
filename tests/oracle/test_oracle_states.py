"""Saved states taken wherever a standard host may take them, restored into a fresh
instance and continued: the continuation equals the unbroken run bit for bit.

FMI 2.0 lets a host call ``fmi2GetFMUstate`` in any state of the co-simulation state
machine (section 4.2.4; there is no event mode in co-simulation): after setting
parameters, in initialisation mode, right after ``fmi2ExitInitializationMode``, after an
``fmi2SetReal`` of the next step's inputs, and right after ``fmi2DoStep`` with no
``fmi2GetReal`` in between (libcosim and ecos save there).  Our FMUs compute their
outputs lazily, so an output variable is stale until it is read: a state that took an
output where it needed the state behind it is right only when a read came first.  Every
save point below is restored into a fresh instance (``fmi2Instantiate``,
``fmi2DeSerializeFMUstate``, ``fmi2SetFMUstate``), which then runs the rest of the call
sequence; its every ``fmi2GetReal`` must equal the unbroken run's.

The expected values are the unbroken run's own: no number here comes from a model.  The
built FMUs are driven through fmpy's ``FMU2Slave`` (the native entry and its state
machine included); the shaft slaves are also driven in this process, where the mutation
run (tests/mutation/run_mutants.py) can reach their code.
"""
from __future__ import annotations

import math
from pathlib import Path

import fmpy
import pytest

pytestmark = pytest.mark.oracle

H = 1e-3          # the communication step [s]
STEPS = 8         # steps of every run
T0 = 0.25         # start time (not 0: a state must carry its own time)


def _shaft_inputs(mean, amplitude):
    def inputs(k):
        return {"tau": mean + amplitude * math.sin(0.7 * k + 0.3), "tau_rate": 40.0 * math.cos(0.7 * k),
                "tau_accel": -900.0 * math.sin(0.7 * k)}
    return inputs


def _coupling_inputs(k):
    return {"phi1": 0.041 * k + 0.02, "w1": 40.0 + 0.3 * math.sin(k), "phi2": 0.039 * k,
            "w2": 38.5 + 0.2 * math.cos(k)}


def _swinging(k):   # beyond the 23 N.m the resistive load holds at rest and back: slips and sticks
    return {"tau": 30.0 * math.sin(0.9 * k), "tau_rate": 27.0 * math.cos(0.9 * k), "tau_accel": 0.0}


#: (case id, FMU, parameters, inputs at step k): every FMU and every kind of parameter
#: that gives a model a state of its own or a different law.
CASES = [
    ("engine line", "EngineShaft", {}, _shaft_inputs(-110.0, 30.0)),
    ("engine line lagged", "EngineShaft", {"torque_lag": 0.004, "torque_start": 150.0},
     _shaft_inputs(-110.0, 30.0)),
    ("engine table", "EngineShaft", {"characteristic": "kavz685", "w_start": 38.2}, _shaft_inputs(-150.0, 40.0)),
    ("engine table lagged", "EngineShaft", {"characteristic": "kavz685", "w_start": 38.2, "torque_lag": 0.003,
                                            "torque_start": 90.0}, _shaft_inputs(-150.0, 40.0)),
    ("engine points", "EngineShaft", {"characteristic": "0:500; 30:450; 40:0", "w_start": 39.0, "inertia": 0.05},
     _shaft_inputs(-100.0, 20.0)),
    ("load constant", "LoadShaft", {"load_kind": "constant", "mean_torque": 50.0}, _shaft_inputs(60.0, 20.0)),
    ("load random", "LoadShaft", {"seed": 7}, _shaft_inputs(110.0, 20.0)),
    ("load spectrum", "LoadShaft", {"order_share": 0.4, "order": 2, "order_phase": 0.3, "narrowband_share": 0.3},
     _shaft_inputs(110.0, 20.0)),
    ("load fourier", "LoadShaft", {"load_kind": "fourier", "fourier": "100; 5:3; 2:-1"}, _shaft_inputs(100.0, 20.0)),
    ("load table", "LoadShaft", {"load_kind": "table", "table": "0.25:100; 0.252:130; 0.256:90"},
     _shaft_inputs(100.0, 20.0)),
    ("load viscous", "LoadShaft", {"load_kind": "constant", "mean_torque": 80.0, "viscous_damping": 0.7},
     _shaft_inputs(100.0, 20.0)),
    ("load friction", "LoadShaft", {"load_kind": "constant", "mean_torque": 20.0, "load_direction": "resistive",
                                    "friction_torque": 2.0, "breakaway_torque": 3.0, "viscous_damping": 0.1,
                                    "w_start": 0.05, "inertia": 0.05}, _swinging),
    ("coupling linear", "LeverCoupling", {"stiffness": 900.0, "damping": 4.0}, _coupling_inputs),
    ("coupling table", "LeverCoupling", {"elastic_table": "0.05:10; 0.1:16; 0.2:16.5; 0.3:26.5; 0.45:50",
                                         "damping": 0.5}, _coupling_inputs),
    ("coupling scaled", "LeverCoupling", {"transfer_mode": "scaled", "misalignment": 0.35}, _coupling_inputs),
    ("coupling misalignment moving", "LeverCoupling", {"misalignment": 0.2},
     lambda k: _coupling_inputs(k) | {"misalignment": 0.2 + 0.01 * k}),
    ("misalignment source", "MisalignmentSource", {"table": "0.25:0.2; 0.254:0.3; 0.26:0.25"}, lambda k: {}),
    ("freewheel", "FreewheelRectifier", {}, lambda k: {"tau": 0.5 * math.sin(0.9 * k), "tau_rate": 0.0}),
    ("freewheel loaded", "FreewheelRectifier", {"resistance_torque": 0.2, "input_speed": 30.0},
     lambda k: {"tau": -0.3 + 0.2 * math.sin(0.9 * k), "tau_rate": 0.0}),
]


def _sequence(parameters: dict, inputs) -> list[tuple]:
    """The call sequence of a standard host: parameters while instantiated, the
    experiment, initialisation (with the first inputs), then per step set - doStep -
    get."""
    ops = [("set", parameters), ("setup",), ("enter",), ("set", inputs(0)), ("exit",)]
    for k in range(STEPS):
        ops += [("set", inputs(k)), ("step", T0 + k * H), ("get",)]
    return ops


#: Where a state is saved: after the op of this index (a name for the test id).
def _save_points(ops) -> dict[str, int]:
    points = {"instantiated, parameters set": 1, "after fmi2SetupExperiment": 2,
              "initialisation mode": 3, "initialisation mode, inputs set": 4,
              "after fmi2ExitInitializationMode, nothing read": 5}
    for k in (0, 1, 4):
        first = 5 + 3 * k
        points[f"step {k}: inputs set"] = first + 1
        points[f"step {k}: after fmi2DoStep, nothing read"] = first + 2
        points[f"step {k}: outputs read"] = first + 3
    return points


class _Fmpy:
    """A built FMU through fmpy's FMU2Slave (errors raise fmpy's FMICallException)."""

    def __init__(self, fmu_dir: Path, fmu: str):
        from fmpy.fmi2 import FMU2Slave
        from harness.engine.component import unzipped

        path = Path(fmu_dir) / f"{fmu}.fmu"
        md = fmpy.read_model_description(str(path))
        self.vars = {v.name: v for v in md.modelVariables}
        self.outputs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped(path),
                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName=fmu)
        self.slave.instantiate(loggingOn=False)

    def set(self, values: dict):
        for name, value in values.items():
            v = self.vars[name]
            {"Real": lambda: self.slave.setReal([v.valueReference], [float(value)]),
             "Integer": lambda: self.slave.setInteger([v.valueReference], [int(value)]),
             "String": lambda: self.slave.setString([v.valueReference], [str(value)])}[v.type]()

    def setup(self):
        self.slave.setupExperiment(startTime=T0)

    def enter(self):
        self.slave.enterInitializationMode()

    def exit(self):
        self.slave.exitInitializationMode()

    def step(self, t):
        self.slave.doStep(t, H)

    def get(self):
        return self.slave.getReal(self.outputs)

    def save(self) -> bytes:
        state = self.slave.getFMUstate()
        data = self.slave.serializeFMUstate(state)
        self.slave.freeFMUstate(state)
        return bytes(data)

    def restore(self, data: bytes):
        state = self.slave.deSerializeFMUstate(data)
        self.slave.setFMUstate(state)
        self.slave.freeFMUstate(state)

    def free(self):
        self.slave.freeInstance()


class _InProcess:
    """The slave class itself, in this process (no native entry): the same calls as
    pythonfmu's library makes; a logged error fails the test."""

    def __init__(self, fmu_dir: Path, fmu: str):
        from lever.fmus import shafts

        self.cls = getattr(shafts, fmu)
        self.slave = self.cls(instance_name=fmu, resources=None)
        self.vr = {v.name: vr for vr, v in self.slave.vars.items()}
        self.outputs = [self.vr[o.name] for o in self.cls.OUTPUTS]

    def _check(self):
        assert not self.slave.log_queue, [str(m) for m in self.slave.log_queue]

    def set(self, values: dict):
        for name, value in values.items():
            kind = type(self.slave.vars[self.vr[name]]).__name__
            getattr(self.slave, {"Real": "set_real", "Integer": "set_integer", "String": "set_string"}[kind])(
                [self.vr[name]], [value])
        self._check()

    def setup(self):
        self.slave.setup_experiment(T0)

    def enter(self):
        self.slave.enter_initialization_mode()
        self._check()

    def exit(self):
        self.slave.exit_initialization_mode()
        self._check()

    def step(self, t):
        assert self.slave.do_step(t, H)
        self._check()

    def get(self):
        values = self.slave.get_real(self.outputs)
        self._check()
        return values

    def save(self) -> bytes:
        return self.cls._fmu_state_to_bytes(self.slave._get_fmu_state())

    def restore(self, data: bytes):
        self.slave._set_fmu_state(self.cls._fmu_state_from_bytes(data))
        self._check()

    def free(self):
        pass


def _play(instance, ops, saves: dict[int, bytes] | None = None) -> list:
    """Run ``ops`` on ``instance``; the outputs of every get, and (when ``saves`` is a
    dict) the serialized state after each op index in it."""
    rows = []
    for i, op in enumerate(ops):
        if op[0] == "set":
            instance.set(op[1])
        elif op[0] == "step":
            instance.step(op[1])
        elif op[0] == "get":
            rows.append(instance.get())
        else:
            getattr(instance, op[0])()
        if saves is not None and i + 1 in saves:
            saves[i + 1] = instance.save()
    return rows


def _check_every_save_point(driver, fmu_dir, fmu, parameters, inputs):
    ops = _sequence(parameters, inputs)
    points = _save_points(ops)
    unbroken = driver(fmu_dir, fmu)
    saving = driver(fmu_dir, fmu)
    try:
        expected = _play(unbroken, ops)
        saves = {index: b"" for index in points.values()}
        assert _play(saving, ops, saves) == expected, "saving a state changed the run that saved it"
    finally:
        unbroken.free()
        saving.free()
    assert len({row[0] for row in expected}) > 1 or fmu == "MisalignmentSource", "the run does not move"
    wrong = []
    for where, index in points.items():
        fresh = driver(fmu_dir, fmu)
        try:
            fresh.restore(saves[index])
            continued = _play(fresh, ops[index:])
        finally:
            fresh.free()
        gets_before = sum(1 for op in ops[:index] if op[0] == "get")
        if continued != expected[gets_before:]:
            first = next(i for i, (a, b) in enumerate(zip(continued, expected[gets_before:])) if a != b)
            wrong.append(f"saved at '{where}': get {first} after the restore gave {continued[first]}, the unbroken "
                         f"run {expected[gets_before + first]}")
    assert not wrong, (f"{fmu} {parameters}: a state restored into a fresh instance does not continue as the "
                       "unbroken run (a serialized state took an output, stale until read, for a state?):\n  "
                       + "\n  ".join(wrong))


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_a_state_saved_anywhere_continues_bit_for_bit_in_a_fresh_instance(fmu_dir, case):
    _, fmu, parameters, inputs = case
    _check_every_save_point(_Fmpy, fmu_dir, fmu, parameters, inputs)


SHAFT_CASES = [c for c in CASES if c[1] in ("EngineShaft", "LoadShaft")]


@pytest.mark.parametrize("case", SHAFT_CASES, ids=[c[0] for c in SHAFT_CASES])
def test_the_shaft_slaves_states_continue_bit_for_bit_in_this_process(case):
    """The same, on the shaft slave classes in this process: the code the mutation run
    mutates (the FMUs carry their own copy)."""
    _, fmu, parameters, inputs = case
    _check_every_save_point(_InProcess, None, fmu, parameters, inputs)
