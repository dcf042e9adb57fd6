"""The bad-input corpus: values and call sequences an importer may throw at our FMUs,
kept as data (a table of cases) and run through the FMI interface of the built FMUs
with fmpy's ``FMU2Slave`` (``lever badinputs``, ``tests/fmus/test_badinputs.py``), and the
Model Exchange interface with its ``FMU2Model``: every Model Exchange function in a state the
standard's table does not allow and on a Co-Simulation instance, the Co-Simulation functions
on a Model Exchange instance, arrays of the wrong size or NULL for every function that takes
one, non-finite states and times, directional derivatives of references that are no known or
unknown; what fmpy's wrappers would not pass (a NULL array, a size other than the model's,
a Co-Simulation function on a Model Exchange instance) is called through ctypes on the same
instance.  Besides fmi2Error and the message, such a case checks that no Real and no state
changed and that a legal round of calls (on to continuous-time mode, fmi2SetTime,
fmi2SetContinuousStates, fmi2GetDerivatives, fmi2GetEventIndicators, the outputs finite,
fmi2CompletedIntegratorStep) works afterwards.

Every case must end the same way: the offending call returns fmi2Error (or fmi2Discard),
the FMU logs a message that names the variable (or the call) and what is allowed, a
refused call changes no variable (every Real is read before and after it), the instance
stays usable where FMI lets it, nothing is ever fatal, and the instance is freed cleanly.

Besides bad values: fmi2Set* on outputs, after fmi2Terminate, with the wrong type or an
unknown value reference, a multi-value call with one bad value (nothing of it applied),
serialized states damaged every way ``_STATE_EDITS`` lists (header, length, format,
model, GUID, nesting, content, a native header that disagrees with the model's part),
communication points off by more than rounding, and steps too costly to take (a huge step,
a tiny ``max_substep``).  The importing process - the one running
the corpus - survives all of it.

The FMI 3.0 editions (build/fmus3) get cases of their own (``_fmi3_cases``, run with fmpy's
``FMU3Slave``/``FMU3Model``, every call under test through ctypes): the FMI 3.0 state machine
(every Model Exchange function in each state the standard's table does not allow, the
Co-Simulation ones out of order, each interface's functions on the other's instance),
value counts (``nValues``) that differ from the value references, NULL arrays, unknown
value references, ``time`` and event indicators set, types the FMUs have no variable of,
Model Exchange arrays of another size than the model's, NaN and infinity (inputs,
parameters, step sizes and communication points, start time, fmi3SetTime, states), and
serialized states with the FMI 3 header damaged (``STATE3_EDITS``) or the FMI 2 entry's part
inside it damaged as ``_STATE_EDITS`` says.  Each must return fmi3Error (never Discard or
Fatal) with a message in FMI 3.0 terms that names the call and what is wrong, change no
Float64 and no state, and leave the instance usable: a step, or a continuous-time round,
after fmi3Reset where it was terminated.

Cases for the declared parameters and inputs are generated from the adapters of every
FMU of ``lever.fmus.registry`` (every real: NaN, +inf, -inf and the nearest values
outside its range; every fixed parameter: a change after initialisation), the rest are
written out by hand.
"""
from __future__ import annotations

import ctypes
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

from lever.fmus import registry
from lever.physics.parameters import Parameter

from harness.paths import FMUS

FMI2_OK, FMI2_WARNING, FMI2_DISCARD, FMI2_ERROR, FMI2_FATAL = range(5)
REFUSED = (FMI2_DISCARD, FMI2_ERROR)

#: FMU -> its adapter class, for every FMU of the registry
_ADAPTERS = {m.name: m.adapter() for m in registry.MODELS}
#: FMU -> (parameters, names of its inputs), as the adapters declare them
DECLARED = {fmu: (tuple(cls.PARAMETERS), tuple(p.name for p in cls.INPUTS)) for fmu, cls in _ADAPTERS.items()}
PHASES = ("instantiated", "initialization", "stepping")
DEG = math.pi / 180.0

#: Well-formed values of the table parameters (for changing them after initialisation).
_GOOD_TABLES = {("LeverCoupling", "elastic_table"): "0.1:10; 0.2:30",
                ("EngineShaft", "characteristic"): "0:600; 100:0",
                ("LoadShaft", "fourier"): "100; 1:2", ("LoadShaft", "table"): "0:100; 1:110",
                ("MisalignmentSource", "table"): "0:0.2; 1:0.3"}


@dataclass(frozen=True)
class Case:
    """One bad input.

    ``phase``: where the FMU is when the bad input arrives (``instantiated``,
    ``initialization`` or ``stepping``, the last after one step).  ``setup``: good values
    set first.  ``action``: ``("set", name, value)`` or ``("call", fmi_function, args)``.
    ``refused_by``: the call that must return error/discard: the action itself
    (``"action"``) or ``fmi2ExitInitializationMode`` (``"exit"``: values that are only
    judged together, when the model is built).  ``expect``: fragments the logged error
    message must contain (the variable and its allowed range).  ``start``: the start time.
    """

    fmu: str
    category: str
    label: str
    phase: str
    action: tuple
    expect: tuple[str, ...]
    setup: tuple[tuple[str, object], ...] = ()
    refused_by: str = "action"
    #: the start time given to fmi2SetupExperiment (the first step starts there)
    start: float = 0.0
    #: the interface the instance is instantiated for: ``CoSimulation`` (fmpy's FMU2Slave) or
    #: ``ModelExchange`` (FMU2Model; ``phase`` then one of ``ME_PHASES``)
    interface: str = "CoSimulation"

    @property
    def name(self) -> str:
        return f"{self.fmu}: {self.label}"


def _declared(fmu: str, name: str) -> Parameter:
    cls = _ADAPTERS[fmu]
    return {p.name: p for p in (*cls.PARAMETERS, *cls.INPUTS)}[name]


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
        reals += [(_declared(fmu, n), "stepping") for n in inputs]
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
                  for edit, (label, fragments) in _STATE_EDITS.items() if edit in state_edits(fmu)]
        cases += _boundary_cases(fmu)
    return cases


#: Damage done to a state the instance serialized itself (``_edited_state``):
#: edit -> (label, fragments of the refusal's message).
_STATE_EDITS = {
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
}


def state_edits(fmu: str) -> tuple[str, ...]:
    """The edits of ``_STATE_EDITS`` that ``fmu``'s state has something for (an input, a
    real parameter)."""
    parameters, inputs = DECLARED[fmu]
    needs = {"nan-input": bool(inputs), "parameter-range": any(p.kind == "real" for p in parameters),
             "parameter-type": any(p.kind == "real" for p in parameters)}
    return tuple(edit for edit in _STATE_EDITS if needs.get(edit, True))


#: The native entry's frame around the model's serialized state (build/shim: magic[8]
#: version:u32 state:u32 time:f64 length:u64, little-endian on our platforms).
SHIM_MAGIC, SHIM_HEADER = b"LVRSHIM\0", 32


def _edited_state(data: bytes, edit: str, fmu: str) -> bytes:
    """A serialized state of ours with one kind of damage (``_STATE_EDITS``).

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
_OUTPUTS = {fmu: tuple(o.name for o in cls.OUTPUTS) for fmu, cls in _ADAPTERS.items()}


def corpus() -> list[Case]:
    return _generated() + _by_hand() + _model_exchange_cases() + _fmi3_cases()


# -- running a case ---------------------------------------------------------------------------------------

@dataclass
class Outcome:
    case: Case
    status: int | None = None          # status of the call that had to refuse
    messages: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.problems


_counter = itertools.count(1)
_LOG: dict[str, list[tuple[int, str]]] = {}
_listening = False


def _listen():
    global _listening
    if not _listening:
        from harness.engine.component import add_log_listener
        add_log_listener(lambda name, status, category, text: _LOG.setdefault(name, []).append((status, text)))
        _listening = True


class _Slave:
    """One FMU2Slave instance of a built FMU with its own log."""

    _descriptions: dict[str, object] = {}

    def __init__(self, fmu: str, fmu_dir: Path):
        import fmpy
        from fmpy.fmi2 import FMU2Slave
        from harness.engine.component import log_callbacks
        from harness.engine.component import unzipped as extracted

        path = Path(fmu_dir) / f"{fmu}.fmu"
        if str(path) not in self._descriptions:
            self._descriptions[str(path)] = fmpy.read_model_description(str(path))
        self.md, unzipped = self._descriptions[str(path)], extracted(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.instance = f"corpus-{fmu}-{next(_counter)}"
        self.log = _LOG.setdefault(self.instance, [])
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipped,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.instance)
        self.fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
        self.time = 0.0

    def call(self, function: str, *args) -> int:
        from fmpy.fmi1 import FMICallException
        try:
            getattr(self.fmu, function)(*args)
        except FMICallException as error:
            return error.status
        return FMI2_OK

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
        problems = []
        self.call("terminate")
        try:
            self.fmu.freeInstance()
        except Exception as error:  # noqa: BLE001 - reported as the case's problem
            problems.append(f"fmi2FreeInstance raised {error!r}")
        return problems


def _foreign_state_bytes(case: Case, fmu_dir: Path) -> bytes:
    other = next(n for n in DECLARED if n != case.fmu)
    slave = _Slave(other, fmu_dir)
    try:
        slave.advance("stepping")
        return bytes(slave.fmu.serializeFMUstate(slave.fmu.getFMUstate()))
    finally:
        slave.free()


def _act(slave: _Slave, case: Case, fmu_dir: Path) -> int:
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
            data = _edited_state(own, args[0], case.fmu)
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
    if case.action[:2] == ("call", "fmi3"):
        return run_fmi3_case(case, fmu_dir)
    if case.action[:2] == ("call", "me"):
        return run_me_case(case, fmu_dir)
    _listen()
    outcome = Outcome(case)
    slave = _Slave(case.fmu, fmu_dir)
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
        outcome.messages = [text for level, text in logged if level >= FMI2_DISCARD]
        if status not in REFUSED:
            outcome.problems.append(f"status {status}, expected fmi2Error or fmi2Discard")
        if any(level == FMI2_FATAL for level, _ in logged):
            outcome.problems.append("a fatal status was logged")
        text = " ".join(outcome.messages)
        missing = [f for f in case.expect if f.lower() not in text.lower()]
        if missing:
            outcome.problems.append(f"the message does not say {missing}: {text!r}")
        if case.refused_by == "action":
            if before is not None:
                after = slave.get(case.action[1])
                if not (after == before or (isinstance(before, float) and math.isnan(before) and math.isnan(after))):
                    outcome.problems.append(f"the refused value was applied: {before!r} -> {after!r}")
            after = slave.reals()
            changed = [n for n, x in everything.items()
                       if not (after[n] == x or (math.isnan(x) and math.isnan(after[n])))]
            if changed:
                outcome.problems.append(f"the refused call changed {', '.join(changed)}")
            if (case.phase == "stepping" and case.action[1] not in ("terminate-then-step", "terminate-then-set")
                    and not slave.step_ok()):
                outcome.problems.append(f"the instance did not step on after the refusal: {slave.log[-1:]}")
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += slave.free()
        _LOG.pop(slave.instance, None)
    return outcome


def run(fmu_dir: Path = FMUS, cases: list[Case] | None = None) -> list[Outcome]:
    return [run_case(case, fmu_dir) for case in (corpus() if cases is None else cases)]


def summary(outcomes: list[Outcome]) -> str:
    """Counts by FMU and category, and every failed case."""
    passed = sum(o.passed for o in outcomes)
    count = {kind: sum(o.case.interface == kind for o in outcomes)
             for kind in ("CoSimulation", "ModelExchange", "CoSimulation3", "ModelExchange3")}
    fmi3 = count["CoSimulation3"] + count["ModelExchange3"]
    if fmi3 or count["ModelExchange"]:
        through = (f"fmpy's FMU2Slave ({count['CoSimulation']}) and FMU2Model ({count['ModelExchange']}, Model "
                   f"Exchange)")
        if fmi3:
            through += (f", and for the FMI 3.0 editions FMU3Slave ({count['CoSimulation3']}) and FMU3Model "
                        f"({count['ModelExchange3']})")
    else:
        through = "fmpy's FMU2Slave"
    lines = [f"bad-input corpus: {len(outcomes)} cases through {through}, {passed} pass, "
             f"{len(outcomes) - passed} fail"]
    if fmi3:
        lines.append(f"  FMI 3.0 cases: {fmi3} (the corpus {len(outcomes) - fmi3} -> {len(outcomes)} cases with them), "
                     f"{sum(o.passed for o in outcomes if o.case.interface.endswith('3'))} pass")
    table: dict[tuple[str, str], list[int]] = {}
    for o in outcomes:
        cell = table.setdefault((o.case.category, o.case.fmu), [0, 0])
        cell[0] += 1
        cell[1] += o.passed
    fmus = list(dict.fromkeys([*DECLARED, *(o.case.fmu for o in outcomes)]))
    width = max(15, *(len(f) + 2 for f in fmus))
    lines.append(f"  {'category':34s}" + "".join(f"{f:>{width}s}" for f in fmus))
    for category in dict.fromkeys(c for c, _ in table):
        cells = [table.get((category, f)) for f in fmus]
        lines.append(f"  {category:34s}" + "".join(f"{'-' if c is None else f'{c[1]}/{c[0]}':>{width}s}" for c in cells))
    for o in outcomes:
        if not o.passed:
            lines.append(f"FAIL {o.case.name}: " + "; ".join(o.problems))
    return "\n".join(lines)


# -- Model Exchange: the calls and the state machine ------------------------------------------------------

#: the Model Exchange phases a case starts from: ``event`` after fmi2ExitInitializationMode,
#: ``continuous`` after the event iteration and fmi2EnterContinuousTimeMode, ``terminated``
#: after fmi2Terminate from there
ME_PHASES = ("instantiated", "initialization", "event", "continuous", "terminated")
#: the native entry's own value references (lever.fmus.model_exchange.CHANNEL)
CHANNEL = 0x40000000
#: the Model Exchange functions that take an array of the states' or indicators' size
ME_ARRAYS = {"fmi2GetDerivatives": "nx", "fmi2GetContinuousStates": "nx", "fmi2SetContinuousStates": "nx",
             "fmi2GetEventIndicators": "nz", "fmi2GetNominalsOfContinuousStates": "nx"}
#: every Model Exchange function of FMI 2.0 (besides those common to both interfaces)
ME_FUNCTIONS = ("fmi2EnterEventMode", "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode",
                "fmi2CompletedIntegratorStep", "fmi2SetTime", *ME_ARRAYS)
#: the sizes of each FMU's Model Exchange interface (its model description says them:
#: ``test_model_exchange.py`` checks them there)
ME_SIZES = {"LeverCoupling": (0, 0), "EngineShaft": (4, 1), "LoadShaft": (3, 1), "FreewheelRectifier": (11, 8),
            "MisalignmentSource": (0, 0)}


def _me(fmu, category, label, phase, what, expect, *args) -> Case:
    return Case(fmu, category, label, phase, ("call", "me", (what, *args)), expect, interface="ModelExchange")


def _model_exchange_cases() -> list[Case]:
    cases = []
    for fmu in DECLARED:
        nx, nz = ME_SIZES[fmu]
        parameters, inputs = DECLARED[fmu]
        order = "out-of-order ME call"
        # each Model Exchange function in a state the standard's table does not allow it in
        wrong_states = [
            ("fmi2GetDerivatives", "instantiated"), ("fmi2GetDerivatives", "initialization"),
            ("fmi2SetContinuousStates", "initialization"), ("fmi2SetContinuousStates", "event"),
            ("fmi2SetContinuousStates", "terminated"),
            ("fmi2NewDiscreteStates", "continuous"), ("fmi2NewDiscreteStates", "initialization"),
            ("fmi2EnterContinuousTimeMode", "continuous"), ("fmi2EnterContinuousTimeMode", "initialization"),
            ("fmi2EnterEventMode", "instantiated"), ("fmi2EnterEventMode", "initialization"),
            ("fmi2EnterEventMode", "terminated"),
            ("fmi2CompletedIntegratorStep", "event"), ("fmi2CompletedIntegratorStep", "initialization"),
            ("fmi2SetTime", "instantiated"), ("fmi2SetTime", "initialization"), ("fmi2SetTime", "terminated"),
            ("fmi2GetEventIndicators", "instantiated"), ("fmi2GetContinuousStates", "instantiated"),
            ("fmi2GetNominalsOfContinuousStates", "initialization"),
            ("fmi2GetDirectionalDerivative", "instantiated"),
            ("fmi2ExitInitializationMode", "continuous"), ("fmi2EnterInitializationMode", "event"),
            ("fmi2SetupExperiment", "continuous"),
        ]
        for function, phase in wrong_states:
            cases.append(_me(fmu, order, f"{function} in {phase} (Model Exchange)", phase, function,
                             (function, "not allowed in state")))
        # the Co-Simulation functions on a Model Exchange instance
        for function in ("fmi2DoStep", "fmi2GetFMUstate", "fmi2GetRealStatus", "fmi2SetRealInputDerivatives"):
            why = "FMU state functions" if "FMUstate" in function else "a Co-Simulation function"
            cases.append(_me(fmu, order, f"{function} on a Model Exchange instance", "continuous", function,
                             (function, "Model Exchange interface", why)))
        # the Model Exchange functions on a Co-Simulation instance
        for function in ME_FUNCTIONS:
            cases.append(Case(fmu, order, f"{function} on a Co-Simulation instance", "stepping",
                              ("call", "me", (function,)), (function, "Model Exchange function", "fmi2CoSimulation"),
                              interface="CoSimulation"))
        # arrays of another size than the model's, and NULL arrays
        for function, size in ME_ARRAYS.items():
            n = nx if size == "nx" else nz
            what = "states" if function.endswith("States") and "Nominals" not in function else {
                "fmi2GetDerivatives": "derivatives", "fmi2GetEventIndicators": "event indicators",
                "fmi2GetNominalsOfContinuousStates": "nominals"}[function]
            for delta in ((1, -1) if n else (1,)):
                cases.append(_me(fmu, "wrong ME size", f"{function} with {n + delta} {what} ({n} declared)",
                                 "continuous", function, (function, f"{n + delta} {what} given", f"has {n}"),
                                 "size", n + delta))
            if n:
                cases.append(_me(fmu, "wrong ME size", f"{function} with a NULL array", "continuous", function,
                                 (function, "NULL"), "null", n))
        cases.append(_me(fmu, "wrong ME size", "fmi2NewDiscreteStates with a NULL fmi2EventInfo", "event",
                         "fmi2NewDiscreteStates", ("fmi2NewDiscreteStates", "NULL"), "null"))
        cases.append(_me(fmu, "wrong ME size", "fmi2CompletedIntegratorStep with NULL flags", "continuous",
                         "fmi2CompletedIntegratorStep", ("fmi2CompletedIntegratorStep", "NULL"), "null"))
        # states and times that are not finite
        for k, value in ((0, math.nan), (nx - 1, math.inf), (nx // 2, -math.inf)) if nx else ():
            cases.append(_me(fmu, "non-finite ME state", f"fmi2SetContinuousStates with x[{k}] = {value}",
                             "continuous", "fmi2SetContinuousStates", ("fmi2SetContinuousStates", f"x[{k}]",
                                                                       "not finite"), "value", k, value))
        for value in (math.nan, math.inf, -math.inf):
            cases.append(_me(fmu, "non-finite ME state", f"fmi2SetTime({value})", "continuous", "fmi2SetTime",
                             ("fmi2SetTime", "not finite"), "value", 0, value))
        # directional derivatives with references that are no known or unknown
        unknown = ("fmi2GetDirectionalDerivative", "value reference")
        for label, kind in (("an unknown value reference as the known", "known-unknown"),
                            ("an unknown value reference as the unknown", "unknown-unknown"),
                            ("a native entry's reference as the known", "known-channel"),
                            ("an output as the known", "known-output")):
            cases.append(_me(fmu, "bad directional derivative", f"fmi2GetDirectionalDerivative with {label}",
                             "continuous", "fmi2GetDirectionalDerivative", unknown, kind))
        if inputs:
            cases += [
                _me(fmu, "bad directional derivative", "fmi2GetDirectionalDerivative with an input as the unknown",
                    "continuous", "fmi2GetDirectionalDerivative", unknown, "unknown-input"),
                _me(fmu, "bad directional derivative", "fmi2GetDirectionalDerivative with a NaN seed",
                    "continuous", "fmi2GetDirectionalDerivative", ("fmi2GetDirectionalDerivative", "not finite"),
                    "nan-seed"),
            ]
        # the native entry's channel is not the host's
        cases += [
            _me(fmu, "bad directional derivative", "fmi2GetReal of a native entry's reference", "continuous",
                "fmi2GetReal", ("fmi2GetReal", "value reference", "no variable"), "channel"),
            _me(fmu, "bad directional derivative", "fmi2SetReal of a native entry's reference", "continuous",
                "fmi2SetReal", ("fmi2SetReal", "value reference", "no variable"), "channel"),
        ]
    return cases


def _array(n: int):
    import ctypes
    return (ctypes.c_double * max(n + 1, 1))()


class _Model:
    """One instance of a built FMU for a Model Exchange case: fmpy's ``FMU2Model`` (or
    ``FMU2Slave`` for the Model Exchange calls on a Co-Simulation instance), its own log."""

    def __init__(self, fmu: str, fmu_dir: Path, interface: str):
        import fmpy
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from harness.engine.component import log_callbacks
        from harness.engine.component import unzipped as extracted

        path = Path(fmu_dir) / f"{fmu}.fmu"
        if str(path) not in _Slave._descriptions:
            _Slave._descriptions[str(path)] = fmpy.read_model_description(str(path))
        self.md, unzipped = _Slave._descriptions[str(path)], extracted(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.nx, self.nz = self.md.numberOfContinuousStates, self.md.numberOfEventIndicators
        self.me = interface == "ModelExchange"
        self.instance = f"corpus-me-{fmu}-{next(_counter)}"
        self.log = _LOG.setdefault(self.instance, [])
        kind = FMU2Model if self.me else FMU2Slave
        identifier = (self.md.modelExchange if self.me else self.md.coSimulation).modelIdentifier
        self.fmu = kind(guid=self.md.guid, unzipDirectory=unzipped, modelIdentifier=identifier,
                        instanceName=self.instance)
        self.fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
        self.phase = "instantiated"
        self.time = 0.0

    def call(self, function: str, *args) -> int:
        from fmpy.fmi1 import FMICallException
        try:
            getattr(self.fmu, function)(*args)
        except FMICallException as error:
            return error.status
        return FMI2_OK

    def raw(self, function: str, argtypes, *args) -> int:
        """A function called straight from the library (one fmpy does not wrap for this
        interface, or with arguments its wrapper would not pass)."""
        import ctypes
        entry = getattr(self.fmu.dll, function)
        entry.argtypes, entry.restype = [ctypes.c_void_p, *argtypes], ctypes.c_int
        return entry(self.fmu.component, *args)

    def advance(self, phase: str) -> int:
        worst = FMI2_OK
        if not self.me:
            return _Slave.advance(self, phase)     # Co-Simulation: as the other cases
        steps = ME_PHASES.index(phase)
        if steps >= 1:
            worst = max(worst, self.call("setupExperiment", None, 0.0, None), self.call("enterInitializationMode"))
        if steps >= 2:
            worst = max(worst, self.call("exitInitializationMode"))
        if steps >= 3:
            worst = max(worst, self._event_iteration(), self.call("enterContinuousTimeMode"))
        if steps >= 4:
            worst = max(worst, self.call("terminate"))
        self.phase = phase
        return worst

    def _event_iteration(self) -> int:
        from fmpy.fmi1 import FMICallException
        for _ in range(100):
            try:
                if not self.fmu.newDiscreteStates()[0]:
                    return FMI2_OK
            except FMICallException as error:
                return error.status
        return FMI2_ERROR

    def states(self) -> list | None:
        if not self.me or self.phase == "instantiated" or not self.nx:
            return None
        x = _array(self.nx)
        return list(x)[: self.nx] if self.call("getContinuousStates", x, self.nx) <= FMI2_WARNING else None

    def reals(self) -> dict:
        names = [n for n, v in self.variables.items() if v.type == "Real"]
        return dict(zip(names, self.fmu.getReal([self.variables[n].valueReference for n in names])))

    def usable(self) -> str | None:
        """A legal round from the case's phase on: on to continuous-time mode, a step of
        continuous-time calls (Co-Simulation: a step); None when it works, else why not."""
        if not self.me:
            return None if _Slave.step_ok(self) else f"the instance did not step on: {self.log[-1:]}"
        if self.phase == "terminated":
            dx = _array(self.nx)
            ok = self.call("getDerivatives", dx, self.nx) <= FMI2_WARNING
            return None if ok else f"fmi2GetDerivatives after fmi2Terminate failed: {self.log[-1:]}"
        rest = ME_PHASES[ME_PHASES.index(self.phase) + 1: ME_PHASES.index("continuous") + 1]
        for phase in rest:
            status = {"initialization": lambda: max(self.call("setupExperiment", None, 0.0, None),
                                                    self.call("enterInitializationMode")),
                      "event": lambda: self.call("exitInitializationMode"),
                      "continuous": lambda: max(self._event_iteration(), self.call("enterContinuousTimeMode"))}[phase]()
            if status > FMI2_WARNING:
                return f"going on to {phase} failed: {self.log[-1:]}"
        x, dx, z = _array(self.nx), _array(self.nx), _array(self.nz)
        statuses = [self.call("setTime", 1e-3), self.call("getContinuousStates", x, self.nx),
                    self.call("setContinuousStates", x, self.nx), self.call("getDerivatives", dx, self.nx),
                    self.call("getEventIndicators", z, self.nz)]
        outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output"]
        values = self.fmu.getReal(outputs)
        if max(statuses) > FMI2_WARNING or not all(math.isfinite(v) for v in list(dx)[: self.nx] + values):
            return f"a continuous-time round after the refusal failed: {self.log[-1:]}"
        if self.fmu.completedIntegratorStep() != (False, False):
            return "fmi2CompletedIntegratorStep asked for an event or the end"
        return None

    def free(self) -> list[str]:
        problems = []
        if self.me and self.phase in ("event", "continuous"):
            self.call("terminate")
        elif not self.me:
            self.call("terminate")
        try:
            self.fmu.freeInstance()
        except Exception as error:  # noqa: BLE001 - reported as the case's problem
            problems.append(f"fmi2FreeInstance raised {error!r}")
        return problems


def _act_me(model: _Model, case: Case) -> int:
    import ctypes

    function, *args = case.action[2]
    kind = args[0] if args else None
    dbl, size_t, ptr = ctypes.c_double, ctypes.c_size_t, ctypes.c_void_p
    n = {"nx": model.nx, "nz": model.nz}
    if function in ME_ARRAYS:
        count = args[1] if kind in ("size", "null") else n[ME_ARRAYS[function]]
        array = None if kind == "null" else _array(max(count, n[ME_ARRAYS[function]]))
        if kind == "value":
            model.call("getContinuousStates", array, model.nx)
            array[args[1]] = args[2]
        return model.raw(function, [ptr, size_t], array, count)
    if function == "fmi2SetTime":
        return model.raw(function, [dbl], args[2] if kind == "value" else 0.5)
    if function == "fmi2NewDiscreteStates":
        from fmpy.fmi2 import fmi2EventInfo
        return model.raw(function, [ptr], None if kind == "null" else ctypes.byref(fmi2EventInfo()))
    if function == "fmi2CompletedIntegratorStep":
        flag = ctypes.c_int()
        return model.raw(function, [ctypes.c_int, ptr, ptr], 1, None if kind == "null" else ctypes.byref(flag),
                         None if kind == "null" else ctypes.byref(flag))
    if function in ("fmi2EnterEventMode", "fmi2EnterContinuousTimeMode", "fmi2ExitInitializationMode",
                    "fmi2EnterInitializationMode"):
        return model.raw(function, [])
    if function == "fmi2SetupExperiment":
        return model.raw(function, [ctypes.c_int, dbl, dbl, ctypes.c_int, dbl], 0, 0.0, 0.0, 0, 0.0)
    if function == "fmi2DoStep":
        return model.raw(function, [dbl, dbl, ctypes.c_int], model.time, 1e-3, 1)
    if function == "fmi2GetFMUstate":
        return model.raw(function, [ptr], ctypes.byref(ctypes.c_void_p()))
    if function == "fmi2GetRealStatus":
        return model.raw(function, [ctypes.c_int, ptr], 2, ctypes.byref(dbl()))
    if function == "fmi2SetRealInputDerivatives":
        vr, order, value = (ctypes.c_uint * 1)(0), (ctypes.c_int * 1)(1), (dbl * 1)(0.0)
        return model.raw(function, [ptr, size_t, ptr, ptr], vr, 1, order, value)
    if function in ("fmi2GetReal", "fmi2SetReal"):
        vr, value = (ctypes.c_uint * 1)(CHANNEL + (1 << 20)), (dbl * 1)(0.0)
        return model.raw(function, [ptr, size_t, ptr], vr, 1, value)
    if function == "fmi2GetDirectionalDerivative":
        variables = model.md.modelVariables
        outputs = [v.valueReference for v in variables if v.causality == "output"]
        inputs = [v.valueReference for v in variables if v.causality == "input"]
        knowns = inputs + [u.variable.derivative.valueReference for u in model.md.derivatives]
        missing = max(v.valueReference for v in variables) + 1000
        unknown, known, seed = outputs[0], (knowns or [missing])[0], 1.0
        if kind == "known-unknown":
            known = missing
        elif kind == "unknown-unknown":
            unknown = missing
        elif kind == "known-channel":
            known = CHANNEL
        elif kind == "known-output":       # an output that is no state (a state is a known)
            states = {u.variable.derivative.valueReference for u in model.md.derivatives}
            known = next(vr for vr in outputs if vr not in states)
        elif kind == "unknown-input":
            unknown = inputs[0]
        elif kind == "nan-seed":
            seed = math.nan
        out = (dbl * 1)()
        return model.raw(function, [ptr, size_t, ptr, size_t, ptr, ptr], (ctypes.c_uint * 1)(unknown), 1,
                         (ctypes.c_uint * 1)(known), 1, (dbl * 1)(seed), out)
    raise ValueError(f"unknown Model Exchange action {function}")


def run_me_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
    _listen()
    outcome = Outcome(case)
    model = _Model(case.fmu, fmu_dir, case.interface)
    try:
        if model.advance(case.phase) > FMI2_WARNING:
            outcome.problems.append(f"reaching phase {case.phase} failed: {model.log[-1:]}")
        everything, states = model.reals(), model.states()
        seen = len(model.log)
        status = _act_me(model, case)
        outcome.status = status
        logged = model.log[seen:]
        outcome.messages = [text for level, text in logged if level >= FMI2_DISCARD]
        if status != FMI2_ERROR:
            outcome.problems.append(f"status {status}, expected fmi2Error")
        if any(level == FMI2_FATAL for level, _ in logged):
            outcome.problems.append("a fatal status was logged")
        text = " ".join(outcome.messages)
        missing = [f for f in case.expect if f.lower() not in text.lower()]
        if missing:
            outcome.problems.append(f"the message does not say {missing}: {text!r}")
        after = model.reals()
        changed = [n for n, x in everything.items() if not (after[n] == x or (math.isnan(x) and math.isnan(after[n])))]
        if changed:
            outcome.problems.append(f"the refused call changed {', '.join(changed)}")
        if states is not None and model.states() != states:
            outcome.problems.append(f"the refused call changed the states: {states} -> {model.states()}")
        why = model.usable()
        if why:
            outcome.problems.append(why)
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += model.free()
        _LOG.pop(model.instance, None)
    return outcome


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


def _fmi3_cases() -> list[Case]:
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
                cases.append(_fmi3(fmu, sizes, "fmi3SetFloat64 of an event indicator", phase, interface,
                                   "fmi3SetFloat64", ("fmi3SetFloat64", "event indicator", "cannot be set"),
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
                                   (f"'{name}'", _declared(fmu, name).range_text()), "value", name, value))
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
            label, fragments = _STATE_EDITS[edit]
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

    _descriptions: dict[str, object] = {}

    def __init__(self, fmu: str, fmu_dir: Path, interface: str):
        import fmpy
        from fmpy.fmi3 import FMU3Model, FMU3Slave
        from harness.engine.component import unzipped as extracted
        from harness.paths import fmi3_dir

        path = fmi3_dir(fmu_dir) / f"{fmu}.fmu"
        if str(path) not in self._descriptions:
            self._descriptions[str(path)] = fmpy.read_model_description(str(path))
        self.md = self._descriptions[str(path)]
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.cs = interface == "CoSimulation3"
        self.nx, self.nz = ME_SIZES[fmu]
        self.instance = f"corpus3-{fmu}-{next(_counter)}"
        self.log: list[tuple[int, str]] = []
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

    def call(self, function: str, *args):
        """An fmpy method: its result, or the status it raised."""
        from fmpy.fmi1 import FMICallException
        try:
            getattr(self.fmu, function)(*args)
        except FMICallException as error:
            return error.status
        return FMI3_OK

    def _event_iteration(self) -> int:
        from fmpy.fmi1 import FMICallException
        for _ in range(100):
            try:
                if not self.fmu.updateDiscreteStates()[0]:
                    return FMI3_OK
            except FMICallException as error:
                return error.status
        return FMI3_ERROR

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
        """Every Float64 but the event indicators (a Co-Simulation instance has no value for them)."""
        names = [n for n, v in self.variables.items() if v.type == "Float64" and not n.startswith("event_indicator_")]
        from fmpy.fmi1 import FMICallException
        try:
            return dict(zip(names, self.fmu.getFloat64([self.variables[n].valueReference for n in names])))
        except FMICallException:
            return None

    def states(self) -> list | None:
        if self.cs or self.phase == "instantiated" or not self.nx:
            return None
        x = _array(self.nx)
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
        x, dx, z = _array(self.nx), _array(self.nx), _array(self.nz)
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
        try:
            self.fmu.freeInstance()
        except Exception as error:  # noqa: BLE001 - reported as the case's problem
            return [f"fmi3FreeInstance raised {error!r}"]
        return []




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
        array = _array(max(count, size, 1))
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
            data = data[:STATE3_HEADER] + _edited_state(data[STATE3_HEADER:], kind, case.fmu)
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
    if kind in ("unknown", "time", "indicator", "value"):
        vr = {"unknown": 999_999, "time": inst.variables["time"].valueReference,
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


def run_fmi3_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
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
        logged = inst.log[seen:]
        outcome.messages = [text for level, text in logged if level >= FMI3_DISCARD]
        if status != FMI3_ERROR:
            outcome.problems.append(f"status {status}, expected fmi3Error")
        if any(level == FMI3_FATAL for level, _ in logged):
            outcome.problems.append("a fatal status was logged")
        text = " ".join(outcome.messages)
        missing = [f for f in case.expect if f.lower() not in text.lower()]
        if missing:
            outcome.problems.append(f"the message does not say {missing}: {text!r}")
        if "fmi2" in text:
            outcome.problems.append(f"the message speaks of FMI 2.0 functions: {text!r}")
        after = inst.reals()
        if everything is not None:
            changed = [n for n, x in everything.items()
                       if after is None or not (after[n] == x or (math.isnan(x) and math.isnan(after[n])))]
            if changed:
                outcome.problems.append(f"the refused call changed {', '.join(changed[:5])}")
        if states is not None and inst.states() != states:
            outcome.problems.append(f"the refused call changed the states: {states} -> {inst.states()}")
        why = inst.usable()
        if why:
            outcome.problems.append(why)
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += inst.free()
    return outcome
