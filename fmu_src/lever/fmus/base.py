"""The FMI glue shared by our FMUs: a pythonfmu slave that declares its variables from
the physics' ``Parameter`` lists, refuses bad values with a logged error (never an
exception), tracks the FMI call sequence, saves and restores its complete state, and
writes a model description with units, ranges and output dependencies.

Why never raise: pythonfmu 0.7 turns any Python exception into fmi2Fatal and frees the
Python instance while keeping a dangling pointer to it, so an exception could crash the
importer on its next call.  Instead a refused call logs an error (the status shim that
our build puts in front of pythonfmu's library returns it as fmi2Error) and leaves the
instance usable.
"""
from __future__ import annotations

import functools
import json
import math
import operator
import re
import struct
import traceback
from pathlib import Path
from typing import NamedTuple, Sequence
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Boolean, Fmi2Slave, Real, Integer, String, Fmi2Causality, Fmi2Variability, Fmi2Initial
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from ..physics.parameters import DISPLAY_UNITS, QUANTITIES, UNITS, Parameter, ParameterError
from .. import __version__


class Output(NamedTuple):
    name: str
    unit: str
    description: str
    #: the output this one is the time derivative of (FMI's ``derivative`` attribute):
    #: lets a master predict connected outputs by Taylor expansion
    derivative_of: str = ""
    #: inputs this output depends on directly; None: all inputs if the model has direct
    #: feedthrough (``FEEDTHROUGH``), else none
    depends_on: tuple | None = None


class MechanicalPort(NamedTuple):
    """A rotational flange of the model, as the OSP Interface Specification describes it
    (``AngularMechanicalPort``: a torque and an angular velocity of opposite causality, a
    power bond), with the flange's angle beside it (``AngularDisplacement``: our compliant
    coupling needs angles as well as speeds)."""
    name: str
    torque: str
    angular_velocity: str
    angle: str
    description: str


def declared_type(spec) -> tuple[str, str, dict]:
    """The FMI type definition a declared variable refers to: (type name, FMI type
    element, attributes of that element)."""
    kind = getattr(spec, "kind", "real")
    if kind == "real":
        unit = spec.unit or "1"
        quantity = QUANTITIES[unit]
        attrs = {"quantity": quantity}
        if unit != "1":
            attrs["unit"] = unit
            if unit in DISPLAY_UNITS:
                attrs["displayUnit"] = DISPLAY_UNITS[unit]
        return quantity, "Real", attrs
    if kind == "integer":
        return _camel(spec.name), "Integer", {"quantity": _camel(spec.name)}
    if spec.choices:
        return _camel(spec.name), "String", {}
    return "PointTable", "String", {}


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


def guarded(default=None):
    """Run an FMI entry point so that no exception escapes: it is logged as an error
    naming the call, and ``default`` (or ``default(self, *args)`` when callable) is
    returned instead."""

    def wrap(method):
        @functools.wraps(method)
        def call(self, *args):
            try:
                return method(self, *args)
            except ParameterError as error:
                self._error(f"{method.__name__}: {error}")
            except Exception as error:  # noqa: BLE001 - the importer must survive anything
                where = traceback.extract_tb(error.__traceback__)[-1]
                self._error(f"{method.__name__}: internal error {type(error).__name__}: {error} "
                            f"(at {where.name}, line {where.lineno})")
            return default(self, *args) if callable(default) else default

        return call

    return wrap


class _OwnState(dict):
    """A state an instance took itself (``fmi2GetFMUstate``), with the model and GUID
    its serialized form carries in its header."""
    __slots__ = ("owner", "model", "guid")


class _SerializedState:
    """Bytes given to ``fmi2DeSerializeFMUstate``, kept as they are: pythonfmu calls the
    deserializer on the class, where nothing can be logged and an exception is fatal, so
    they are judged (header, then content) by ``fmi2SetFMUstate`` on the instance."""
    __slots__ = ("data",)

    def __init__(self, data: bytes):
        self.data = data


#: A serialized state: ``STATE_MAGIC``, a space, a JSON header (format, model, GUID,
#: length of the payload), a newline, the payload (JSON of the state).
STATE_MAGIC = b"lever-fmu-state"
#: The native entry (build/shim) keeps the state machine's state and the time in its own
#: header and passes them in front of the bytes as ``SHIM_FRAME <state bit> <the time's 64
#: bits in hex>``: the state is refused unless they agree with its phase and time.
SHIM_FRAME = b"lever-shim-frame"
_SHIM_PHASES = {1: ("instantiated",), 2: ("initialization",), 4: ("stepping",), 8: ("stepping",),
                16: ("terminated",)}
STATE_FORMAT = 1
_HEADER_LIMIT = 1024     # bytes the header line may take
_NESTING_LIMIT = 4       # a state is {"variables": {...}, "internal": {"y": [...]}}


def _nesting(data: bytes) -> int:
    """The deepest nesting of JSON arrays and objects in ``data`` (strings skipped):
    judged before parsing, so deeply nested bytes never reach the recursive parser."""
    depth = deepest = 0
    in_string = escaped = False
    for byte in data:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:          # backslash
                escaped = True
            elif byte == 0x22:          # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):      # [ {
            depth += 1
            deepest = max(deepest, depth)
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return deepest


_GUIDS: dict[str, str] = {}


def _guid_of(resources) -> str:
    """The GUID in the model description of the unpacked FMU whose resources folder is
    ``resources`` ("" where there is none to read: the model run outside an FMU)."""
    key = str(resources or "")
    if key not in _GUIDS:
        guid = ""
        if key:
            try:
                text = (Path(key).parent / "modelDescription.xml").read_text(encoding="utf-8", errors="replace")
                found = re.search(r'\bguid\s*=\s*"([^"]*)"', text)
                guid = found.group(1) if found else ""
            except (OSError, ValueError):
                pass
        _GUIDS[key] = guid
    return _GUIDS[key]


def _nan_values(self, vrs):
    return [math.nan] * len(vrs)


# What must be recomputed before outputs are read (``LeverSlave._dirty``).
_CLEAN = 0
_INPUTS_CHANGED = 1      # only outputs that depend on inputs (``_compute_input_outputs``)
_ALL = 2                 # everything: time, state or model changed
_LIVE = ("initialization", "stepping")


class LeverSlave(Fmi2Slave):
    """Base of our FMUs.  Subclasses declare

    * ``PARAMETERS``: structural parameters (``Parameter``), fixed after initialisation;
    * ``INPUTS``: real inputs (``Parameter``, range checked at every set);
    * ``OUTPUTS``: real outputs (``Output``);
    * ``FEEDTHROUGH``: whether outputs depend directly on inputs;

    and implement ``_build()`` (make the physics from the parameters; raise
    ParameterError when they do not fit together), ``_compute_outputs()`` and
    ``_advance(t, h)`` (return None on success or a message why the step failed).
    """

    PARAMETERS: Sequence[Parameter] = ()
    INPUTS: Sequence[Parameter] = ()
    OUTPUTS: Sequence[Output] = ()
    FEEDTHROUGH = False
    DESCRIPTION = ""
    #: the model's equations, one per line, for its documentation
    EQUATIONS: Sequence[str] = ()
    #: rotational flanges (``MechanicalPort``), for the OSP model description
    PORTS: Sequence[MechanicalPort] = ()

    author = "lever-cosim project"
    license = "MIT"
    version = __version__
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0, step_size=1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = self.DESCRIPTION
        self._phase = "instantiated"   # -> initialization -> stepping (-> terminated)
        self._time = 0.0
        self._start_time = 0.0         # fmi2SetupExperiment's: the scale of the host's time rounding
        self._dirty = _ALL             # what must be recomputed before outputs are read
        self._build_error = None
        self._declared = {}
        for p in self.PARAMETERS:
            self._declare(p, Fmi2Causality.parameter)
        for p in self.INPUTS:
            self._declare(p, Fmi2Causality.input)
        for o in self.OUTPUTS:
            setattr(self, o.name, 0.0)
            self.register_variable(Real(o.name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated, description=o.description))
            self._declared[o.name] = o
        # value reference -> the declared parameter or input it sets (nothing else may be
        # set: FMI 2.0 allows fmi2Set* on parameters and inputs only)
        self._settable = {vr: self._declared[v.name] for vr, v in self.vars.items()
                          if isinstance(self._declared.get(v.name), Parameter)}
        self._built_with = None        # the parameter values the model was built with
        # The hot path, mapped once: value reference -> attribute name of each Real, and
        # of each real input its name and closed bounds (open ones moved in by an ulp), so
        # that a good value costs one comparison; anything else takes _set_values's path,
        # which says what is wrong.
        self._real_names = {vr: v.name for vr, v in self.vars.items() if isinstance(v, Real)}
        self._fast_inputs = {}
        for vr, p in self._settable.items():
            if p.kind == "real" and not p.fixed:
                low = math.nextafter(p.low, math.inf) if p.low_open else p.low
                high = math.nextafter(p.high, -math.inf) if p.high_open else p.high
                self._fast_inputs[vr] = (p.name, low, high)
        self._outputs_of = operator.attrgetter(*(o.name for o in self.OUTPUTS)) if self.OUTPUTS else None

    # -- declaration ----------------------------------------------------------------------
    def _declare(self, p: Parameter, causality):
        setattr(self, p.name, p.default)
        kind = {"real": Real, "integer": Integer, "string": String}[p.kind]
        if causality == Fmi2Causality.parameter:
            variability = Fmi2Variability.fixed
        else:
            variability = Fmi2Variability.continuous
        self.register_variable(kind(p.name, causality=causality, variability=variability, start=p.default,
                                    description=p.description))
        self._declared[p.name] = p

    _KINDS = {Real: "Real", Integer: "Integer", String: "String", Boolean: "Boolean"}

    def _set_values(self, call: str, kind, vrs, values):
        """``fmi2Set<kind>``: every value is judged first - the variable exists, is of
        that type, may be set in this state (FMI 2.0 CS: parameters before the end of
        initialisation, inputs also while stepping, nothing after fmi2Terminate), lies in
        its range - and applied only when all are good: a refused call changes nothing."""
        if len(vrs) != len(values):
            self._error(f"{call}: {len(vrs)} value references but {len(values)} values; nothing was applied")
            return
        checked = []
        for vr, value in zip(vrs, values):
            var = self.vars.get(vr)
            if var is None:
                self._error(f"{call}: value reference {vr} is no variable of {type(self).__name__}; "
                            "nothing of this call was applied")
                return
            if not isinstance(var, kind):
                self._error(f"{call}: '{var.name}' (value reference {vr}) is a {self._KINDS[type(var)]} variable; "
                            "nothing of this call was applied")
                return
            p = self._settable.get(vr)
            if p is None:
                causality = var.causality.name
                self._error(f"{call}: '{var.name}' is {'an' if causality[0] in 'aeiou' else 'a'} {causality} "
                            f"({var.variability.name}) and cannot be "
                            "set (FMI 2.0 lets an importer set parameters and inputs only); the value "
                            f"{value!r} was not applied, nor anything else of this call")
                return
            if self._phase == "terminated":
                self._error(f"{call}: '{p.name}' cannot be set after fmi2Terminate (the value {value!r} was not "
                            "applied)")
                return
            if p.fixed and self._phase not in ("instantiated", "initialization"):
                self._error(f"parameter '{p.name}' is fixed: it cannot be changed after initialisation "
                            f"(the value {value!r} was not applied, nor anything else of this call)")
                return
            try:
                checked.append((p, p.check(value)))
            except ParameterError as error:
                self._error(f"{error}; the value was not applied, '{p.name}' stays {getattr(self, p.name)!r} "
                            "(nor was anything else of this call)")
                return
        for p, value in checked:
            setattr(self, p.name, value)
            if p.fixed:
                self._model_stale = True
        self._dirty = _ALL if any(p.fixed for p, _ in checked) else max(self._dirty, _INPUTS_CHANGED)

    def _error(self, message: str):
        self.log(message, Fmi2Status.error)

    def _values(self) -> dict:
        return {p.name: getattr(self, p.name) for p in self.PARAMETERS}

    # -- FMI entry points -----------------------------------------------------------------
    @guarded()
    def enter_initialization_mode(self):
        if self._phase != "instantiated":
            self._error(f"fmi2EnterInitializationMode called in phase '{self._phase}'")
            return
        self._phase = "initialization"
        # Build for outputs read during initialisation, but judge the parameters only at
        # exit: the importer may still correct them (FMI 2.0: fmi2Error is final).
        self._try_build(report=False)

    @guarded()
    def exit_initialization_mode(self):
        if self._phase != "initialization":
            self._error(f"fmi2ExitInitializationMode called in phase '{self._phase}' "
                        "(expected after fmi2EnterInitializationMode)")
            return
        if self._model_stale or self._build_error:
            self._try_build()
        if self._build_error:
            self._error(f"the model cannot be initialised: {self._build_error}")
            return
        self._refresh()
        self._phase = "stepping"

    @guarded()
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if not math.isfinite(start_time):
            self._error(f"fmi2SetupExperiment: start time {start_time} is not finite")
            return
        self._time = self._start_time = float(start_time)

    @guarded(default=False)
    def do_step(self, current_time, step_size):
        if self._phase != "stepping":
            self._error(f"fmi2DoStep called in phase '{self._phase}': the FMU must be initialised first "
                        "(fmi2EnterInitializationMode, fmi2ExitInitializationMode)")
            return False
        if not (math.isfinite(step_size) and step_size > 0.0):
            self._error(f"fmi2DoStep: communication step size {step_size} must be finite and > 0")
            return False
        if not (math.isfinite(current_time) and abs(current_time - self._time) <= self._rounding()):
            self._error(f"fmi2DoStep: current communication point {current_time!r} does not match the FMU's "
                        f"time {self._time!r} (off by {current_time - self._time:.3g} s, more than the "
                        f"{self._rounding():.3g} s that rounding of the host's time explains: steps must be "
                        "contiguous; restore a saved state to go back)")
            return False
        failure = self._advance(current_time, step_size)
        if failure:
            self._error(f"fmi2DoStep at t = {current_time:.9g} s, h = {step_size:.3g} s: {failure}")
            return False
        self._time = current_time + step_size
        self._dirty = _ALL
        return True

    #: ulps of the time's magnitude a host's communication point may differ from the FMU's:
    #: a host that computes its points as t0 + k*h, from an integer-nanosecond clock, or by
    #: t += h differs by a few roundings (at most 5 ulps of max(|t|, |t0|)), never by a step
    ROUNDING_ULPS = 8

    def _rounding(self) -> float:
        """How far a communication point may lie from the FMU's time (rounding only)."""
        return self.ROUNDING_ULPS * math.ulp(max(abs(self._time), abs(self._start_time)))

    @guarded()
    def terminate(self):
        self._phase = "terminated"

    @guarded(default=_nan_values)
    def get_real(self, vrs):
        if self._dirty and self._phase in _LIVE:
            self._refresh()
        names = self._real_names
        try:
            return [float(getattr(self, names[vr])) for vr in vrs]
        except KeyError:
            unknown = next(vr for vr in vrs if vr not in names)
            self._error(f"fmi2GetReal: value reference {unknown} is no Real variable of {type(self).__name__}")
            return _nan_values(self, vrs)

    @guarded()
    def set_real(self, vrs, values):
        # The hot path: inputs in range while the FMU runs, applied without further ado;
        # anything else is judged (and refused with its reason) by _set_values.
        fast = self._fast_inputs
        if self._phase != "terminated" and len(vrs) == len(values):
            for vr, x in zip(vrs, values):
                entry = fast.get(vr)
                if entry is None or not entry[1] <= x <= entry[2]:
                    break
            else:
                for vr, x in zip(vrs, values):
                    setattr(self, fast[vr][0], x)
                if not self._dirty:
                    self._dirty = _INPUTS_CHANGED
                return
        self._set_values("fmi2SetReal", Real, vrs, values)

    @guarded(default=_nan_values)
    def get_integer(self, vrs):
        return super().get_integer(vrs)

    @guarded()
    def set_integer(self, vrs, values):
        self._set_values("fmi2SetInteger", Integer, vrs, values)

    @guarded(default=lambda self, vrs: [""] * len(vrs))
    def get_string(self, vrs):
        return super().get_string(vrs)

    @guarded()
    def set_string(self, vrs, values):
        self._set_values("fmi2SetString", String, vrs, values)

    @guarded(default=lambda self, vrs: [False] * len(vrs))
    def get_boolean(self, vrs):
        return super().get_boolean(vrs)

    @guarded()
    def set_boolean(self, vrs, values):
        self._set_values("fmi2SetBoolean", Boolean, vrs, values)

    # -- model construction and outputs -----------------------------------------------------
    _model_stale = True

    def _try_build(self, report: bool = True, reset: bool = True):
        """Build the physics from the parameters; ``reset`` also puts the state to its
        start values (not when a saved state is being restored)."""
        try:
            self._build()
            if reset:
                self._reset_state()
            self._build_error = None
            self._built_with = self._values()
        except ParameterError as error:
            self._build_error = str(error)
            self._built_with = None
            if report:
                self._error(str(error))
        self._model_stale = False
        self._dirty = _ALL

    def _refresh(self):
        if self._build_error is None and not self._model_stale:
            if self._dirty == _ALL:
                self._compute_outputs()
            else:
                self._compute_input_outputs()
            self._dirty = _CLEAN
            # One test for all outputs: their sum is finite unless one is not (or the sum
            # overflows, which the test below sorts out).
            if self._outputs_of is None:
                return
            total = sum(self._outputs_of(self)) if len(self.OUTPUTS) > 1 else self._outputs_of(self)
            if total - total == 0.0:
                return
            bad = [o.name for o in self.OUTPUTS if not math.isfinite(getattr(self, o.name))]
            if bad:
                # Reported at every read until the inputs change: never a silent NaN.
                self._dirty = _ALL
                inputs = ", ".join(f"{p.name} = {getattr(self, p.name)!r}" for p in self.INPUTS)
                self._error(f"output(s) {', '.join(bad)} are not finite at t = {self._time!r} s with inputs "
                            f"{inputs}: the inputs are beyond what the model can represent")

    def _build(self):
        raise NotImplementedError

    def _reset_state(self):
        """Put the model's state to its start values (stateless models: nothing)."""

    def _compute_outputs(self):
        raise NotImplementedError

    def _compute_input_outputs(self):
        """Recompute what depends on the inputs after only they changed (default: all)."""
        self._compute_outputs()

    def _advance(self, t, h):
        raise NotImplementedError

    # -- state: everything needed to continue exactly ---------------------------------------
    def _internal_state(self) -> dict:
        return {}

    def _internal_problem(self, internal) -> str | None:
        """Why ``internal`` (from a serialized state) is not this model's internal state."""
        return None if internal == {} else f"internal state {internal!r} where this model keeps none"

    def _restore_internal_state(self, state: dict):
        pass

    def _guid(self) -> str:
        return _guid_of(self.resources)

    @guarded(default=dict)
    def _get_fmu_state(self):
        state = _OwnState(
            time=self._time,
            phase=self._phase,
            variables={name: getattr(self, name) for name in self._declared},
            internal=self._internal_state(),
        )
        state.owner, state.model, state.guid = self, type(self).__name__, self._guid()
        return state

    def _parse_serialized(self, data: bytes) -> tuple[dict | None, str | None]:
        """(state, None) from serialized bytes, or (None, why they are no state of this FMU);
        behind the native entry, the state must agree with the entry's header."""
        if not data.startswith(SHIM_FRAME + b" "):
            return self._parse_model_state(data)
        end = data.find(b"\n", 0, 128)
        if end < 0:
            return None, "the native entry's frame is not terminated (truncated or malformed)"
        try:
            bit, bits = data[len(SHIM_FRAME) + 1:end].decode("ascii").split(" ")
            bit, time = int(bit), struct.unpack("<d", struct.pack("<Q", int(bits, 16)))[0]
        except (UnicodeDecodeError, ValueError, struct.error):
            return None, "the native entry's frame does not decode"
        state, problem = self._parse_model_state(data[end + 1:])
        if problem is None:
            problem = self._state_problem(state)
        if problem is None and (state["phase"] not in _SHIM_PHASES.get(bit, ()) or state["time"] != time):
            problem = (f"its parts disagree: the native entry's header says state {bit} ("
                       f"{'/'.join(_SHIM_PHASES.get(bit, ('unknown',)))}) at t = {time!r} s, the model's part "
                       f"phase {state['phase']!r} at t = {state['time']!r} s (damaged or edited bytes)")
        return (None, problem) if problem else (state, None)

    def _parse_model_state(self, data: bytes) -> tuple[dict | None, str | None]:
        if not data.startswith(STATE_MAGIC + b" "):
            return None, f"the bytes do not start with {STATE_MAGIC.decode()!r} (not a serialized state of a lever FMU)"
        end = data.find(b"\n", 0, _HEADER_LIMIT)
        if end < 0:
            return None, f"the state's header is not terminated within {_HEADER_LIMIT} bytes (truncated or malformed)"
        try:
            header = json.loads(data[len(STATE_MAGIC) + 1:end].decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as error:
            return None, f"the state's header does not decode ({type(error).__name__}: {error})"
        if not (isinstance(header, dict) and set(header) == {"format", "model", "guid", "length"}):
            return None, f"the state's header {header!r} lacks format, model, guid or length"
        if header["format"] != STATE_FORMAT:
            return None, f"state format {header['format']!r}; this FMU reads format {STATE_FORMAT}"
        if header["model"] != type(self).__name__:
            return None, f"not a state of {type(self).__name__}: it is a state of {header['model']!r}"
        guid = self._guid()
        if header["guid"] and guid and header["guid"] != guid:
            return None, (f"not a state of this build of {type(self).__name__}: GUID {header['guid']!r}, "
                          f"this FMU's is {guid!r}")
        payload = data[end + 1:]
        if header["length"] != len(payload):
            return None, (f"the state's header announces {header['length']!r} bytes of content, "
                          f"{len(payload)} follow (truncated or padded)")
        if _nesting(payload) > _NESTING_LIMIT:
            return None, f"the state's content is nested deeper than {_NESTING_LIMIT} levels"
        try:
            return json.loads(payload.decode("utf-8")), None
        except (UnicodeDecodeError, ValueError, RecursionError) as error:
            return None, f"the state's content does not decode ({type(error).__name__}: {error})"

    def _state_problem(self, state) -> str | None:
        """Why ``state`` is not a complete, valid state of this FMU (None when it is one):
        every part is judged before anything is applied."""
        if not isinstance(state, dict) or set(state) != {"time", "phase", "variables", "internal"}:
            return "not a state of this FMU (it needs time, phase, variables and internal)"
        variables = state["variables"]
        if not isinstance(variables, dict) or set(variables) != set(self._declared):
            names = set(variables) if isinstance(variables, dict) else set()
            return (f"not a state of {type(self).__name__}: its variables differ (unknown: "
                    f"{', '.join(sorted(map(str, names - set(self._declared)))) or '-'}; missing: "
                    f"{', '.join(sorted(set(self._declared) - names)) or '-'})")
        if state["phase"] not in ("instantiated", "initialization", "stepping", "terminated"):
            return f"not a state of this FMU: unknown phase {state['phase']!r}"
        if not (type(state["time"]) is float and math.isfinite(state["time"])):
            return f"not a state of this FMU: time {state['time']!r} is not a finite number"
        for name, spec in self._declared.items():
            value = variables[name]
            kind = getattr(spec, "kind", "real")
            if type(value) not in {"real": (float, int), "integer": (int,), "string": (str,)}[kind]:
                return f"not a state of this FMU: '{name}' = {value!r} is not a{'n' if kind == 'integer' else ''} {kind}"
            message = spec.problem(value) if isinstance(spec, Parameter) else (
                None if math.isfinite(value) else f"output '{name}' = {value!r} is not finite")
            if message:
                return f"not a state of this FMU: {message}"
        return self._internal_problem(state["internal"])

    @guarded()
    def _set_fmu_state(self, state):
        # A state this instance took is one; anything else (another instance's, or
        # deserialized bytes) is judged completely first.  An iterating master restores
        # its own state on every step: the check would cost a fifth of the restore.
        own = type(state) is _OwnState and state.owner is self
        if not own:
            problem = None
            if isinstance(state, _SerializedState):
                state, problem = self._parse_serialized(state.data)
            elif type(state) is _OwnState and state.model != type(self).__name__:
                problem = f"not a state of {type(self).__name__}: it is a state of {state.model!r}"
            problem = problem or self._state_problem(state)
            if problem:
                self._error(f"fmi2SetFMUstate: {problem}; the FMU's state is unchanged")
                return
        elif state["phase"] == self._phase == "stepping" and not self._model_stale and self._build_error is None:
            # Its own state while stepping: the parameters are fixed since, the model was
            # built for them and nothing can fail (an iterating master's every step).
            for name, value in state["variables"].items():
                setattr(self, name, value)
            self._time = state["time"]
            self._restore_internal_state(state["internal"])
            self._dirty = _ALL
            return
        # Applied as one transaction: should the model not build from the state's
        # parameters, the instance is put back as it was.
        before = dict(self.__dict__)
        try:
            for name, value in state["variables"].items():
                setattr(self, name, value)
            self._time = state["time"]
            self._phase = state["phase"]
            if self._phase != "instantiated" and (self._model_stale or self._build_error is not None
                                                   or self._built_with != self._values()):
                self._try_build(report=False, reset=False)
                if self._build_error is not None:
                    raise ParameterError("state", self._build_error)
            self._restore_internal_state(state["internal"])
        except Exception as error:
            self.__dict__.clear()
            self.__dict__.update(before)
            why = str(error) if isinstance(error, ParameterError) else f"{type(error).__name__}: {error}"
            self._error(f"fmi2SetFMUstate: the model does not build from the state ({why}); the FMU's state "
                        "is unchanged")
            return
        self._dirty = _ALL

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        # repr-exact floats: a restored state continues bit-identically.
        payload = json.dumps(state, allow_nan=True).encode("utf-8")     # judged when restored
        header = json.dumps({"format": STATE_FORMAT, "model": getattr(state, "model", ""),
                             "guid": getattr(state, "guid", ""), "length": len(payload)})
        return STATE_MAGIC + b" " + header.encode("utf-8") + b"\n" + payload

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        return _SerializedState(bytes(data))

    # -- model description -----------------------------------------------------------------
    @classmethod
    def dependencies(cls, output: Output) -> list[str]:
        """The inputs ``output`` depends on directly (its ``depends_on``, else all inputs
        with direct feedthrough, none without)."""
        if output.depends_on is not None:
            return list(output.depends_on)
        return [p.name for p in cls.INPUTS] if cls.FEEDTHROUGH else []

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus what it leaves out: units (with display units),
        min/max of parameters and inputs, and the output dependencies (outputs depend on
        the inputs only where the element has direct feedthrough)."""
        root = super().to_xml(model_options or {})
        used = sorted({spec.unit for spec in self._declared.values() if spec.unit not in ("", "1")})
        units = Element("UnitDefinitions")
        for name in used:
            exponents, _ = UNITS[name]
            unit = SubElement(units, "Unit", {"name": name})
            SubElement(unit, "BaseUnit", {k: str(v) for k, v in exponents.items()})
            if name in DISPLAY_UNITS:
                display = DISPLAY_UNITS[name]
                SubElement(unit, "DisplayUnit", {"name": display, "factor": repr(1.0 / UNITS[display][1])})
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, units)
        # One type definition per quantity (and per kind of string), as the Reference-FMUs
        # do; every variable refers to its type.
        types = Element("TypeDefinitions")
        seen = {}
        for spec in self._declared.values():
            name, element, attrs = declared_type(spec)
            if name in seen:
                continue
            seen[name] = True
            description = {"PointTable": "a table of points as text, 'x:y; x:y; ...'"}.get(name)
            if getattr(spec, "choices", None):
                description = "one of " + ", ".join(repr(c) for c in spec.choices)
            simple = SubElement(types, "SimpleType", {"name": name, **({"description": description}
                                                                        if description else {})})
            SubElement(simple, element, attrs)
        root.insert(position + 1, types)

        nodes = root.find("ModelVariables").findall("ScalarVariable")
        index_of = {node.get("name"): i for i, node in enumerate(nodes, start=1)}
        for node in nodes:
            name = node.get("name")
            spec = self._declared.get(name)
            typed = node[0]
            if spec is None:
                continue
            typed.set("declaredType", declared_type(spec)[0])
            if typed.tag not in ("Real", "Integer"):
                continue
            if typed.tag == "Real" and spec.unit not in ("", "1"):
                typed.set("unit", spec.unit)
                if spec.unit in DISPLAY_UNITS:
                    typed.set("displayUnit", DISPLAY_UNITS[spec.unit])
            if getattr(spec, "derivative_of", ""):
                typed.set("derivative", str(index_of[spec.derivative_of]))
            if isinstance(spec, Parameter):
                # FMI's min and max are inclusive: an open bound is declared as the nearest
                # double inside it, so that the declaration says exactly what is accepted
                as_text = repr if typed.tag == "Real" else (lambda x: str(int(x)))
                if math.isfinite(spec.low):
                    typed.set("min", as_text(math.nextafter(spec.low, math.inf) if spec.low_open else spec.low))
                if math.isfinite(spec.high):
                    typed.set("max", as_text(math.nextafter(spec.high, -math.inf) if spec.high_open else spec.high))

        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outputs = SubElement(structure, "Outputs")
        initial = SubElement(structure, "InitialUnknowns")
        for o in self.OUTPUTS:
            sources = self.dependencies(o)
            attrs = {"index": str(index_of[o.name]), "dependencies": " ".join(str(index_of[n]) for n in sources)}
            if sources:
                attrs["dependenciesKind"] = " ".join("dependent" for _ in sources)
            SubElement(outputs, "Unknown", attrs)
            SubElement(initial, "Unknown", dict(attrs))
        return root
