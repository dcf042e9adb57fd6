"""The native entry's private channel to the model of a Model Exchange FMU.

pythonfmu 0.7 exports Co-Simulation only, so the native entry (build/shim) implements the
Model Exchange functions and their state machine itself and reaches the model through
pythonfmu's ``fmi2GetReal``/``fmi2SetReal`` on value references of its own, at and above
``CHANNEL`` (far above any variable's): pythonfmu passes value references through
untouched, and the entry refuses such references from a host, so only it uses them.  A
reference there is ``CHANNEL + (kind << 20) + index``; every ME call is one such get or
set, and errors are logged like any other (fmi2Error, the instance usable).
"""
from __future__ import annotations

import ctypes
import math
from array import array
from itertools import compress

from .recompute import ALL, CLEAN, INPUTS_CHANGED

CHANNEL = 0x40000000
KIND_SHIFT = 20
INDEX_MASK = (1 << KIND_SHIFT) - 1
# kinds of channel references
(CONTROL, STATES, DERIVATIVES, INDICATORS, NOMINALS, SEEDS, DIRECTIONAL, EVENT_INFO, OUTPUT_RATES, INPUT_TABLE,
 STATE_OUTPUT_TABLE, OUTPUT_TABLE) = range(12)
# CONTROL set: the interface (1: Model Exchange), the time, a command, the address of the
# native entry's point block (0: none), a sync (nothing but the point block taken); get: the sizes
SET_INTERFACE, SET_TIME, SET_COMMAND, SET_POINT, SYNC = 0, 1, 2, 3, 4
# the point block: what is pending (bits), the time, the states, then the deferred inputs'
# values and their pending flags, then whether the outputs there are the model's and the
# outputs, left at the end of a Co-Simulation step (build/shim: POINT_*)
POINT_TIME, POINT_STATES, POINT_INPUTS, POINT_HEADER = 1, 2, 4, 2
GET_STATES, GET_INDICATORS, GET_DEFERRED_INPUTS, GET_STATE_OUTPUTS, GET_OUTPUTS = 0, 1, 2, 3, 4
NEW_DISCRETE_STATES = 2.0
# EVENT_INFO: what fmi2NewDiscreteStates reports
INFO_FIELDS = ("newDiscreteStatesNeeded", "terminateSimulation", "nominalsOfContinuousStatesChanged",
               "valuesOfContinuousStatesChanged", "nextEventTimeDefined", "nextEventTime")


class NativeEntryChannel:
    """The channel's side in the model (a part of ``lever.fmus.model_exchange``'s
    ``ModelExchangeSlave``, which gives it the states, derivatives, indicators and partial
    derivatives it answers with): what the native entry sets and reads there, the point
    block it leaves the time, the states and deferred inputs in, the event update."""

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

    def _block_outputs(self) -> tuple:
        """The outputs a Co-Simulation step leaves in the point block (``_publish_outputs``),
        in its order: every output (read together by ``_outputs_of``) of a model with states;
        none of a model without, whose outputs follow the inputs a host sets before it reads."""
        return tuple(o.name for o in self.OUTPUTS) if self.ME_STATES else ()

    def _publish_outputs(self):
        """At the end of a Co-Simulation step: the outputs computed now and left in the point
        block, where the native entry answers a read of them until the next call of another
        kind.  Outputs that are not all finite are left to the next read, which says so."""
        self._compute_outputs()
        values = self._outputs_of(self)
        total = sum(values)
        if total - total == 0.0:
            self._dirty = CLEAN
            at = self._outputs_at
            self._point[at + 1:at + 1 + len(values)] = array("d", values)
            self._point[at] = 1.0

    def _take_point(self):
        """The time, states and inputs the host set through the native entry since the
        model last saw them (checked there: finite, in range, the right number), if any:
        first thing in every call that reaches the model through fmi2GetReal, fmi2SetReal
        or fmi2DoStep."""
        point = self._point
        if point is None or not point[0]:
            return
        pending = int(point[0])
        point[0] = 0.0
        if pending != POINT_INPUTS:         # Model Exchange's time and states
            if pending & POINT_TIME:
                self._time = point[1]
            if pending & POINT_STATES:
                self._set_x(point[POINT_HEADER:POINT_HEADER + len(self._state_index)].tolist())
            if pending & (POINT_TIME | POINT_STATES):
                self._dirty = ALL
        if pending & POINT_INPUTS:
            first, flags, end = self._deferred_span
            block = point[first:end].tolist()   # one copy: cheaper than element by element
            for name, value in compress(zip(self._deferred_names, block), block[flags - first:]):
                setattr(self, name, value)
            point[flags:end] = self._no_inputs_pending
            if not self._dirty:
                self._dirty = INPUTS_CHANGED

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
            size = first + 2 * m + 1 + len(self._block_outputs())
            # a memoryview of the block: its items and slices are read and written in C
            self._point = (memoryview((ctypes.c_double * size).from_address(address)).cast("B").cast("d")
                           if address else None)
            self._deferred_names = tuple(name for _, (name, _, _) in deferred)
            self._deferred_span = (first, first + m, first + 2 * m)
            self._outputs_at = first + 2 * m if self._point is not None and self._block_outputs() else None
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
                     GET_STATE_OUTPUTS: float(len(self._state_output_table())),
                     GET_OUTPUTS: float(len(self._block_outputs()))}
            return [sizes[i] for i in index]
        if kind == STATE_OUTPUT_TABLE:
            table = [float(value) for pair in self._state_output_table() for value in pair]
            return [table[i] for i in index]
        if kind == OUTPUT_TABLE:
            table = [float(self._vr_of[name]) for name in self._block_outputs()]
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
