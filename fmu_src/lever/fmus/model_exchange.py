"""FMI 2.0 Model Exchange for our FMUs, from the physics' Model Exchange interface
(``lever.physics.me_base``): the states, their derivatives, the event indicators, the
event updates and the analytic partials that ``fmi2GetDirectionalDerivative`` multiplies.

A model declares its continuous states (``StateVariable``: an output of the FMU or a local
variable declared here, and the variable holding its derivative), the number of event
indicators, and the parameter sets whose models together show every dependency the model
can have (the model description is one for all parameter values).

The slave is put together from a part a job: the native entry's private channel
(``me_channel``), the partial derivatives (``me_partials``) and the model description's
Model Exchange parts (``me_description``); this module holds the states, the physics'
model at the current point and the FMI calls.
"""
from __future__ import annotations

import math
from typing import Callable, NamedTuple, Sequence

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Variability, Integer, Real

from ..physics.parameters import ParameterError
from .base import _LIVE, LeverSlave, _nan_values, _reader_of
from .guard import guarded
from .me_channel import CHANNEL, DERIVATIVES, INFO_FIELDS, KIND_SHIFT, NativeEntryChannel
from .me_description import LIVE_EVENT_INDICATORS, ModelExchangeDescription
from .me_partials import PartialDerivatives
from .recompute import ALL, CLEAN


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


class StateVariable(NamedTuple):
    """A continuous state of the Model Exchange edition."""
    name: str              #: the variable of the state (an output, or a local declared here)
    derivative: str        #: the variable of its derivative (an output, or a local declared here)
    attribute: str         #: where the co-simulation edition keeps the value
    physics: str           #: the state's name in the physics' Model Exchange model
    unit: str = ""
    description: str = ""              #: of a local state
    derivative_description: str = ""   #: of a local derivative


class ModelExchangeSlave(NativeEntryChannel, PartialDerivatives, ModelExchangeDescription,
                         LeverSlave):
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
    _outputs_at = None        # where the outputs a step leaves there begin (None: nowhere)

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
            read_x = _reader_of([self.ME_STATES[k].attribute for k in positions])
        else:
            def read_x(slave):
                x = slave._x()
                return [x[k] for k in positions]
        padding = [0.0] * (len(self.ME_STATES) - len(positions)) if positions == tuple(range(len(positions))) else None
        return _Layout(positions, padding, tuple(model.OUTPUTS) if cls._me_output_values is
                       ModelExchangeSlave._me_output_values else None, read_x, _reader_of(model.INPUTS))

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

    @guarded(default=_nan_values)
    def get_real(self, vrs):
        if self._model_stale:           # every read, whatever it reads: the model its parameters make
            self._build_for_reading()
        point = self._point
        if point is not None and point[0]:
            self._take_point()
        if vrs and max(vrs) < self._special_from:         # the model's variables: a host's reads
            if not self._me:                              # Co-Simulation: LeverSlave.get_real's
                if self._dirty and self._phase in _LIVE:
                    LeverSlave._refresh(self)
                return self._read_reals(vrs)
            if point is not None and self._phase == "stepping" and self._state_outputs.issuperset(vrs):
                return self._read_reals(vrs)
        elif vrs == self._derivative_refs and vrs:        # every right-hand side
            return self._derivatives()
        elif vrs:
            if self._is_channel(vrs):
                return self._channel_get(vrs)
            return self._get_with_locals(vrs)
        # LeverSlave.get_real's, the model built above
        if self._dirty and self._phase in _LIVE:
            self._refresh()
        return self._read_reals(vrs)

    @guarded(default=lambda self, vrs: [0] * len(vrs))
    def get_integer(self, vrs):
        if self._model_stale:
            self._build_for_reading()
        if self._live_vr in vrs:
            return [self._live_event_indicators() if vr == self._live_vr else
                    LeverSlave.get_integer.__wrapped__(self, [vr])[0] for vr in vrs]
        return LeverSlave.get_integer.__wrapped__(self, vrs)

    @guarded(default=False)
    def do_step(self, current_time, step_size):
        # a Co-Simulation host's inputs the native entry kept since the last call: the step
        # takes them itself, no sync call before it
        point = self._point
        if point is not None and point[0]:
            self._take_point()
        stepped = LeverSlave.do_step.__wrapped__(self, current_time, step_size)
        if stepped and self._outputs_at is not None and not self._me:
            try:
                self._publish_outputs()
            except Exception:  # noqa: BLE001 - the next read computes them again and says what failed
                self._dirty = ALL
        return stepped

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
