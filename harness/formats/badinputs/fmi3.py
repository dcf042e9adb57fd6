"""The FMI 3.0 cases: the editions in build/fmus3, run with fmpy's ``FMU3Slave`` and
``FMU3Model``, every call under test through ctypes."""
from __future__ import annotations

import ctypes
import math
from pathlib import Path

from harness.formats.badinputs.common import (free_instance, judge_after_refusal, judge_log, DECLARED, Case, Outcome, c_array, declared, instance_numbers,
                                              model_description, settle, status_of)
from harness.formats.badinputs.co_simulation import SHIM_HEADER, STATE_EDITS, edited_state, state_edits
from harness.formats.badinputs.model_exchange import ME_SIZES
from harness.paths import FMUS

# -- FMI 3.0: the editions in build/fmus3 ---------------------------------------------------------------

FMI3_OK, FMI3_WARNING, FMI3_DISCARD, FMI3_ERROR, FMI3_FATAL = range(5)
#: the phases an FMI 3.0 case starts from: Co-Simulation ``step`` after one fmi3DoStep, Model
#: Exchange ``event`` after fmi3ExitInitializationMode, ``continuous`` after the event
#: iteration and fmi3EnterContinuousTimeMode; ``terminated`` after fmi3Terminate from there
CS3_PHASES = ("instantiated", "initialization", "step", "terminated")
ME3_PHASES = ("instantiated", "initialization", "event", "continuous", "terminated")
#: FMI 3.0 Model Exchange function -> the phases the FMI 3.0 state machine allows it in
ME3_ALLOWED = {
    "fmi3SetTime": ("event", "continuous"),
    "fmi3SetContinuousStates": ("continuous",),
    "fmi3GetContinuousStateDerivatives": ("event", "continuous", "terminated"),
    "fmi3GetEventIndicators": ("initialization", "event", "continuous", "terminated"),
    "fmi3GetContinuousStates": ("initialization", "event", "continuous", "terminated"),
    "fmi3GetNominalsOfContinuousStates": ("instantiated", "event", "continuous", "terminated"),
    "fmi3CompletedIntegratorStep": ("continuous",),
    "fmi3EnterEventMode": ("continuous",),
    "fmi3EnterContinuousTimeMode": ("event",),
    "fmi3UpdateDiscreteStates": ("event",),
    "fmi3ExitInitializationMode": ("initialization",),
    "fmi3EnterInitializationMode": ("instantiated",),
    "fmi3Terminate": ("event", "continuous"),
}
#: the Model Exchange functions that take an array of the states' or indicators' size
ME3_ARRAYS = {"fmi3GetContinuousStateDerivatives": "nx", "fmi3GetContinuousStates": "nx",
              "fmi3SetContinuousStates": "nx", "fmi3GetEventIndicators": "nz",
              "fmi3GetNominalsOfContinuousStates": "nx"}
#: the getters and setters of the types the FMUs have, with their ctypes element type's name
FMI3_TYPES = ("Float64", "Int32", "Boolean", "String")
#: damage done to the FMI 3.0 entry's own header of a serialized state (magic[8] version:u32
#: state:u32 discarded:u32 reserved:u32 time:f64, then the FMI 2.0 entry's state):
#: edit -> (label, fragments of the refusal's message)
STATE3_EDITS = {
    "truncated": ("truncated in the middle", ("fmi3DeserializeFMUState",)),
    "header-only": ("cut after the FMI 3 header", ("fmi3DeserializeFMUState", "not a serialized FMI 3 state")),
    "empty": ("of zero bytes", ("fmi3DeserializeFMUState", "not a serialized FMI 3 state")),
    "padded": ("with bytes appended", ("fmi3DeserializeFMUState", "padded")),
    "magic": ("with another magic", ("fmi3DeserializeFMUState", "not a serialized FMI 3 state")),
    "version": ("of an unknown format version", ("fmi3DeserializeFMUState", "format version")),
    "state": ("whose header names another FMI 3 state", ("fmi3DeserializeFMUState", "damaged")),
    "state-bits": ("whose header names two FMI 3 states", ("fmi3DeserializeFMUState", "damaged")),
    "discarded": ("whose header says the last step was discarded", ("fmi3DeserializeFMUState", "damaged")),
    "time": ("whose header's time disagrees with the model's", ("fmi3DeserializeFMUState", "damaged")),
    "time-bit": ("with one bit of the header's time flipped", ("fmi3DeserializeFMUState", "damaged")),
    "time-nan": ("with a NaN time in the header", ("fmi3DeserializeFMUState", "damaged")),
    "payload-byte": ("with a byte of the model's part made invalid UTF-8", ("fmi3SetFMUState", "does not decode")),
}
STATE3_HEADER = 32


def _fmi3(fmu, category, label, phase, interface, what, expect, *args) -> Case:
    return Case(fmu, category, f"{label} (FMI 3 {'CS' if interface == 'CoSimulation3' else 'ME'})", phase,
                ("call", "fmi3", (what, *args)), tuple(expect), interface=interface)


def cases() -> list[Case]:
    cs, me = "CoSimulation3", "ModelExchange3"
    cases = []
    for fmu in DECLARED:
        nx, nz = ME_SIZES[fmu]
        parameters, inputs = DECLARED[fmu]
        order = "FMI 3 out-of-order call"
        # Co-Simulation: its state machine
        for function, phases in (("fmi3DoStep", ("instantiated", "initialization", "terminated")),
                                 ("fmi3ExitInitializationMode", ("instantiated", "step", "terminated")),
                                 ("fmi3EnterInitializationMode", ("initialization", "step", "terminated")),
                                 ("fmi3EnterStepMode", ("instantiated", "initialization", "step")),
                                 ("fmi3UpdateDiscreteStates", ("initialization", "step")),
                                 ("fmi3Terminate", ("instantiated", "initialization", "terminated"))):
            for phase in phases:
                cases.append(_fmi3(fmu, order, f"{function} in {phase}", phase, cs, function,
                                   (function, "is not allowed in")))
        cases += [
            _fmi3(fmu, order, "fmi3EnterEventMode without eventModeUsed", "step", cs, "fmi3EnterEventMode",
                  ("fmi3EnterEventMode", "eventModeUsed")),
            _fmi3(fmu, order, "fmi3EnterConfigurationMode", "step", cs, "fmi3EnterConfigurationMode",
                  ("fmi3EnterConfigurationMode", "structural parameters")),
            _fmi3(fmu, order, "fmi3ExitConfigurationMode", "step", cs, "fmi3ExitConfigurationMode",
                  ("fmi3ExitConfigurationMode",)),
        ]
        for function in ME3_ALLOWED:
            if function in ("fmi3UpdateDiscreteStates", "fmi3ExitInitializationMode", "fmi3EnterInitializationMode",
                            "fmi3Terminate", "fmi3EnterEventMode"):
                continue          # Co-Simulation has them too (above)
            cases.append(_fmi3(fmu, order, f"{function} on a Co-Simulation instance", "step", cs, function,
                               (function, "instantiated for Co-Simulation", "Model Exchange function")))
        # Model Exchange: every function in every state the table does not allow it in
        for function, allowed in ME3_ALLOWED.items():
            for phase in ME3_PHASES:
                if phase not in allowed:
                    cases.append(_fmi3(fmu, order, f"{function} in {phase}", phase, me, function,
                                       (function, "is not allowed in")))
        for function in ("fmi3DoStep", "fmi3GetFMUState", "fmi3EnterStepMode", "fmi3GetOutputDerivatives"):
            cases.append(_fmi3(fmu, order, f"{function} on a Model Exchange instance", "continuous", me, function,
                               (function, "instantiated for Model Exchange")))
        # value counts, unknown references, types the FMU has no variable of
        sizes = "FMI 3 wrong size or reference"
        for interface, phase in ((cs, "step"), (me, "continuous")):
            for kind in FMI3_TYPES:
                for direction in ("Get", "Set"):
                    function = f"fmi3{direction}{kind}"
                    cases.append(_fmi3(fmu, sizes, f"{function} with one value more than references", phase,
                                       interface, function, (function, "values for", "value references"), "count"))
            cases += [
                _fmi3(fmu, sizes, "fmi3GetFloat64 into a NULL array", phase, interface, "fmi3GetFloat64",
                      ("fmi3GetFloat64", "NULL"), "null"),
                _fmi3(fmu, sizes, "fmi3GetFloat64 of an unknown value reference", phase, interface, "fmi3GetFloat64",
                      ("value reference", "999999"), "unknown"),
                _fmi3(fmu, sizes, "fmi3SetFloat64 of an unknown value reference", phase, interface, "fmi3SetFloat64",
                      ("value reference", "999999"), "unknown"),
                _fmi3(fmu, sizes, "fmi3SetFloat64 of the independent variable time", phase, interface,
                      "fmi3SetFloat64", ("fmi3SetFloat64", "time", "cannot be set"), "time"),
                _fmi3(fmu, sizes, "fmi3GetFloat32 of a Float64 variable", phase, interface, "fmi3GetFloat32",
                      ("fmi3GetFloat32", "Float32"), "type"),
                _fmi3(fmu, sizes, "fmi3SetInt64 of a Float64 variable", phase, interface, "fmi3SetInt64",
                      ("fmi3SetInt64", "Int64"), "type"),
                _fmi3(fmu, sizes, "fmi3GetBinary of a Float64 variable", phase, interface, "fmi3GetBinary",
                      ("fmi3GetBinary", "Binary"), "type"),
            ]
            if nz:
                cases += [
                    _fmi3(fmu, sizes, "fmi3SetFloat64 of an event indicator", phase, interface,
                          "fmi3SetFloat64", ("fmi3SetFloat64", "event indicator", "cannot be set"), "indicator"),
                    _fmi3(fmu, sizes, "fmi3GetFloat64 of an event indicator and an unknown value reference", phase,
                          interface, "fmi3GetFloat64", ("value reference", "999999"), "indicator-unknown"),
                ]
            # the first value reference past the variables the FMI 3 entry adds (time, the indicators)
            cases.append(_fmi3(fmu, sizes, "fmi3GetFloat64 of the value reference after the last event indicator"
                               if nz else "fmi3GetFloat64 of the value reference after time", phase, interface,
                               "fmi3GetFloat64", ("fmi3GetFloat64", "value reference", "no real variable"), "past"))
        # an event indicator is calculated: no value before Initialization Mode
        if nz:
            for interface in (cs, me):
                cases.append(_fmi3(fmu, order, "fmi3GetFloat64 of an event indicator in instantiated", "instantiated",
                                   interface, "fmi3GetFloat64",
                                   ("fmi3GetFloat64", "event indicator", "fmi3EnterInitializationMode", "Instantiated"),
                                   "indicator"))
        for function, size in ME3_ARRAYS.items():
            n = nx if size == "nx" else nz
            for count in ([n + 1] + ([n - 1] if n else [])):
                cases.append(_fmi3(fmu, sizes, f"{function} with {count} elements for {n}", "continuous", me,
                                   function, (function, str(count)), "size", count))
        # NaN and infinity
        bad = "FMI 3 non-finite value"
        for name in inputs:
            for value in (math.nan, math.inf, -math.inf):
                cases.append(_fmi3(fmu, bad, f"input {name} = {value}", "step", cs, "fmi3SetFloat64",
                                   (f"'{name}'", declared(fmu, name).range_text()), "value", name, value))
        for p in parameters:
            if p.kind == "real":
                cases.append(_fmi3(fmu, bad, f"parameter {p.name} = nan", "instantiated", cs, "fmi3SetFloat64",
                                   (f"'{p.name}'", p.range_text()), "value", p.name, math.nan))
        for label, point, h in (("NaN step size", None, math.nan), ("infinite step size", None, math.inf),
                                ("NaN communication point", math.nan, 1e-3)):
            cases.append(_fmi3(fmu, bad, f"fmi3DoStep with a {label}", "step", cs, "fmi3DoStep",
                               ("fmi3DoStep",), "step", point, h))
        for interface in (cs, me):
            cases.append(_fmi3(fmu, bad, "fmi3EnterInitializationMode with a NaN start time", "instantiated",
                               interface, "fmi3EnterInitializationMode", ("fmi3EnterInitializationMode", "start time"),
                               "start", math.nan))
        for value in (math.nan, math.inf):
            cases.append(_fmi3(fmu, bad, f"fmi3SetTime({value})", "continuous", me, "fmi3SetTime",
                               ("fmi3SetTime", "not finite"), "value", value))
        if nx:
            for value in (math.nan, math.inf, -math.inf):
                cases.append(_fmi3(fmu, bad, f"fmi3SetContinuousStates with a state = {value}", "continuous", me,
                                   "fmi3SetContinuousStates", ("fmi3SetContinuousStates",), "value", 0, value))
        # serialized states: the FMI 3 header damaged, and the FMI 2 entry's part inside it
        states = "FMI 3 bad state"
        for edit, (label, fragments) in STATE3_EDITS.items():
            cases.append(_fmi3(fmu, states, f"a serialized state {label}", "step", cs, "state3", fragments, edit))
        for edit in state_edits(fmu):
            label, fragments = STATE_EDITS[edit]
            # the FMI 2 entry's header is checked against the FMI 3 header first
            expect = ("fmi3DeserializeFMUState", "damaged") if edit.startswith("frame-") else ("FMUState",) + fragments
            cases.append(_fmi3(fmu, states, f"a serialized state whose model part is {label}", "step", cs,
                               "state3-inner", expect, edit))
    return cases


#: the arguments after the instance of an FMI 3.0 function taking an array and its size
_ARRAY_ARGS = (ctypes.c_void_p, ctypes.c_size_t)


class _Instance3:
    """One instance of an FMU's FMI 3.0 edition (fmpy's FMU3Slave or FMU3Model) with its own
    log; the calls under test go through ctypes with prototypes of their own, so that no
    wrapper of fmpy's checks or changes what they pass."""

    def __init__(self, fmu: str, fmu_dir: Path, interface: str):
        from fmpy.fmi3 import FMU3Model, FMU3Slave
        from harness.engine.component import unzipped as extracted
        from harness.paths import fmi3_dir

        path = fmi3_dir(fmu_dir) / f"{fmu}.fmu"
        self.md = model_description(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.cs = interface == "CoSimulation3"
        self.nx, self.nz = ME_SIZES[fmu]
        self.instance = f"corpus3-{fmu}-{next(instance_numbers)}"
        self.log: list[tuple[int, str]] = []
        #: what a call under test did wrong beyond its status and messages
        self.problems: list[str] = []
        cls = FMU3Slave if self.cs else FMU3Model
        self.fmu = cls(guid=self.md.guid, unzipDirectory=extracted(path), modelIdentifier=fmu,
                       instanceName=self.instance)

        def log_message(env, status, category, message):
            self.log.append((int(status), message.decode(errors="replace") if message else ""))

        self.fmu.instantiate(logMessage=log_message)
        self.phase, self.time = "instantiated", 0.0

    def raw(self, function: str, argtypes, *args) -> int:
        import ctypes
        prototype = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, *argtypes)
        return int(prototype((function, self.fmu.dll))(self.fmu.component, *args))

    def call(self, function: str, *args) -> int:
        return status_of(self.fmu, function, *args)

    def _event_iteration(self) -> int:
        return settle(self.fmu.updateDiscreteStates)

    def advance(self, phase: str) -> int:
        """From the current phase on to ``phase``; the worst status seen."""
        order = CS3_PHASES if self.cs else ME3_PHASES
        worst = FMI3_OK
        for step in order[order.index(self.phase) + 1: order.index(phase) + 1]:
            if step == "initialization":
                status = self.call("enterInitializationMode", None, 0.0)
            elif step == "step":
                status = max(self.call("exitInitializationMode"), self.call("doStep", 0.0, 1e-3))
                self.time = 1e-3
            elif step == "event":
                status = self.call("exitInitializationMode")
            elif step == "continuous":
                status = max(self._event_iteration(), self.call("enterContinuousTimeMode"))
            else:
                status = self.call("terminate")
            worst = max(worst, status)
            self.phase = step
        return worst

    def reals(self) -> dict | None:
        """Every Float64 (the event indicators from Initialization Mode on: before, they have
        no value)."""
        names = [n for n, v in self.variables.items() if v.type == "Float64"
                 and not (self.phase == "instantiated" and n.startswith("event_indicator_"))]
        from fmpy.fmi1 import FMICallException
        try:
            return dict(zip(names, self.fmu.getFloat64([self.variables[n].valueReference for n in names])))
        except FMICallException:
            return None

    def states(self) -> list | None:
        if self.cs or self.phase == "instantiated" or not self.nx:
            return None
        x = c_array(self.nx)
        return list(x)[: self.nx] if self.raw("fmi3GetContinuousStates", list(_ARRAY_ARGS), x, self.nx) <= FMI3_WARNING else None

    def outputs_finite(self) -> bool:
        outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output"]
        return all(math.isfinite(x) for x in self.fmu.getFloat64(outputs))

    def usable(self) -> str | None:
        """A legal round from the case's phase on (after fmi3Reset where it was terminated): a
        step, or a continuous-time round; None when it works, else why not."""
        if self.phase == "terminated":
            if self.call("reset") > FMI3_WARNING:
                return f"fmi3Reset after fmi3Terminate failed: {self.log[-1:]}"
            self.phase, self.time = "instantiated", 0.0
        if self.cs:
            if self.advance("step") > FMI3_WARNING:
                return f"going on to Step Mode failed: {self.log[-1:]}"
            if self.call("doStep", self.time, 1e-3) > FMI3_WARNING or not self.outputs_finite():
                return f"the instance did not step on: {self.log[-1:]}"
            self.time += 1e-3
            return None
        if self.advance("continuous") > FMI3_WARNING:
            return f"going on to Continuous-Time Mode failed: {self.log[-1:]}"
        import ctypes
        x, dx, z = c_array(self.nx), c_array(self.nx), c_array(self.nz)
        statuses = [self.raw("fmi3SetTime", [ctypes.c_double], 1e-3),
                    self.raw("fmi3GetContinuousStates", list(_ARRAY_ARGS), x, self.nx),
                    self.raw("fmi3SetContinuousStates", list(_ARRAY_ARGS), x, self.nx),
                    self.raw("fmi3GetContinuousStateDerivatives", list(_ARRAY_ARGS), dx, self.nx),
                    self.raw("fmi3GetEventIndicators", list(_ARRAY_ARGS), z, self.nz)]
        if max(statuses) > FMI3_WARNING or not all(math.isfinite(v) for v in list(dx)[: self.nx]) \
                or not self.outputs_finite():
            return f"a continuous-time round after the refusal failed: {self.log[-1:]}"
        if self.fmu.completedIntegratorStep() != (False, False):
            return "fmi3CompletedIntegratorStep asked for an event or the end"
        return None

    def free(self) -> list[str]:
        if self.phase in ("step", "event", "continuous"):
            self.call("terminate")
        return free_instance(self.fmu, "fmi3FreeInstance")




def _state3_edited(data: bytes, edit: str) -> bytes:
    """A serialized FMI 3 state of ours with one kind of damage to its header (``STATE3_EDITS``)."""
    import struct
    if edit == "truncated":
        return data[: len(data) // 2]
    if edit == "header-only":
        return data[:STATE3_HEADER]
    if edit == "empty":
        return b""
    if edit == "padded":
        return data + b"  "
    if edit == "magic":
        return b"NOTLVR3\0" + data[8:]
    if edit == "version":
        return data[:8] + struct.pack("<I", 99) + data[12:]
    if edit in ("state", "state-bits"):
        return data[:12] + struct.pack("<I", 32 if edit == "state" else 48) + data[16:]
    if edit == "discarded":
        return data[:16] + struct.pack("<I", 1) + data[20:]
    if edit in ("time", "time-bit", "time-nan"):
        time = struct.unpack("<d", data[24:32])[0]
        if edit == "time":
            time = 5.0
        elif edit == "time-nan":
            time = math.nan
        else:
            time = struct.unpack("<d", struct.pack("<Q", struct.unpack("<Q", struct.pack("<d", time))[0] ^ 1))[0]
        return data[:24] + struct.pack("<d", time) + data[32:]
    if edit == "payload-byte":
        middle = STATE3_HEADER + SHIM_HEADER + (len(data) - STATE3_HEADER - SHIM_HEADER) * 3 // 4
        return data[:middle] + b"\xff" + data[middle + 1:]
    raise ValueError(f"unknown edit {edit}")


def _act3(inst: _Instance3, case: Case, fmu_dir: Path) -> int:
    import ctypes

    function, *args = case.action[2]
    kind = args[0] if args else None
    dbl, size_t, ptr, boolean = ctypes.c_double, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_bool
    flags = [boolean() for _ in range(5)]
    n = {"nx": inst.nx, "nz": inst.nz}
    outputs = [v.valueReference for v in inst.md.modelVariables if v.causality == "output"]
    if function == "fmi3DoStep":
        point, h = (inst.time, 1e-3) if kind is None else (inst.time if args[1] is None else args[1], args[2])
        return inst.raw(function, [dbl, dbl, boolean, ptr, ptr, ptr, ptr], point, h, True,
                        *(ctypes.byref(f) for f in flags[:3]), ctypes.byref(dbl()))
    if function == "fmi3EnterInitializationMode":
        start = args[1] if kind == "start" else 0.0
        return inst.raw(function, [boolean, dbl, dbl, boolean, dbl], False, 0.0, start, False, 0.0)
    if function in ("fmi3ExitInitializationMode", "fmi3EnterStepMode", "fmi3EnterEventMode",
                    "fmi3EnterContinuousTimeMode", "fmi3Terminate", "fmi3EnterConfigurationMode",
                    "fmi3ExitConfigurationMode"):
        return inst.raw(function, [])
    if function == "fmi3UpdateDiscreteStates":
        return inst.raw(function, [ptr] * 6, *(ctypes.byref(f) for f in flags), ctypes.byref(dbl()))
    if function == "fmi3CompletedIntegratorStep":
        return inst.raw(function, [boolean, ptr, ptr], True, ctypes.byref(flags[0]), ctypes.byref(flags[1]))
    if function == "fmi3SetTime":
        return inst.raw(function, [dbl], args[1] if kind == "value" else 0.5)
    if function in ME3_ARRAYS:
        size = n[ME3_ARRAYS[function]]
        count = args[1] if kind == "size" else size
        array = c_array(max(count, size, 1))
        if kind == "value":
            inst.raw("fmi3GetContinuousStates", list(_ARRAY_ARGS), array, size)
            array[args[1]] = args[2]
        return inst.raw(function, list(_ARRAY_ARGS), array, count)
    if function == "fmi3GetFMUState":
        return inst.raw(function, [ptr], ctypes.byref(ptr()))
    if function == "fmi3GetOutputDerivatives":
        return inst.raw(function, [ptr, size_t, ptr, ptr, size_t], (ctypes.c_uint32 * 1)(outputs[0]), 1,
                        (ctypes.c_int32 * 1)(1), (dbl * 1)(), 1)
    if function in ("state3", "state3-inner"):
        state = inst.fmu.getFMUState()
        data = bytes(inst.fmu.serializeFMUState(state))
        inst.fmu.freeFMUState(state)
        if function == "state3":
            data = _state3_edited(data, kind)
        else:
            data = data[:STATE3_HEADER] + edited_state(data[STATE3_HEADER:], kind, case.fmu)
        buffer = (ctypes.c_uint8 * max(len(data), 1)).from_buffer_copy(data or b"\0")
        restored = ptr()
        status = inst.raw("fmi3DeserializeFMUState", [ptr, size_t, ptr], buffer, len(data), ctypes.byref(restored))
        if status > FMI3_WARNING:
            return status
        status = inst.raw("fmi3SetFMUState", [ptr], restored)
        inst.raw("fmi3FreeFMUState", [ptr], ctypes.byref(restored))
        return status
    # getters and setters
    element = {"Float64": dbl, "Int32": ctypes.c_int32, "Boolean": boolean, "String": ctypes.c_char_p,
               "Float32": ctypes.c_float, "Int64": ctypes.c_int64}
    kind_of = function[len("fmi3Get"):]
    vr = outputs[0]
    if kind == "count":
        values = (element[kind_of] * 2)()
        return inst.raw(function, [ptr, size_t, ptr, size_t], (ctypes.c_uint32 * 1)(vr), 1, values, 2)
    if kind == "null":
        return inst.raw(function, [ptr, size_t, ptr, size_t], (ctypes.c_uint32 * 1)(vr), 1, None, 1)
    if kind == "indicator-unknown":
        values = (dbl * 2)(-1.0, -1.0)
        status = inst.raw(function, [ptr, size_t, ptr, size_t],
                          (ctypes.c_uint32 * 2)(inst.variables["event_indicator_1"].valueReference, 999_999), 2,
                          values, 2)
        if list(values) != [-1.0, -1.0]:
            inst.problems.append(f"the refused read wrote {list(values)} into the values array")
        return status
    if kind in ("unknown", "time", "indicator", "value", "past"):
        own = [v.valueReference for n, v in inst.variables.items() if n == "time" or n.startswith("event_indicator_")]
        vr = {"unknown": 999_999, "time": inst.variables["time"].valueReference, "past": max(own) + 1,
              "indicator": inst.variables.get("event_indicator_1", inst.variables["time"]).valueReference}.get(kind)
        value = 1.0
        if kind == "value":
            vr, value = inst.variables[args[1]].valueReference, args[2]
        return inst.raw(function, [ptr, size_t, ptr, size_t], (ctypes.c_uint32 * 1)(vr), 1, (dbl * 1)(value), 1)
    if kind == "type":
        if function == "fmi3GetBinary":
            return inst.raw(function, [ptr, size_t, ptr, ptr, size_t], (ctypes.c_uint32 * 1)(vr), 1,
                            (size_t * 1)(), (ptr * 1)(), 1)
        return inst.raw(function, [ptr, size_t, ptr, size_t], (ctypes.c_uint32 * 1)(vr), 1,
                        (element[kind_of] * 1)(), 1)
    raise ValueError(f"unknown FMI 3 action {function} {kind}")


def run_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
    outcome = Outcome(case)
    inst = _Instance3(case.fmu, fmu_dir, case.interface)
    try:
        if inst.advance(case.phase) > FMI3_WARNING:
            outcome.problems.append(f"reaching phase {case.phase} failed: {inst.log[-1:]}")
        everything, states = inst.reals(), inst.states()
        if everything is None:
            outcome.problems.append(f"the Float64 variables could not be read before the call: {inst.log[-1:]}")
        seen = len(inst.log)
        status = _act3(inst, case, fmu_dir)
        outcome.status = status
        outcome.problems += inst.problems
        logged = inst.log[seen:]
        if status != FMI3_ERROR:
            outcome.problems.append(f"status {status}, expected fmi3Error")
        text = judge_log(outcome, logged, case)
        if "fmi2" in text:
            outcome.problems.append(f"the message speaks of FMI 2.0 functions: {text!r}")
        judge_after_refusal(outcome, inst, everything, states, most=5)
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += inst.free()
    return outcome
