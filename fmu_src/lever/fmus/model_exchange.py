"""FMI 2.0 Model Exchange for our FMUs, from the physics' Model Exchange interface
(``lever.physics.me_base``): the states, their derivatives, the event indicators, the
event updates and the analytic partials that ``fmi2GetDirectionalDerivative`` multiplies.

pythonfmu 0.7 exports Co-Simulation only, so the native entry (build/shim) implements the
Model Exchange functions and their state machine itself and reaches the model through
pythonfmu's ``fmi2GetReal``/``fmi2SetReal`` on value references of its own, at and above
``CHANNEL`` (far above any variable's): pythonfmu passes value references through
untouched, and the entry refuses such references from a host, so only it uses them.  A
reference there is ``CHANNEL + (kind << 20) + index``; every ME call is one such get or
set, and errors are logged like any other (fmi2Error, the instance usable).

Directional derivatives are the physics' partials, analytic: those of the physics' model's
outputs and derivatives (``partials``), and for an FMU output beyond them (the freewheel's
torques, flags and energies) the model's ``named_partials``; an output with neither is
refused with fmi2Error and a sentence, never approximated.  The explicit time part of
``fmi3GetOutputDerivatives`` is a central difference in time (``_time_partials``) with a
step independent of the time itself.

A model declares its continuous states (``StateVariable``: an output of the FMU or a local
variable declared here, and the variable holding its derivative), the number of event
indicators, and the parameter sets whose models together show every dependency the model
can have (the model description is one for all parameter values).
"""
from __future__ import annotations

import ctypes
import math
from operator import attrgetter
from typing import Callable, NamedTuple, Sequence
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Variability, Integer, Real

from ..physics.me_base import der
from ..physics.parameters import DISPLAY_UNITS, ParameterError
from .base import LeverSlave, _nan_values
from .declarations import Output
from .guard import guarded
from .model_description import camel_case, declared_type, define_unit
from .recompute import ALL, CLEAN, INPUTS_CHANGED

CHANNEL = 0x40000000
KIND_SHIFT = 20
INDEX_MASK = (1 << KIND_SHIFT) - 1
# kinds of channel references
(CONTROL, STATES, DERIVATIVES, INDICATORS, NOMINALS, SEEDS, DIRECTIONAL, EVENT_INFO, OUTPUT_RATES, INPUT_TABLE,
 STATE_OUTPUT_TABLE) = range(11)
# CONTROL set: the interface (1: Model Exchange), the time, a command, the address of the
# native entry's point block (0: none), a sync (nothing but the point block taken); get: the sizes
SET_INTERFACE, SET_TIME, SET_COMMAND, SET_POINT, SYNC = 0, 1, 2, 3, 4
# the point block: what is pending (bits), the time, the states, then the deferred inputs'
# values and their pending flags (build/shim: POINT_*)
POINT_TIME, POINT_STATES, POINT_INPUTS, POINT_HEADER = 1, 2, 4, 2
GET_STATES, GET_INDICATORS, GET_DEFERRED_INPUTS, GET_STATE_OUTPUTS = 0, 1, 2, 3
NEW_DISCRETE_STATES = 2.0
# EVENT_INFO: what fmi2NewDiscreteStates reports
INFO_FIELDS = ("newDiscreteStatesNeeded", "terminateSimulation", "nominalsOfContinuousStatesChanged",
               "valuesOfContinuousStatesChanged", "nextEventTimeDefined", "nextEventTime")


#: an FMU output beyond the physics' model's outputs: its partials are the model's
#: ``named_partials`` (refused where it has none)
_NUMERICAL = "named"

#: the step [s] of the central difference in time of ``_time_partials``: fixed, not scaled
#: with |t| (at t = 1e6 s a relative step was 1 s against 450 rad/s tones), the differences
#: taken over the step as the floating-point times realise it.  Relative error about
#: (omega h)^2 / 6 + ulp(omega t) / (omega h) for a component of angular frequency omega:
#: 3e-6 + 7e-6 for a 450 rad/s tone at t = 1e6 s (docs/hosts.md)
TIME_STEP = 1e-5

#: the Integer calculated parameter that says how many event indicators can change sign
#: with the parameters set (the first ones; the others stay positive): a host may leave the
#: rest out of its root finding, each of which costs an evaluation of the model
LIVE_EVENT_INDICATORS = "live_event_indicators"


def _read_by_get_real():
    """pythonfmu's getter of a local variable, which it never calls (``get_real`` reads the
    locals): one function for all instead of a closure per instance."""
    raise NotImplementedError("read through get_real")


class _Layout(NamedTuple):
    """Where the hot path (outputs, derivatives at every right-hand side) finds what the
    physics' model takes, made once per model: attribute and name lookups spelled out."""
    positions: tuple           #: where each of the physics' states sits in ``ME_STATES``
    padding: list | None       #: the physics' states are the first of ``ME_STATES``, in that order: zeros
                               #: for the derivatives of the others (None: they are not)
    outputs: tuple | None      #: the physics' outputs (None: ``_me_output_values`` is a subclass's)
    read_x: Callable           #: the physics' states of the slave, in the physics' order (a sequence)
    read_u: Callable           #: the physics' inputs of the slave (a tuple)


def _reader(names: Sequence[str]) -> Callable:
    """A function of an object returning the tuple of its attributes ``names``, read in C
    (``attrgetter`` returns a bare value for one name: wrapped to a tuple)."""
    if len(names) == 1:
        one = attrgetter(names[0])
        return lambda obj: (one(obj),)
    return attrgetter(*names) if names else (lambda obj: ())


class StateVariable(NamedTuple):
    """A continuous state of the Model Exchange edition."""
    name: str              #: the variable of the state (an output, or a local declared here)
    derivative: str        #: the variable of its derivative (an output, or a local declared here)
    attribute: str         #: where the co-simulation edition keeps the value
    physics: str           #: the state's name in the physics' Model Exchange model
    unit: str = ""
    description: str = ""              #: of a local state
    derivative_description: str = ""   #: of a local derivative


class ModelExchangeSlave(LeverSlave):
    """A ``LeverSlave`` that also runs as a Model Exchange FMU.  Subclasses set
    ``ME_STATES``, ``ME_EVENT_INDICATORS``, ``ME_STRUCTURE_CASES`` and implement
    ``_me_physics()`` (the physics' Model Exchange model of the built model)."""

    ME_STATES: Sequence[StateVariable] = ()
    ME_EVENT_INDICATORS = 0
    #: parameter values (over the defaults) whose models' dependencies together are every
    #: dependency the model can have: the model description's ModelStructure is their union
    ME_STRUCTURE_CASES: Sequence[dict] = ({},)
    #: the dependencies (FMU names) of outputs that are neither the physics' outputs nor
    #: state derivatives (a model with more outputs than its physics' ME model names)
    ME_OUTPUT_DEPENDENCIES: dict = {}

    # Per instance only what changes (rebound, never mutated in place); the layout, the
    # same for every instance of a class, is the class's (``_layout``).  A host that
    # instantiates and frees in a loop leaves each freed Python slave to the cyclic
    # collector: the fewer objects one holds, the less waits for it.
    _me = False               # the native entry instantiated the Model Exchange interface
    _me_model = None          # the physics' model, made for the physics built
    _me_layout = None         # its _Layout
    _me_source = None
    _seeds: dict = {}         # known value reference -> seed of a directional derivative
    _event_info = (0.0,) * len(INFO_FIELDS)
    _point = None             # the native entry's point block (a memoryview of doubles), once it gave one
    _keys_of = None           # (model, known keys, unknown keys) of directional derivatives' references
    _partials_at = None       # (model, t, x, u, partials) of the last directional derivative
    _deferred_names = ()      # the inputs it may hold, in its order

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        outputs = {o.name for o in self.OUTPUTS}
        for s in self.ME_STATES:
            for name, text in ((s.name, s.description), (s.derivative, s.derivative_description)):
                if name not in outputs:
                    self.register_variable(Real(name, causality=Fmi2Causality.local,
                                                variability=Fmi2Variability.continuous,
                                                initial=Fmi2Initial.calculated, description=text,
                                                getter=_read_by_get_real), nested=False)
        if self.ME_EVENT_INDICATORS:
            # registered last: the value references of every other variable stay as they were
            self.register_variable(Integer(LIVE_EVENT_INDICATORS, causality=Fmi2Causality.calculatedParameter,
                                           variability=Fmi2Variability.fixed, initial=Fmi2Initial.calculated,
                                           description="event indicators that can change sign with the parameters "
                                                       "set: the first ones; the others stay positive, a host may "
                                                       "leave them out of its root finding",
                                           getter=_read_by_get_real), nested=False)
        if "_me_locals" not in type(self).__dict__:
            self._layout()

    def _layout(self):
        cls = type(self)
        #: value reference -> (state index, True for the derivative)
        cls._me_locals = {}
        cls._vr_of = {v.name: vr for vr, v in self.vars.items()}
        for k, s in enumerate(self.ME_STATES):
            for name, is_derivative in ((s.name, False), (s.derivative, True)):
                if self.vars[cls._vr_of[name]].causality == Fmi2Causality.local:
                    cls._me_locals[cls._vr_of[name]] = (k, is_derivative)
        # The locals are registered last and the channel lies above them: one comparison
        # tells a co-simulation master's read (all below) from anything else.
        cls._special_from = min(cls._me_locals) if cls._me_locals else CHANNEL
        cls._input_names = tuple(p.name for p in self.INPUTS)
        cls._state_of_physics = {s.physics: k for k, s in enumerate(self.ME_STATES)}
        cls._live_vr = cls._vr_of.get(LIVE_EVENT_INDICATORS)
        # the derivatives' channel references, read at every right-hand side: told apart by
        # one list comparison
        n = len(self.ME_STATES)
        cls._state_index = list(range(n))
        cls._derivative_refs = [CHANNEL + (DERIVATIVES << KIND_SHIFT) + k for k in range(n)]
        cls._state_attributes = tuple(s.attribute for s in self.ME_STATES)
        # Outputs that are states, kept in the attribute of their own name (``_x`` the
        # default): read without the model evaluated, as a host reads the angles and speeds
        # it feeds to a coupling at every right-hand side.
        outputs = {o.name for o in self.OUTPUTS}
        cls._state_outputs = frozenset(
            cls._vr_of[s.name] for s in self.ME_STATES
            if s.name in outputs and s.attribute == s.name and cls._x is ModelExchangeSlave._x)

    # -- what each model provides ----------------------------------------------------------------
    def _me_physics(self):
        """The physics' Model Exchange model of the built model (``me_base.ModelExchange``)."""
        raise NotImplementedError

    def _physics_key(self):
        """What the physics' model is made from: a new one when it changes."""
        raise NotImplementedError

    def _fold_indicators(self, values: list) -> list:
        """The FMU's event indicators from the physics' (default: those, then 1.0 for the
        ones this model does not use)."""
        if len(values) > self.ME_EVENT_INDICATORS:
            raise ValueError(f"{len(values)} event indicators, {self.ME_EVENT_INDICATORS} declared")
        return list(values) + [1.0] * (self.ME_EVENT_INDICATORS - len(values))

    def _live_event_indicators(self) -> int:
        """How many of the event indicators (the first ones) can change sign with the
        parameters set: the physics' model's events, folded as ``_fold_indicators`` folds
        them; all of them while the model is not built."""
        if self._phase == "instantiated" or self._model_stale or self._build_error is not None:
            return self.ME_EVENT_INDICATORS
        return min(len(self._me_current().EVENTS), self.ME_EVENT_INDICATORS)

    def _events_settled(self, t, x, u):
        """After an event update: what the adapter keeps besides the physics (default none)."""

    def _x(self) -> list:
        """The continuous states, in the order of ``ME_STATES``."""
        return [float(getattr(self, s.attribute)) for s in self.ME_STATES]

    def _set_x(self, x):
        for attribute, value in zip(self._state_attributes, x):
            setattr(self, attribute, float(value))

    def _me_output_values(self, model, t, x, u) -> dict:
        """The outputs by name in Model Exchange (default: the physics' model's)."""
        return dict(zip(model.OUTPUTS, model.outputs(t, x, u)))

    # -- the physics' model at the current point ----------------------------------------------------
    def _me_current(self):
        model = self._me_model
        if model is not None and not self._model_stale and self._build_error is None \
                and self._me_source is self._physics_key():
            return model                # the common case, at every right-hand side
        self._build_for_reading()
        if self._model_stale or self._build_error is not None:
            raise ParameterError("", f"the model is not built: {self._build_error or 'parameters changed since'}")
        key = self._physics_key()
        if self._me_model is None or self._me_source is not key:
            self._me_model, self._me_source = self._me_physics(), key
            self._me_layout = self._layout_of(self._me_model)
            self._start_modes()
        return self._me_model

    def _start_modes(self):
        self._partials_at = None        # the modes may change
        model = self._me_model
        if hasattr(model, "initialize"):
            model.initialize(self._time, self._x_physics(), self._u())
        self._events_settled(self._time, self._x_physics(), self._u())

    def _layout_of(self, model) -> _Layout:
        cls = type(self)
        positions = tuple(self._state_of_physics[name] for name in model.STATES)
        if cls._x is ModelExchangeSlave._x:
            # The states and inputs are kept as floats (``_set_x``, ``set_real``, the point
            # block), so they are read as they are: in one C call at every right-hand side.
            read_x = _reader([self.ME_STATES[k].attribute for k in positions])
        else:
            def read_x(slave):
                x = slave._x()
                return [x[k] for k in positions]
        padding = [0.0] * (len(self.ME_STATES) - len(positions)) if positions == tuple(range(len(positions))) else None
        return _Layout(positions, padding, tuple(model.OUTPUTS) if cls._me_output_values is
                       ModelExchangeSlave._me_output_values else None, read_x, _reader(model.INPUTS))

    def _x_physics(self) -> list:
        return list(self._me_layout.read_x(self))

    def _u(self) -> list:
        return list(self._me_layout.read_u(self))

    def _derivatives(self) -> list:
        model = self._me_current()
        layout = self._me_layout
        values = model.derivatives(self._time, list(layout.read_x(self)), list(layout.read_u(self)))
        if layout.padding is not None:
            return [*values, *layout.padding]
        out = [0.0] * len(self.ME_STATES)     # a state the physics does not have stays constant
        for k, value in zip(layout.positions, values):
            out[k] = value
        return out

    def _indicators(self) -> list:
        model = self._me_current()
        return self._fold_indicators(model.event_indicators(self._time, self._x_physics(), self._u()))

    # -- FMI ------------------------------------------------------------------------------------------
    @guarded()
    def exit_initialization_mode(self):
        LeverSlave.exit_initialization_mode.__wrapped__(self)
        if self._me and self._phase == "stepping":
            self._me_model = None      # modes from the inputs the host has set now
            self._me_current()

    def _refresh(self):
        if not self._me:
            return super()._refresh()
        if self._build_error is not None or self._model_stale:
            return
        model = self._me_current()
        names = self._me_layout.outputs
        if names is not None:
            outputs = model.outputs(self._time, self._x_physics(), self._u())
            for name, value in zip(names, outputs):
                setattr(self, name, value)
            self._dirty = CLEAN
            total = sum(outputs)        # finite unless an output is not (or the sum overflows)
            if total - total == 0.0:
                return
            values = dict(zip(names, outputs))
        else:
            values = self._me_output_values(model, self._time, self._x_physics(), self._u())
            for name, value in values.items():
                setattr(self, name, value)
            self._dirty = CLEAN
        bad = [name for name, value in values.items() if not math.isfinite(value)]
        if bad:
            self._dirty = ALL
            self._error(f"output(s) {', '.join(bad)} are not finite at t = {self._time!r} s with states "
                        f"{self._x()!r} and inputs {self._u()!r}")

    @staticmethod
    def _is_channel(vrs) -> bool:
        return bool(vrs) and max(vrs) >= CHANNEL

    #: inputs whose set the model judges beyond their declared range (a subclass's
    #: ``set_real``): never deferred
    JUDGED_INPUTS: tuple = ()

    def _deferred_inputs(self) -> list:
        """``[(value reference, (name, low, high))]`` of the inputs the native entry may keep
        in the point block when a host sets them in range while the model runs: those
        ``set_real`` applies without further ado (its fast path), in value-reference order."""
        judged = set(self.JUDGED_INPUTS)
        names = set(self._input_names) - judged
        return sorted((vr, entry) for vr, entry in self._fast_inputs.items() if entry[0] in names)

    def _state_output_table(self) -> list:
        """``[(value reference, state index)]`` of the outputs that are states (kept in the
        attribute of their name): the native entry answers a read of those alone in
        Continuous-Time Mode from the states the host set, without a call into Python."""
        return sorted((self._vr_of[s.name], k) for k, s in enumerate(self.ME_STATES)
                      if self._vr_of.get(s.name) in self._state_outputs)

    def _take_point(self):
        """The time and states the host set through the native entry since the model last
        saw them (checked there: finite, the right number), if any: first thing in every
        call that reaches the model through fmi2GetReal or fmi2SetReal."""
        point = self._point
        if point is None or not point[0]:
            return
        block = point.tolist()          # one copy of the block: cheaper than element by element
        pending = int(block[0])
        point[0] = 0.0
        if pending & POINT_TIME:
            self._time = block[1]
        if pending & POINT_STATES:
            self._set_x(block[POINT_HEADER:POINT_HEADER + len(self._state_index)])
        if pending & (POINT_TIME | POINT_STATES):
            self._dirty = ALL
        if pending & POINT_INPUTS:
            first, flags, end = self._deferred_span
            for name, value, flag in zip(self._deferred_names, block[first:flags], block[flags:end]):
                if flag:
                    setattr(self, name, value)
            point[flags:end] = self._no_inputs_pending
            if not self._dirty:
                self._dirty = INPUTS_CHANGED

    @guarded(default=_nan_values)
    def get_real(self, vrs):
        if self._model_stale:           # every read, whatever it reads: the model its parameters make
            self._build_for_reading()
        point = self._point
        if point is not None and point[0]:
            self._take_point()
        if vrs == self._derivative_refs and vrs:          # every right-hand side
            return self._derivatives()
        if point is not None and self._phase == "stepping" and self._state_outputs.issuperset(vrs):
            return [float(getattr(self, self._real_names[vr])) for vr in vrs]
        if vrs and max(vrs) >= self._special_from:
            if self._is_channel(vrs):
                return self._channel_get(vrs)
            return self._get_with_locals(vrs)
        return LeverSlave.get_real.__wrapped__(self, vrs)

    @guarded(default=lambda self, vrs: [0] * len(vrs))
    def get_integer(self, vrs):
        if self._model_stale:
            self._build_for_reading()
        if self._live_vr in vrs:
            return [self._live_event_indicators() if vr == self._live_vr else
                    LeverSlave.get_integer.__wrapped__(self, [vr])[0] for vr in vrs]
        return LeverSlave.get_integer.__wrapped__(self, vrs)

    @guarded()
    def set_real(self, vrs, values):
        self._take_point()
        if self._is_channel(vrs):
            return self._channel_set(vrs, values)
        return LeverSlave.set_real.__wrapped__(self, vrs, values)

    def _get_with_locals(self, vrs):
        values = []
        derivatives = None
        for vr in vrs:
            if vr not in self._me_locals:
                values.extend(LeverSlave.get_real.__wrapped__(self, [vr]))
                continue
            k, is_derivative = self._me_locals[vr]
            if not is_derivative:
                values.append(self._x()[k])
            elif self._phase == "instantiated" or self._model_stale or self._build_error is not None:
                values.append(0.0)       # like the outputs: calculated once the model is built
            else:
                if derivatives is None:
                    self._cs_modes()
                    derivatives = self._derivatives()
                values.append(derivatives[k])
        return values

    def _cs_modes(self):
        """In co-simulation the physics' modes follow the co-simulation edition's."""
        if not self._me:
            self._me_current()
            self._modes_from_co_simulation()

    def _modes_from_co_simulation(self):
        """Default: the modes the physics' model takes from the state (a load's memoryless
        law, an engine's segment)."""
        self._start_modes()

    # -- the channel ------------------------------------------------------------------------------
    def _split(self, vrs):
        kinds = {(vr - CHANNEL) >> KIND_SHIFT for vr in vrs}
        if len(kinds) != 1 or min(vrs) < CHANNEL:
            raise ValueError(f"value references {list(vrs)} mix kinds of the native entry's channel")
        return kinds.pop(), [(vr - CHANNEL) & INDEX_MASK for vr in vrs]

    def _channel_set(self, vrs, values):
        if len(vrs) != len(values):
            raise ValueError(f"{len(vrs)} value references but {len(values)} values")
        kind, index = self._split(vrs)
        if kind == CONTROL and index == [SET_INTERFACE]:
            if self._phase != "instantiated":
                raise ValueError("the interface is chosen at instantiation")
            self._me = values[0] == 1.0
        elif kind == CONTROL and index == [SET_TIME]:
            self._set_time(values[0])
        elif kind == CONTROL and index == [SYNC]:
            pass                        # the point block was taken above
        elif kind == CONTROL and index == [SET_POINT]:
            address = int(values[0])
            deferred = self._deferred_inputs()
            first = POINT_HEADER + max(len(self.ME_STATES), 1)
            m = len(deferred)
            # a memoryview of the block: its items and slices are read and written in C
            self._point = (memoryview((ctypes.c_double * (first + 2 * m)).from_address(address)).cast("B").cast("d")
                           if address else None)
            self._deferred_names = tuple(name for _, (name, _, _) in deferred)
            self._deferred_span = (first, first + m, first + 2 * m)
            self._no_inputs_pending = memoryview(bytes(8 * m)).cast("d")
        elif kind == CONTROL and index == [SET_COMMAND] and values[0] == NEW_DISCRETE_STATES:
            self._new_discrete_states()
        elif kind == STATES:
            self._set_states(index, values)
        elif kind == SEEDS:
            self._seeds = dict(zip(index, values))
        else:
            raise ValueError(f"value references {list(vrs)} are nothing the native entry may set")

    def _set_time(self, t):
        if not math.isfinite(t):
            self._error(f"fmi2SetTime: time {t!r} is not finite; the time stays {self._time!r} s")
            return
        self._time = float(t)
        self._dirty = ALL

    def _channel_get(self, vrs):
        kind, index = self._split(vrs)
        if kind == CONTROL:
            sizes = {GET_STATES: float(len(self.ME_STATES)), GET_INDICATORS: float(self.ME_EVENT_INDICATORS),
                     GET_DEFERRED_INPUTS: float(len(self._deferred_inputs())),
                     GET_STATE_OUTPUTS: float(len(self._state_output_table()))}
            return [sizes[i] for i in index]
        if kind == STATE_OUTPUT_TABLE:
            table = [float(value) for pair in self._state_output_table() for value in pair]
            return [table[i] for i in index]
        if kind == INPUT_TABLE:
            table = [value for vr, (_, low, high) in self._deferred_inputs() for value in (float(vr), low, high)]
            return [table[i] for i in index]
        if kind == STATES:
            x = self._x()
            return [x[i] for i in index]
        if kind == DERIVATIVES:
            values = self._derivatives()
            return [values[i] for i in index]
        if kind == INDICATORS:
            self._cs_modes()
            values = self._indicators()
            return [values[i] for i in index]
        if kind == NOMINALS:
            return [1.0 for _ in index]
        if kind == EVENT_INFO:
            return [self._event_info[i] for i in index]
        if kind == DIRECTIONAL:
            seeds, self._seeds = self._seeds, {}
            return self._directional(index, seeds)
        if kind == OUTPUT_RATES:
            return self._output_rates(index)
        raise ValueError(f"value references {list(vrs)} are nothing the native entry may read")

    def _set_states(self, index, values):
        n = len(self.ME_STATES)
        if index != self._state_index:
            self._error(f"fmi2SetContinuousStates: {len(index)} states given, this model has {n}; nothing was set")
            return
        total = sum(values)
        bad = [] if total - total == 0.0 else [self.ME_STATES[k].name for k, v in enumerate(values)
                                                if not math.isfinite(v)]
        if bad:
            self._error(f"fmi2SetContinuousStates: state(s) {', '.join(bad)} not finite ({list(values)!r}); "
                        f"the states stay {self._x()!r}")
            return
        self._set_x(values)
        self._dirty = ALL

    def _new_discrete_states(self):
        self._partials_at = None        # the modes may change
        model = self._me_current()
        t, u = self._time, self._u()
        before, modes = self._x(), model.modes()
        after = model.event_update(t, self._x_physics(), u)
        x = list(before)
        for name, value in zip(model.STATES, after):
            x[self._state_of_physics[name]] = value
        self._set_x(x)
        self._events_settled(t, self._x_physics(), u)
        upcoming = model.next_time_event(t) if hasattr(model, "next_time_event") else None
        # a mode changed: the right-hand side jumped, the host's integrator must restart here
        # (me_base: ``modes``), as where a state changed
        changed = x != before or model.modes() != modes
        self._event_info = (0.0, 0.0, 0.0, float(changed), float(upcoming is not None),
                            float(upcoming) if upcoming is not None else 0.0)
        self._dirty = ALL

    # -- directional derivatives -------------------------------------------------------------------
    def _unknown_key(self, vr):
        """The physics' name of the unknown with value reference ``vr`` (an output or a
        state's derivative), or None."""
        var = self.vars.get(vr)
        if var is None:
            return None
        model = self._me_model
        if var.name in model.OUTPUTS:
            return var.name
        for s in self.ME_STATES:
            if s.derivative == var.name:
                return der(s.physics) if s.physics in model.STATES else ""
        for s in self.ME_STATES:
            if s.name == var.name:
                return ("state", s.physics)
        if var.name in self._declared and var.causality.name == "output":
            return _NUMERICAL
        return None

    def _known_key(self, vr):
        """The physics' name of the known with value reference ``vr`` (an input, or in
        Model Exchange a state), or None."""
        var = self.vars.get(vr)
        if var is None:
            return None
        if var.name in self._input_names:
            return var.name
        if self._me:
            for s in self.ME_STATES:
                if s.name == var.name:
                    return s.physics
        return None

    def _directional(self, unknowns, seeds):
        model = self._me_current()
        self._cs_modes()
        cached = self._keys_of
        if cached is None or cached[0] is not model:
            cached = self._keys_of = (model, {}, {})
        known_keys, unknown_keys = cached[1], cached[2]
        knowns = {}
        for vr, seed in seeds.items():
            key = known_keys[vr] if vr in known_keys else known_keys.setdefault(vr, self._known_key(vr))
            if key is None:
                self._error(f"fmi2GetDirectionalDerivative: value reference {vr} is no "
                            f"{'input or state' if self._me else 'input'} of {type(self).__name__}")
                return _nan_values(self, unknowns)
            if not math.isfinite(seed):
                self._error(f"fmi2GetDirectionalDerivative: seed {seed!r} of value reference {vr} is not finite")
                return _nan_values(self, unknowns)
            knowns[key] = knowns.get(key, 0.0) + seed
        keys = []
        for vr in unknowns:
            key = unknown_keys[vr] if vr in unknown_keys else unknown_keys.setdefault(vr, self._unknown_key(vr))
            if key is None:
                self._error(f"fmi2GetDirectionalDerivative: value reference {vr} is no output or state "
                            f"derivative of {type(self).__name__}")
                return _nan_values(self, unknowns)
            keys.append(key)
        t, x, u = self._time, self._x_physics(), self._u()
        partials = self._partials(model, t, x, u)
        out = []
        named = None
        for vr, key in zip(unknowns, keys):
            if isinstance(key, tuple):           # an output that is a state: itself
                out.append(knowns.get(key[1], 0.0) if self._me else 0.0)
            elif key == _NUMERICAL:
                if named is None and (named := self._named_partials(model, t, x, u, "fmi2GetDirectionalDerivative",
                                                                    unknowns)) is None:
                    return _nan_values(self, unknowns)
                row = named[self.vars[vr].name]
                out.append(sum(row.get(wrt, 0.0) * seed for wrt, seed in knowns.items()))
            else:
                out.append(sum(partials.get((key, wrt), 0.0) * seed for wrt, seed in knowns.items()))
        return out

    def _named_partials(self, model, t, x, u, call: str, unknowns) -> dict | None:
        """The model's ``named_partials`` at the point, or None after an fmi2Error that says
        it has none (an output without analytic partials is refused, not approximated)."""
        if not hasattr(model, "named_partials"):
            names = [self.vars[vr].name for vr in unknowns if self._unknown_key(vr) == _NUMERICAL]
            self._error(f"{call}: output(s) {', '.join(names)} of {type(self).__name__} have no analytic partial "
                        "derivatives in its physics; refused rather than approximated")
            return None
        return model.named_partials(t, x, u)

    def _partials(self, model, t, x, u) -> dict:
        """``model.partials(t, x, u)``, kept for the next call at the same point and modes: a
        host that assembles a Jacobian asks one directional derivative per state and input."""
        kept = self._partials_at
        if kept is not None and kept[0] is model and kept[1] == t and kept[2] == x and kept[3] == u:
            return kept[4]
        partials = model.partials(t, x, u)
        self._partials_at = (model, t, x, u, partials)
        return partials

    def _output_rates(self, unknowns):
        """The first time derivatives of the outputs ``unknowns`` (value references) at the
        current point along the model's own motion with the inputs held: the partials of the
        directional derivative with the states' derivatives as the seed, plus the explicit
        time dependence (a load's time series) by central differences in time:
        dy/dt = dy/dx * dx/dt + dy/dt|x,u."""
        model = self._me_current()
        self._cs_modes()
        rates = self._derivatives()
        seed = {s.physics: rates[k] for k, s in enumerate(self.ME_STATES) if s.physics in model.STATES}
        keys = []
        for vr in unknowns:
            var = self.vars.get(vr)
            key = self._unknown_key(vr) if var is not None and var.causality.name == "output" else None
            if key is None:
                self._error(f"fmi3GetOutputDerivatives: value reference {vr} is no output of {type(self).__name__}")
                return _nan_values(self, unknowns)
            keys.append(key)
        t, x, u = self._time, self._x_physics(), self._u()
        partials = model.partials(t, x, u)
        explicit = self._time_partials(model, t, x, u)
        out, named = [], None
        for vr, key in zip(unknowns, keys):
            if isinstance(key, tuple):           # an output that is a state: its derivative
                out.append(seed.get(key[1], 0.0))
            elif key == _NUMERICAL:
                if named is None and (named := self._named_partials(model, t, x, u, "fmi3GetOutputDerivatives",
                                                                    unknowns)) is None:
                    return _nan_values(self, unknowns)
                name = self.vars[vr].name
                out.append(sum(named[name].get(wrt, 0.0) * rate for wrt, rate in seed.items())
                           + explicit.get(name, 0.0))
            else:
                out.append(sum(partials.get((key, wrt), 0.0) * rate for wrt, rate in seed.items())
                           + explicit.get(key, 0.0))
        bad = [self.vars[vr].name for vr, v in zip(unknowns, out) if not math.isfinite(v)]
        if bad:
            self._error(f"fmi3GetOutputDerivatives: the rate of output(s) {', '.join(bad)} is not finite at "
                        f"t = {self._time!r} s")
            return _nan_values(self, unknowns)
        return out

    def _time_partials(self, model, t, x, u) -> dict:
        """d/dt of the outputs and state derivatives at fixed states and inputs: a central
        difference over ``TIME_STEP`` whatever |t| is, divided by the step the two
        floating-point times really span (exactly 0 for a model whose laws do not contain
        the time)."""
        later, earlier = t + TIME_STEP, t - TIME_STEP
        sides = []
        for when in (later, earlier):
            values = dict(self._me_output_values(model, when, x, u))
            values.update((der(name), v) for name, v in zip(model.STATES, model.derivatives(when, x, u)))
            sides.append(values)
        span = later - earlier
        return {key: (sides[0][key] - sides[1][key]) / span for key in sides[0]}

    # -- model description ---------------------------------------------------------------------------
    def _structure(self) -> dict:
        """{unknown variable: set of known variables} over ``ME_STRUCTURE_CASES`` (the FMU's
        names: outputs and state derivatives on inputs and states)."""
        saved = dict(self.__dict__)
        union: dict[str, set] = {}
        try:
            for case in self.ME_STRUCTURE_CASES:
                for p in self.PARAMETERS:
                    setattr(self, p.name, case.get(p.name, p.default))
                self._build()
                self._model_stale, self._build_error = False, None
                self._me_model = None
                model = self._me_physics()
                names = {s.physics: s.name for s in self.ME_STATES}
                unknown = {o: o for o in model.OUTPUTS}
                unknown.update({der(s.physics): s.derivative for s in self.ME_STATES})
                for of, wrt in model.dependencies.items():
                    union.setdefault(unknown[of], set()).update(names.get(w, w) for w in wrt)
        finally:
            self.__dict__.clear()
            self.__dict__.update(saved)
        for state in self.ME_STATES:     # an output that is a state is that state
            union.setdefault(state.name, {state.name})
        for name, wrt in self.ME_OUTPUT_DEPENDENCIES.items():
            union.setdefault(name, set()).update(wrt)
        missing = [o.name for o in self.OUTPUTS if o.name not in union]
        if missing:
            raise ValueError(f"{type(self).__name__}: the dependencies of output(s) {', '.join(missing)} are "
                             "not declared (ME_OUTPUT_DEPENDENCIES)")
        return union

    def to_xml(self, model_options=None) -> Element:
        root = super().to_xml(model_options)
        cs = root.find("CoSimulation")
        cs.set("providesDirectionalDerivative", "true")
        me = Element("ModelExchange", {
            "modelIdentifier": cs.get("modelIdentifier"), "needsExecutionTool": "false",
            "completedIntegratorStepNotNeeded": "true", "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "true", "canGetAndSetFMUstate": "false",
            "canSerializeFMUstate": "false", "providesDirectionalDerivative": "true"})
        root.insert(list(root).index(cs), me)
        root.set("numberOfEventIndicators", str(self.ME_EVENT_INDICATORS))

        nodes = root.find("ModelVariables").findall("ScalarVariable")
        index_of = {node.get("name"): i for i, node in enumerate(nodes, start=1)}
        units, types = root.find("UnitDefinitions"), root.find("TypeDefinitions")
        defined = {u.get("name") for u in units}
        typed_as = {t.get("name") for t in types}
        for s in self.ME_STATES:
            for name in (s.name, s.derivative):
                if self._vr_of[name] in self._me_locals:
                    spec = Output(name, s.unit if name == s.name else _rate_unit(s.unit), "")
                    type_name, element, attrs = declared_type(spec)
                    typed = nodes[index_of[name] - 1][0]
                    typed.set("declaredType", type_name)
                    typed.set("unit", spec.unit)
                    if spec.unit in DISPLAY_UNITS:
                        typed.set("displayUnit", DISPLAY_UNITS[spec.unit])
                    if spec.unit not in defined:
                        define_unit(units, spec.unit)
                        defined.add(spec.unit)
                    if type_name not in typed_as:
                        SubElement(SubElement(types, "SimpleType", {"name": type_name}), element, attrs)
                        typed_as.add(type_name)
            nodes[index_of[s.derivative] - 1][0].set("derivative", str(index_of[s.name]))

        structure = self._structure()
        inputs = set(self._input_names)

        def unknown(parent, name, only_inputs=False):
            sources = sorted((index_of[n] for n in structure.get(name, ()) if not only_inputs or n in inputs))
            attrs = {"index": str(index_of[name]), "dependencies": " ".join(map(str, sources))}
            if sources:
                attrs["dependenciesKind"] = " ".join("dependent" for _ in sources)
            SubElement(parent, "Unknown", attrs)

        model_structure = root.find("ModelStructure")
        for child in list(model_structure):
            model_structure.remove(child)
        outputs = SubElement(model_structure, "Outputs")
        for o in self.OUTPUTS:
            unknown(outputs, o.name)
        if self.ME_STATES:
            derivatives = SubElement(model_structure, "Derivatives")
            for s in self.ME_STATES:
                unknown(derivatives, s.derivative)
        # At initialisation the states are unknowns themselves (from the parameters): the
        # initial unknowns' knowns are the inputs.
        initial = SubElement(model_structure, "InitialUnknowns")
        names = {o.name for o in self.OUTPUTS} | {self.vars[vr].name for vr in self._me_locals}
        for name in sorted(names, key=index_of.get):
            unknown(initial, name, only_inputs=True)
        if self._live_vr is not None:
            type_name = camel_case(LIVE_EVENT_INDICATORS)
            nodes[index_of[LIVE_EVENT_INDICATORS] - 1][0].set("declaredType", type_name)
            SubElement(SubElement(types, "SimpleType", {"name": type_name}), "Integer",
                       {"quantity": type_name, "min": "0", "max": str(self.ME_EVENT_INDICATORS)})
            # a calculated parameter is an initial unknown; it depends on the parameters
            # (no dependencies attribute: on every known)
            SubElement(initial, "Unknown", {"index": str(index_of[LIVE_EVENT_INDICATORS])})
        return root


def _rate_unit(unit: str) -> str:
    return {"rad": "rad/s", "rad/s": "rad/s2", "J": "W", "N.m": "N.m/s"}.get(unit, "")
