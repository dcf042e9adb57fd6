"""The FMI 2.0 Co-Simulation cases: generated from every FMU's declared parameters and
inputs, and written out by hand (states, steps, types, unknown references), run through
fmpy's ``FMU2Slave``."""
from __future__ import annotations

import math
from pathlib import Path

from lever.physics.parameters import Parameter

from harness.formats.badinputs.common import (changed, free_instance, judge_log, DECLARED, DEG, FMI2_OK, FMI2_WARNING,
                                              LOG, PHASES, REFUSED, Case, Outcome, ADAPTERS, declared,
                                              instance_numbers, listen, model_description, status_of)
from harness.paths import FMUS


#: Well-formed values of the table parameters (for changing them after initialisation).
_GOOD_TABLES = {("LeverCoupling", "elastic_table"): "0.1:10; 0.2:30",
                ("EngineShaft", "characteristic"): "0:600; 100:0",
                ("LoadShaft", "fourier"): "100; 1:2", ("LoadShaft", "table"): "0:100; 1:110",
                ("MisalignmentSource", "table"): "0:0.2; 1:0.3"}




def _outside(p: Parameter) -> list[tuple[str, float]]:
    """The nearest values outside a real parameter's range, with a label."""
    values = []
    if math.isfinite(p.low):
        if p.low_open:
            values.append(("zero" if p.low == 0 else "at the open lower bound", p.low))
        elif p.low > 0:
            values += [("zero", 0.0), ("below the range", p.low / 2)]
        values.append(("negative" if p.low >= 0 else "below the range",
                       -1.0 if p.low >= 0 else p.low - max(1.0, abs(p.low))))
    if math.isfinite(p.high):
        values.append(("at the open upper bound" if p.high_open else "above the range",
                       p.high if p.high_open else p.high + max(1.0, abs(p.high))))
    return values


def _range_fragments(p: Parameter) -> tuple[str, ...]:
    return (f"'{p.name}'", p.range_text())


def _generated() -> list[Case]:
    cases = []
    for fmu, (parameters, inputs) in DECLARED.items():
        reals = [(p, "instantiated") for p in parameters if p.kind == "real"]
        reals += [(declared(fmu, n), "stepping") for n in inputs]
        for p, phase in reals:
            kind = "input" if phase == "stepping" else "parameter"
            for value in (math.nan, math.inf, -math.inf):
                cases.append(Case(fmu, f"non-finite {kind}", f"{p.name} = {value}", phase, ("set", p.name, value),
                                  _range_fragments(p)))
            for label, value in _outside(p):
                category = {"inertia": "non-positive inertia", "stiffness": "non-positive stiffness",
                            "damping": "negative damping", "misalignment": "misalignment out of range"}.get(
                    p.name, f"{kind} out of range")
                cases.append(Case(fmu, category, f"{p.name} = {value!r} ({label})", phase, ("set", p.name, value),
                                  _range_fragments(p)))
        for p in parameters:
            if p.kind == "integer":
                for value in (int(p.low) - 1, int(p.high) + 1):
                    if -2 ** 31 <= value < 2 ** 31:
                        cases.append(Case(fmu, "parameter out of range", f"{p.name} = {value}", "instantiated",
                                          ("set", p.name, value), _range_fragments(p)))
            if p.choices:
                for value in ("", "unknown", p.choices[0].upper()):
                    cases.append(Case(fmu, "unknown mode", f"{p.name} = {value!r}", "instantiated",
                                      ("set", p.name, value), (f"'{p.name}'",) + tuple(f"'{c}'" for c in p.choices)))
        # Every fixed parameter, changed after initialisation (to a value it would accept).
        for p in parameters:
            if p.kind == "real":
                good = p.default * 1.5 + 0.001 if p.default else 0.1
                good = good if good < p.high else (p.default + p.high) / 2
            elif p.kind == "integer":
                good = p.default + 1
            elif p.choices:
                good = next(c for c in p.choices if c != p.default)
            else:
                good = _GOOD_TABLES[fmu, p.name]
            assert p.problem(good) is None, (p.name, good)
            cases.append(Case(fmu, "set after initialisation", f"{p.name} changed after initialisation", "stepping",
                              ("set", p.name, good), (f"'{p.name}'", "fixed", "after initialisation")))
    return cases


#: Tables and combinations the range check alone cannot judge (written out by hand).
_TABLES = [
    # (fmu, parameter, text, fragments, extra setup)
    ("LeverCoupling", "elastic_table", "0.1:10; 0.2:5", ("non-decreasing",), ()),
    ("LeverCoupling", "elastic_table", "0.2:10; 0.1:20", ("strictly increasing",), ()),
    ("LeverCoupling", "elastic_table", "0.1:10", ("at least 2 points",), ()),
    ("LeverCoupling", "elastic_table", "0:5; 0.1:10; 0.2:20", ("zero deflection",), ()),
    ("LeverCoupling", "elastic_table", "0.1:0; 0.2:0", ("no torque",), ()),
    ("LeverCoupling", "elastic_table", "0.1:ten; 0.2:20", ("not numeric",), ()),
    ("LeverCoupling", "elastic_table", "0.1:10:3; 0.2:20", ("2 values",), ()),
    ("LeverCoupling", "elastic_table", "0.1:nan; 0.2:20", ("non-finite",), ()),
    ("LeverCoupling", "elastic_table", "0.1:10; 0.2:1e300", ("within",), ()),
    ("EngineShaft", "characteristic", "40:500", ("at least 2",), ()),
    ("EngineShaft", "characteristic", "40:500; 40:400", ("distinct",), ()),
    ("EngineShaft", "characteristic", "40:500; fast:400", ("not numeric",), ()),
    ("EngineShaft", "characteristic", "40:500; 60:inf", ("non-finite",), ()),
    ("EngineShaft", "characteristic", "kavz", ("named characteristic", "kavz685"), ()),
    ("LoadShaft", "table", "0:100", ("at least 2",), (("load_kind", "table"),)),
    ("LoadShaft", "table", "0:100; 2:120; 1:110", ("strictly increasing",), (("load_kind", "table"),)),
    ("LoadShaft", "table", "0:100; 1:-inf", ("non-finite",), (("load_kind", "table"),)),
    ("LoadShaft", "fourier", "100", ("at least one harmonic",), (("load_kind", "fourier"),)),
    ("LoadShaft", "fourier", "mean; 1:2", ("mean torque",), (("load_kind", "fourier"),)),
    ("LoadShaft", "fourier", "100; 1:2:3", ("2 values",), (("load_kind", "fourier"),)),
]


def _by_hand() -> list[Case]:
    cases = []
    for fmu, name, text, fragments, setup in _TABLES:
        cases.append(Case(fmu, "malformed table", f"{name} = {text!r}", "instantiated", ("set", name, text),
                          (f"'{name}'",) + fragments, setup=setup))
    # The source's table is read when the model is built (its angles judged against the
    # coupling's misalignment range): refused at the end of initialisation.
    for text, fragments in (("0:0.1", ("at least 2",)), ("0:0.1; 0:0.2", ("strictly increasing",)),
                            ("0:0.1; 1:2", ("the angle at t = 1 s", "outside"))):
        cases.append(Case("MisalignmentSource", "malformed table", f"table = {text!r}", "instantiated",
                          ("set", "table", text), ("'table'",) + fragments, refused_by="exit"))
    # Values that are each in range but do not fit together: refused when the model is built.
    cases += [
        Case("LeverCoupling", "misalignment out of range", "kinematic alpha + support tilt >= 45 deg",
             "initialization", ("set", "misalignment", 44 * DEG), ("'misalignment'", "45 deg"),
             setup=(("transfer_mode", "kinematic"), ("support_deformation", 0.1)), refused_by="exit"),
        Case("LeverCoupling", "misalignment out of range", "scaled U12 reaching zero",
             "initialization", ("set", "misalignment", 70 * DEG), ("'misalignment'",),
             setup=(("transfer_mode", "scaled"),), refused_by="exit"),
        # A lagged engine's torque is state: a state without it, or with a malformed one, is refused.
        Case("EngineShaft", "bad state", "fmi2SetFMUstate of a lagged engine's state without its torque",
             "stepping", ("call", "edited-state", ("internal-empty",)), ("FMUstate", "lagged engine torque"),
             setup=(("torque_lag", 0.1),)),
        Case("EngineShaft", "bad state", "fmi2SetFMUstate of a lagged engine's state with a malformed torque",
             "stepping", ("call", "edited-state", ("internal",)), ("FMUstate", "internal state", "engine_torque"),
             setup=(("torque_lag", 0.1),)),
        Case("LoadShaft", "parameter out of range", "band_low above band_high", "instantiated",
             ("set", "band_low", 500.0), ("'band_low'", "band_high"), refused_by="exit"),
        Case("LoadShaft", "parameter out of range", "breakaway below the Coulomb friction", "instantiated",
             ("set", "breakaway_torque", 2.0), ("'breakaway_torque'", "'friction_torque'", "Fs >= Fc"),
             setup=(("friction_torque", 5.0),), refused_by="exit"),
        Case("LoadShaft", "parameter out of range", "narrowband_low above narrowband_high", "instantiated",
             ("set", "narrowband_low", 500.0), ("'narrowband_low'", "narrowband_high"),
             setup=(("narrowband_share", 0.5),), refused_by="exit"),
        Case("LoadShaft", "parameter out of range", "spectrum shares of dM summing above 1", "instantiated",
             ("set", "narrowband_share", 0.5), ("'narrowband_share'", "'order_share'", "sum to 1 at most"),
             setup=(("order_share", 0.6),), refused_by="exit"),
        Case("LoadShaft", "malformed table", "load_kind 'table' without a table", "instantiated",
             ("set", "load_kind", "table"), ("'table'", "at least 2"), refused_by="exit"),
        Case("LoadShaft", "malformed table", "load_kind 'fourier' without a series", "instantiated",
             ("set", "load_kind", "fourier"), ("'fourier'", "harmonic"), refused_by="exit"),
        # An input the built coupling cannot take is refused when it is set (not at every read).
        Case("LeverCoupling", "misalignment out of range", "kinematic misalignment input beyond 45 deg", "stepping",
             ("set", "misalignment", 50 * DEG), ("'misalignment'", "45 deg", "nothing of this call"),
             setup=(("transfer_mode", "kinematic"),)),
    ]
    # Steps whose cost has no bound: refused at once, naming the step and the bound.
    cases += [
        Case("LoadShaft", "step too costly", "a step of 1e300 s", "stepping", ("call", "fmi2DoStep", (1e-3, 1e300)),
             ("1e+300", "unbounded")),
        Case("EngineShaft", "step too costly", "a step of 1e300 s", "stepping",
             ("call", "fmi2DoStep", (1e-3, 1e300)), ("1e+300", "unbounded")),
    ]
    for label, h in (("1e4 s", 1e4), ("1e9 s", 1e9), ("1e300 s", 1e300)):
        cases.append(Case("FreewheelRectifier", "step too costly", f"a step of {label}", "stepping",
                          ("call", "fmi2DoStep", (1e-3, h)), ("'max_substep'", "200000", "RK4 substeps")))
    for substep in (1e-12, 1e-300, 2.2e-308, 5e-324):
        cases.append(Case("FreewheelRectifier", "step too costly", f"a 1 ms step with max_substep = {substep!r}",
                          "initialization", ("call", "exit-then-step", (0.0, 1e-3)),
                          ("'max_substep'", "200000", "RK4 substeps"), setup=(("max_substep", substep),)))
    cases.append(Case("FreewheelRectifier", "step too costly", "a substep below the time's resolution at t = 1e6 s",
                      "initialization", ("call", "exit-then-step", (1e6, 1e-6)), ("'max_substep'", "resolution"),
                      setup=(("max_substep", 1e-11),), start=1e6))
    # Communication points off by more than rounding at t = 1e6 s (the FMU is at 1e6 + 1 ms).
    for fmu in DECLARED:
        now = 1e6 + 1e-3
        for label, point in (("one step ahead", now + 1e-3), ("one step behind", 1e6), ("1e-6 s ahead", now + 1e-6),
                             ("1e-6 s behind", now - 1e-6)):
            cases.append(Case(fmu, "bad step", f"communication point {label} at t = 1e6 s", "stepping",
                              ("call", "fmi2DoStep", (point, 1e-3)), ("communication point", "rounding"),
                              start=1e6))
    # Out-of-order and malformed FMI calls.
    for fmu in DECLARED:
        cases += [
            Case(fmu, "out-of-order call", "fmi2DoStep before initialisation", "instantiated",
                 ("call", "fmi2DoStep", (0.0, 1e-3)), ("fmi2DoStep", "initialis")),
            Case(fmu, "out-of-order call", "fmi2DoStep in initialisation mode", "initialization",
                 ("call", "fmi2DoStep", (0.0, 1e-3)), ("fmi2DoStep", "initialis")),
            Case(fmu, "out-of-order call", "fmi2ExitInitializationMode without entering", "instantiated",
                 ("call", "fmi2ExitInitializationMode", ()), ("fmi2ExitInitializationMode", "after")),
            Case(fmu, "out-of-order call", "fmi2EnterInitializationMode twice", "initialization",
                 ("call", "fmi2EnterInitializationMode", ()), ("fmi2EnterInitializationMode", "phase")),
            Case(fmu, "out-of-order call", "fmi2EnterInitializationMode while stepping", "stepping",
                 ("call", "fmi2EnterInitializationMode", ()), ("fmi2EnterInitializationMode", "phase")),
            Case(fmu, "bad step", "negative step size", "stepping", ("call", "fmi2DoStep", (1e-3, -1e-3)),
                 ("step size", "> 0")),
            Case(fmu, "bad step", "zero step size", "stepping", ("call", "fmi2DoStep", (1e-3, 0.0)),
                 ("step size", "> 0")),
            Case(fmu, "bad step", "NaN step size", "stepping", ("call", "fmi2DoStep", (1e-3, math.nan)),
                 ("step size", "finite")),
            Case(fmu, "bad step", "infinite step size", "stepping", ("call", "fmi2DoStep", (1e-3, math.inf)),
                 ("step size", "finite")),
            Case(fmu, "bad step", "communication point ahead of the FMU", "stepping",
                 ("call", "fmi2DoStep", (0.5, 1e-3)), ("communication point", "contiguous")),
            Case(fmu, "bad step", "communication point behind the FMU", "stepping",
                 ("call", "fmi2DoStep", (0.0, 1e-3)), ("communication point", "contiguous")),
            Case(fmu, "bad step", "NaN communication point", "stepping",
                 ("call", "fmi2DoStep", (math.nan, 1e-3)), ("communication point", "contiguous")),
            Case(fmu, "out-of-order call", "fmi2DoStep after fmi2Terminate", "stepping",
                 ("call", "terminate-then-step", ()), ("fmi2DoStep", "terminated")),
            Case(fmu, "out-of-order call", "non-finite start time", "instantiated",
                 ("call", "fmi2SetupExperiment", (math.nan,)), ("start time", "finite")),
            Case(fmu, "bad state", "fmi2SetFMUstate of bytes that are no state", "stepping",
                 ("call", "deserialize", (b"\x00garbage{",)), ("fmi2SetFMUstate", "not a serialized state")),
            Case(fmu, "bad state", "fmi2SetFMUstate of a state of another FMU", "stepping",
                 ("call", "foreign-state", ()), ("fmi2SetFMUstate", "not a state of", "a state of")),
        ]
        cases += [Case(fmu, "bad state", f"fmi2SetFMUstate of its own state, {label}", "stepping",
                       ("call", "edited-state", (edit,)), ("FMUstate",) + fragments)
                  for edit, (label, fragments) in STATE_EDITS.items() if edit in state_edits(fmu)]
        cases += _boundary_cases(fmu)
    return cases


#: Damage done to a state the instance serialized itself (``edited_state``):
#: edit -> (label, fragments of the refusal's message).
STATE_EDITS = {
    "truncated": ("truncated in the middle", ("truncated",)),
    "header-only": ("cut after its header", ("truncated",)),
    "padded": ("with bytes appended", ("padded",)),
    "format": ("of an unknown format version", ("format",)),
    "model": ("whose header names another model", ("not a state of", "a state of")),
    "guid": ("whose header names another GUID", ("GUID",)),
    "nested": ("with deeply nested content", ("nested",)),
    "not-json": ("with content that is no JSON", ("does not decode",)),
    "nan-input": ("with a NaN input", ("not finite",)),
    "parameter-range": ("with a parameter out of its range", ("outside",)),
    "parameter-type": ("with a parameter of the wrong type", ("is not a",)),
    "missing-variable": ("lacking a variable", ("missing",)),
    "time": ("with a non-finite time", ("time",)),
    "phase": ("with an unknown phase", ("phase",)),
    "internal": ("with a malformed internal state", ("internal state",)),
    "frame-time": ("whose native header's time disagrees with the model's", ("disagree",)),
    "frame-state": ("whose native header says terminated over a stepping model", ("disagree",)),
    "frame-time-bit": ("with one bit of the native header's time flipped", ("disagree",)),
    "frame-step-failed": ("whose native header says 'step failed' (never entered by our FMUs)", ("step failed",)),
}


def state_edits(fmu: str) -> tuple[str, ...]:
    """The edits of ``STATE_EDITS`` that ``fmu``'s state has something for (an input, a
    real parameter)."""
    parameters, inputs = DECLARED[fmu]
    needs = {"nan-input": bool(inputs), "parameter-range": any(p.kind == "real" for p in parameters),
             "parameter-type": any(p.kind == "real" for p in parameters)}
    return tuple(edit for edit in STATE_EDITS if needs.get(edit, True))


#: The native entry's frame around the model's serialized state (build/shim: magic[8]
#: version:u32 state:u32 time:f64 length:u64, little-endian on our platforms).
SHIM_MAGIC, SHIM_HEADER = b"LVRSHIM\0", 32


def edited_state(data: bytes, edit: str, fmu: str) -> bytes:
    """A serialized state of ours with one kind of damage (``STATE_EDITS``).

    Truncating and padding damage the whole state, so the native entry's frame must find
    them; every other edit is made to the model's state inside the
    frame, which is then re-framed with the right length, so the model's own validation
    must find it."""
    if edit == "truncated":
        return data[: len(data) // 2]
    if edit == "padded":
        return data + b"  "
    import struct
    if edit.startswith("frame-"):
        # the native entry's header against the model's part: each valid, together not
        state, time = struct.unpack("<Id", data[12:24])
        if edit == "frame-time":
            time = 5.0
        elif edit == "frame-state":
            state = 16
        elif edit == "frame-step-failed":
            state = 8
        else:
            time = struct.unpack("<d", struct.pack("<Q", struct.unpack("<Q", struct.pack("<d", time))[0] ^ 1))[0]
        return data[:12] + struct.pack("<Id", state, time) + data[24:]
    if not data.startswith(SHIM_MAGIC):
        return _edited_model_state(data, edit, fmu)
    frame, inner = data[:SHIM_HEADER], _edited_model_state(data[SHIM_HEADER:], edit, fmu)
    return frame[:24] + struct.pack("<Q", len(inner)) + inner


def _edited_model_state(data: bytes, edit: str, fmu: str) -> bytes:
    import json
    magic, rest = data.split(b" ", 1)
    header_text, payload = rest.split(b"\n", 1)
    header, state = json.loads(header_text), json.loads(payload)
    if edit == "truncated":
        return data[: len(data) // 2]
    if edit == "header-only":
        return data[: len(data) - len(payload)]
    if edit == "padded":
        return data + b"  "
    if edit == "nested":
        payload = b"[" * 100_000 + b"]" * 100_000
    elif edit == "not-json":
        payload = b"{time: soon}"
    else:
        variables = state["variables"]
        parameters, inputs = DECLARED[fmu]
        first_real_parameter = next((p.name for p in parameters if p.kind == "real"), None)
        if edit == "format":
            header["format"] = 99
        elif edit == "model":
            header["model"] = "SomeOtherModel"
        elif edit == "guid":
            header["guid"] = "{00000000-0000-0000-0000-000000000000}"
        elif edit == "nan-input":
            variables[inputs[0]] = math.nan
        elif edit == "parameter-range":
            variables[first_real_parameter] = -1.0e300
        elif edit == "parameter-type":
            variables[first_real_parameter] = "heavy"
        elif edit == "missing-variable":
            del variables[next(iter(variables))]
        elif edit == "time":
            state["time"] = math.inf
        elif edit == "phase":
            state["phase"] = "flying"
        elif edit == "internal":
            state["internal"] = {"bogus": [1, 2]}
        elif edit == "internal-empty":
            state["internal"] = {}
        payload = json.dumps(state, allow_nan=True).encode()
    header["length"] = len(payload)
    return magic + b" " + json.dumps(header).encode() + b"\n" + payload


def _boundary_cases(fmu: str) -> list[Case]:
    """fmi2Set* on what FMI 2.0 does not let an importer set, and in states where it may not."""
    parameters, inputs = DECLARED[fmu]
    outputs = _OUTPUTS[fmu]
    cases = []
    for name in outputs:
        for phase, value in (("stepping", 1.5), ("initialization", math.nan)):
            cases.append(Case(fmu, "set on an output", f"fmi2SetReal on output {name} = {value} ({phase})", phase,
                              ("set", name, value), (f"'{name}'", "cannot be set", "output")))
    if not inputs:
        return cases + [_unknown_reference(fmu)]
    first_input = inputs[0]
    cases += [
        Case(fmu, "set on an output", f"one call setting input {first_input} and output {outputs[0]}", "stepping",
             ("call", "set-many", ((first_input, 0.25), (outputs[0], 2.0))), (f"'{outputs[0]}'", "cannot be set",
                                                                               "nor anything else")),
        Case(fmu, "set in a wrong state", f"input {first_input} set after fmi2Terminate", "stepping",
             ("call", "terminate-then-set", (first_input, 0.25)), ("fmi2SetReal", "'terminated'")),
        Case(fmu, "wrong type or reference", f"fmi2SetInteger on the Real input {first_input}", "stepping",
             ("call", "set-as", ("setInteger", first_input, 1)), (f"'{first_input}'", "Real variable")),
        Case(fmu, "wrong type or reference", f"fmi2SetBoolean on the Real input {first_input}", "stepping",
             ("call", "set-as", ("setBoolean", first_input, True)), (f"'{first_input}'", "Real variable")),
        _unknown_reference(fmu),
    ]
    return cases


def _unknown_reference(fmu: str) -> Case:
    return Case(fmu, "wrong type or reference", "fmi2SetReal of an unknown value reference", "stepping",
                ("call", "set-unknown", ()), ("value reference", "no variable"))


#: FMU -> its outputs (as the adapters declare them)
_OUTPUTS = {fmu: tuple(o.name for o in cls.OUTPUTS) for fmu, cls in ADAPTERS.items()}




def cases() -> list[Case]:
    return _generated() + _by_hand()




class Slave:
    """One FMU2Slave instance of a built FMU with its own log."""

    def __init__(self, fmu: str, fmu_dir: Path):
        from fmpy.fmi2 import FMU2Slave
        from harness.engine.component import log_callbacks
        from harness.engine.component import unzipped as extracted

        path = Path(fmu_dir) / f"{fmu}.fmu"
        self.md, unzipped = model_description(path), extracted(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.instance = f"corpus-{fmu}-{next(instance_numbers)}"
        self.log = LOG.setdefault(self.instance, [])
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipped,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.instance)
        self.fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
        self.time = 0.0

    def call(self, function: str, *args) -> int:
        return status_of(self.fmu, function, *args)

    def set(self, name: str, value) -> int:
        v = self.variables[name]
        setter = {"Real": ("setReal", float), "Integer": ("setInteger", int), "String": ("setString", str)}[v.type]
        return self.call(setter[0], [v.valueReference], [setter[1](value)])

    def reals(self) -> dict:
        """Every Real variable's value (what a refused call must leave as it was)."""
        names = [n for n, v in self.variables.items() if v.type == "Real"]
        return dict(zip(names, self.fmu.getReal([self.variables[n].valueReference for n in names])))

    def get(self, name: str):
        v = self.variables[name]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "String": self.fmu.getString}[v.type]
        value = getter([v.valueReference])[0]
        return value.decode() if isinstance(value, bytes) else value

    def advance(self, phase: str, start: float = 0.0) -> int:
        """Bring the instance from instantiated to ``phase`` (starting at ``start``); the
        worst status seen."""
        worst = FMI2_OK
        if PHASES.index(phase) >= 1:
            worst = max(worst, self.call("setupExperiment", None, start, None))
            worst = max(worst, self.call("enterInitializationMode"))
        if PHASES.index(phase) >= 2:
            worst = max(worst, self.call("exitInitializationMode"))
            worst = max(worst, self.call("doStep", start, 1e-3))
            self.time = start + 1e-3
        return worst

    def step_ok(self) -> bool:
        status = self.call("doStep", self.time, 1e-3)
        self.time += 1e-3
        outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output"]
        return status <= FMI2_WARNING and all(math.isfinite(x) for x in self.fmu.getReal(outputs))

    def free(self) -> list[str]:
        self.call("terminate")
        return free_instance(self.fmu)


def _foreign_state_bytes(case: Case, fmu_dir: Path) -> bytes:
    other = next(n for n in DECLARED if n != case.fmu)
    slave = Slave(other, fmu_dir)
    try:
        slave.advance("stepping")
        return bytes(slave.fmu.serializeFMUstate(slave.fmu.getFMUstate()))
    finally:
        slave.free()


def _act(slave: Slave, case: Case, fmu_dir: Path) -> int:
    kind, *rest = case.action
    if kind == "set":
        return slave.set(*rest)
    function, args = rest
    if function == "fmi2DoStep":
        return slave.call("doStep", *args)
    if function == "fmi2ExitInitializationMode":
        return slave.call("exitInitializationMode")
    if function == "fmi2EnterInitializationMode":
        return slave.call("enterInitializationMode")
    if function == "fmi2SetupExperiment":
        return slave.call("setupExperiment", None, *args)
    if function == "exit-then-step":
        if slave.call("exitInitializationMode") > FMI2_WARNING:
            return FMI2_OK       # refused before the step: the case fails on its message
        return slave.call("doStep", *args)
    if function == "terminate-then-step":
        slave.call("terminate")
        return slave.call("doStep", slave.time, 1e-3)
    if function == "set-many":
        return slave.call("setReal", [slave.variables[n].valueReference for n, _ in args], [v for _, v in args])
    if function == "terminate-then-set":
        slave.call("terminate")
        return slave.set(*args)
    if function == "set-as":
        setter, name, value = args
        return slave.call(setter, [slave.variables[name].valueReference], [value])
    if function == "set-unknown":
        return slave.call("setReal", [max(v.valueReference for v in slave.variables.values()) + 1000], [1.0])
    if function in ("deserialize", "foreign-state", "edited-state"):
        if function == "edited-state":
            own = bytes(slave.fmu.serializeFMUstate(slave.fmu.getFMUstate()))
            data = edited_state(own, args[0], case.fmu)
        else:
            data = args[0] if function == "deserialize" else _foreign_state_bytes(case, fmu_dir)
        from fmpy.fmi1 import FMICallException
        try:
            state = slave.fmu.deSerializeFMUstate(data)
        except FMICallException as error:
            return error.status
        return slave.call("setFMUstate", state)
    raise ValueError(f"unknown action {function}")


def run_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
    listen()
    outcome = Outcome(case)
    slave = Slave(case.fmu, fmu_dir)
    try:
        for name, value in case.setup:
            if slave.set(name, value) > FMI2_WARNING:
                outcome.problems.append(f"setting up {name} = {value!r} was refused")
        if slave.advance(case.phase, case.start) > FMI2_WARNING:
            outcome.problems.append(f"reaching phase {case.phase} failed: {slave.log[-1:]}")
        before = slave.get(case.action[1]) if case.action[0] == "set" else None
        everything = slave.reals() if case.refused_by == "action" else None
        seen = len(slave.log)
        status = _act(slave, case, fmu_dir)
        if case.refused_by == "exit":
            if status > FMI2_WARNING:
                outcome.problems.append(f"the value was refused when set (status {status}), not at initialisation")
            if case.phase == "instantiated":
                slave.advance("initialization")
            status = slave.call("exitInitializationMode")
        outcome.status = status
        logged = slave.log[seen:]
        if status not in REFUSED:
            outcome.problems.append(f"status {status}, expected fmi2Error or fmi2Discard")
        judge_log(outcome, logged, case)
        if case.refused_by == "action":
            if before is not None:
                after = slave.get(case.action[1])
                if not (after == before or (isinstance(before, float) and math.isnan(before) and math.isnan(after))):
                    outcome.problems.append(f"the refused value was applied: {before!r} -> {after!r}")
            moved = changed(everything, slave.reals())
            if moved:
                outcome.problems.append(f"the refused call changed {', '.join(moved)}")
            if (case.phase == "stepping" and case.action[1] not in ("terminate-then-step", "terminate-then-set")
                    and not slave.step_ok()):
                outcome.problems.append(f"the instance did not step on after the refusal: {slave.log[-1:]}")
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += slave.free()
        LOG.pop(slave.instance, None)
    return outcome

