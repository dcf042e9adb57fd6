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
import traceback
from typing import NamedTuple, Sequence
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Slave, Real, Integer, String, Fmi2Causality, Fmi2Variability, Fmi2Initial
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
    """A state an instance took itself (``fmi2GetFMUstate``); deserialized bytes become a
    plain dict and are validated before they are restored."""
    __slots__ = ("owner",)


def _nan_values(self, vrs):
    return [math.nan] * len(vrs)


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
        self._dirty = True             # outputs must be recomputed before they are read
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

    # -- declaration ----------------------------------------------------------------------
    def _declare(self, p: Parameter, causality):
        setattr(self, p.name, p.default)
        kind = {"real": Real, "integer": Integer, "string": String}[p.kind]
        if causality == Fmi2Causality.parameter:
            variability = Fmi2Variability.fixed
        else:
            variability = Fmi2Variability.continuous
        self.register_variable(kind(p.name, causality=causality, variability=variability, start=p.default,
                                    description=p.description, setter=self._setter(p)))
        self._declared[p.name] = p

    def _setter(self, p: Parameter):
        def set_value(value):
            if p.fixed and self._phase not in ("instantiated", "initialization"):
                self._error(f"parameter '{p.name}' is fixed: it cannot be changed after initialisation "
                            f"(the value {value!r} was not applied)")
                return
            # check() judges and converts in one pass: this runs at every input set of every step
            try:
                checked = p.check(value)
            except ParameterError as error:
                self._error(f"{error}; the value was not applied, '{p.name}' stays {getattr(self, p.name)!r}")
                return
            setattr(self, p.name, checked)
            self._dirty = True
            if p.fixed:
                self._model_stale = True

        return set_value

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
        self._time = float(start_time)

    @guarded(default=False)
    def do_step(self, current_time, step_size):
        if self._phase != "stepping":
            self._error(f"fmi2DoStep called in phase '{self._phase}': the FMU must be initialised first "
                        "(fmi2EnterInitializationMode, fmi2ExitInitializationMode)")
            return False
        if not (math.isfinite(step_size) and step_size > 0.0):
            self._error(f"fmi2DoStep: communication step size {step_size} must be finite and > 0")
            return False
        tolerance = 1e-9 * max(1.0, abs(self._time))
        if not (math.isfinite(current_time) and abs(current_time - self._time) <= tolerance):
            self._error(f"fmi2DoStep: current communication point {current_time!r} does not match the FMU's "
                        f"time {self._time!r} (steps must be contiguous; restore a saved state to go back)")
            return False
        failure = self._advance(current_time, step_size)
        if failure:
            self._error(f"fmi2DoStep at t = {current_time:.9g} s, h = {step_size:.3g} s: {failure}")
            return False
        self._time = current_time + step_size
        self._dirty = True
        return True

    @guarded()
    def terminate(self):
        self._phase = "terminated"

    @guarded(default=_nan_values)
    def get_real(self, vrs):
        if self._dirty and self._phase in ("initialization", "stepping"):
            self._refresh()
        return super().get_real(vrs)

    @guarded()
    def set_real(self, vrs, values):
        super().set_real(vrs, values)

    @guarded(default=_nan_values)
    def get_integer(self, vrs):
        return super().get_integer(vrs)

    @guarded()
    def set_integer(self, vrs, values):
        super().set_integer(vrs, values)

    @guarded(default=lambda self, vrs: [""] * len(vrs))
    def get_string(self, vrs):
        return super().get_string(vrs)

    @guarded()
    def set_string(self, vrs, values):
        super().set_string(vrs, values)

    @guarded(default=lambda self, vrs: [False] * len(vrs))
    def get_boolean(self, vrs):
        return super().get_boolean(vrs)

    @guarded()
    def set_boolean(self, vrs, values):
        super().set_boolean(vrs, values)

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
        except ParameterError as error:
            self._build_error = str(error)
            if report:
                self._error(str(error))
        self._model_stale = False
        self._dirty = True

    def _refresh(self):
        if self._build_error is None and not self._model_stale:
            self._compute_outputs()
            self._dirty = False
            bad = [o.name for o in self.OUTPUTS if not math.isfinite(getattr(self, o.name))]
            if bad:
                # Reported at every read until the inputs change: never a silent NaN.
                self._dirty = True
                inputs = ", ".join(f"{p.name} = {getattr(self, p.name)!r}" for p in self.INPUTS)
                self._error(f"output(s) {', '.join(bad)} are not finite at t = {self._time!r} s with inputs "
                            f"{inputs}: the inputs are beyond what the model can represent")

    def _build(self):
        raise NotImplementedError

    def _reset_state(self):
        """Put the model's state to its start values (stateless models: nothing)."""

    def _compute_outputs(self):
        raise NotImplementedError

    def _advance(self, t, h):
        raise NotImplementedError

    # -- state: everything needed to continue exactly ---------------------------------------
    def _internal_state(self) -> dict:
        return {}

    def _restore_internal_state(self, state: dict):
        pass

    @guarded(default=dict)
    def _get_fmu_state(self):
        state = _OwnState(
            time=self._time,
            phase=self._phase,
            variables={name: getattr(self, name) for name in self._declared},
            internal=self._internal_state(),
        )
        state.owner = self
        return state

    def _state_problem(self, state) -> str | None:
        """Why ``state`` is not a state of this FMU (None when it is one)."""
        if isinstance(state, dict) and "not_a_state" in state:
            return f"not a state of this FMU: {state['not_a_state']}"
        if not isinstance(state, dict) or set(state) != {"time", "phase", "variables", "internal"}:
            return "not a state of this FMU"
        variables = state["variables"]
        if not isinstance(variables, dict) or set(variables) != set(self._declared):
            names = set(variables) if isinstance(variables, dict) else set()
            return (f"not a state of {type(self).__name__}: its variables differ (unknown: "
                    f"{', '.join(sorted(names - set(self._declared))) or '-'}; missing: "
                    f"{', '.join(sorted(set(self._declared) - names)) or '-'})")
        if state["phase"] not in ("instantiated", "initialization", "stepping", "terminated"):
            return f"not a state of this FMU: unknown phase {state['phase']!r}"
        if not (isinstance(state["time"], float) and math.isfinite(state["time"])):
            return f"not a state of this FMU: time {state['time']!r} is not a finite number"
        for p in self.PARAMETERS:
            message = p.problem(variables[p.name])
            if message:
                return f"not a state of this FMU: {message}"
        return None

    @guarded()
    def _set_fmu_state(self, state):
        # A state this instance took is one; anything else (deserialized bytes) is checked.
        # An iterating master restores a state on every step: the check would cost a
        # fifth of the restore.
        own = type(state) is _OwnState and state.owner is self
        problem = None if own else self._state_problem(state)
        if problem:
            self._error(f"fmi2SetFMUstate: {problem}; the FMU's state is unchanged")
            return
        parameters_changed = any(getattr(self, p.name) != state["variables"].get(p.name)
                                 for p in self.PARAMETERS)
        for name, value in state["variables"].items():
            setattr(self, name, value)
        self._time = state["time"]
        self._phase = state["phase"]
        if parameters_changed:
            self._try_build(reset=False)
        self._restore_internal_state(state["internal"])
        self._dirty = True

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        # repr-exact floats: a restored state continues bit-identically.
        return json.dumps(state, allow_nan=True).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        # pythonfmu calls this on the class, where nothing can be logged, and turns an
        # exception into fmi2Fatal: bytes that are no state become a marker that
        # fmi2SetFMUstate refuses with a message (fmi2Error) instead.
        try:
            return json.loads(bytes(data).decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as error:
            return {"not_a_state": f"the bytes given to fmi2DeSerializeFMUstate do not decode "
                                   f"({type(error).__name__}: {error})"}

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
                as_text = repr if typed.tag == "Real" else (lambda x: str(int(x)))
                if math.isfinite(spec.low):
                    typed.set("min", as_text(spec.low))
                if math.isfinite(spec.high):
                    typed.set("max", as_text(spec.high))

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
