"""One FMU instance in its Model Exchange interface (fmpy's ``FMU2Model``), for a master
that integrates the system's states itself (``harness.engine.masters.model_exchange``).

It is a ``harness.engine.component.Component`` - named variables, parameters, the raw
fmi2GetReal/fmi2SetReal the system's compiled propagation calls, the same error reports -
with the Model Exchange calls beside them: time, continuous states, derivatives, event
indicators, directional derivatives and the event mode.  They go straight to the FMU's C
functions with preallocated buffers, as the co-simulation hot path does, and each kind is
counted (``model_exchange_calls``) so that a run reports them like every other FMI call.
"""
from __future__ import annotations

import ctypes

from fmpy.fmi2 import FMU2Model, fmi2EventInfo

from harness.engine.component import Component, log_callbacks, unconverted
from harness.engine.interface import RawModelExchangeCalls

#: the kinds of Model Exchange call counted, as ``System.calls_by_kind`` reports them
ME_CALL_KINDS = ("time", "states", "derivatives", "indicators", "directional", "event")

#: an FMU's Integer calculated parameter saying how many of its event indicators (the first
#: ones) can change sign with the parameters set (our FMUs declare it; docs/model-exchange.md)
LIVE_EVENT_INDICATORS = "live_event_indicators"


def set_time_call(t: float) -> str:
    """How a refused fmi2SetTime is named in its error: the time."""
    return f"fmi2SetTime(t = {t:.9g})"


class NoModelExchange(ValueError):
    """An FMU that offers co-simulation only."""


class ModelExchangeComponent(Component):
    """An instantiated FMU in Model Exchange: ``nx`` continuous states, ``nz`` event
    indicators; ``set_time``, ``set_states``, ``derivatives``, ``indicators``,
    ``directional`` and the event mode (``enter_event_mode``, ``new_discrete_states``,
    ``enter_continuous_time_mode``), each checked like the hot path's calls."""

    def __init__(self, name: str, fmu_path, logging_on: bool = False):
        self.me_counts = dict.fromkeys(ME_CALL_KINDS, 0)
        super().__init__(name, fmu_path, logging_on)
        md = self.description
        self.nx = int(md.numberOfContinuousStates)
        self.nz = int(md.numberOfEventIndicators)
        #: the states' variables (in the FMU's order) and their derivatives'
        self.state_names = [u.variable.derivative.name for u in md.derivatives]
        self.derivative_names = [u.variable.name for u in md.derivatives]
        f = self.fmu._functions
        self._nx = ctypes.c_size_t(self.nx)
        #: the calls at every right-hand side, for a master's compiled point (and ours)
        self.me_raw = RawModelExchangeCalls(self.raw.handle, unconverted(f["fmi2SetTime"]),
                                            unconverted(f["fmi2SetContinuousStates"]),
                                            unconverted(f["fmi2GetDerivatives"]),
                                            unconverted(f["fmi2GetDirectionalDerivative"]), self._nx)
        self._get_states = unconverted(f["fmi2GetContinuousStates"])
        self._get_indicators = unconverted(f["fmi2GetEventIndicators"])
        self._enter_event = unconverted(f["fmi2EnterEventMode"])
        self._new_discrete = unconverted(f["fmi2NewDiscreteStates"])
        self._enter_continuous = unconverted(f["fmi2EnterContinuousTimeMode"])
        self._nz = ctypes.c_size_t(self.nz)
        #: buffers the calls fill or read (ctypes arrays; numpy views share them)
        self.x = (ctypes.c_double * max(self.nx, 1))()
        self.dx = (ctypes.c_double * max(self.nx, 1))()
        self.z = (ctypes.c_double * max(self.nz, 1))()
        self._info = fmi2EventInfo()

    def _instantiate(self, logging_on: bool):
        me = self.description.modelExchange
        if me is None:
            raise NoModelExchange(f"component '{self.name}' (FMU {self.fmu_path.name}) offers co-simulation only, "
                                  "no Model Exchange interface")
        fmu = FMU2Model(guid=self.description.guid, unzipDirectory=self._unzipped, modelIdentifier=me.modelIdentifier,
                        instanceName=self.instance_name)
        fmu.instantiate(callbacks=log_callbacks(), loggingOn=logging_on)
        return fmu

    def _do_step_function(self):
        def refused(handle, t, h, no_set_prior_state):
            self.messages.append("[error] fmi2DoStep: a Model Exchange instance takes no communication steps")
            return 3
        return refused

    @property
    def calls(self) -> int:
        return super().calls + sum(self.me_counts.values())

    @property
    def model_exchange_calls(self) -> dict[str, int]:
        return dict(self.me_counts)

    def _status(self, call: str, status: int):
        if status > 1:
            self.fail(call, status)

    def live_indicators(self) -> int:
        """How many event indicators (the first ones) can change sign: what the FMU's
        ``LIVE_EVENT_INDICATORS`` says after initialization, where it declares that Integer
        calculated parameter with a value in [0, nz]; all ``nz`` otherwise."""
        var = self.variables.get(LIVE_EVENT_INDICATORS)
        if var is None or var.type != "Integer" or var.causality != "calculatedParameter":
            return self.nz
        value = self._checked(f"fmi2GetInteger({LIVE_EVENT_INDICATORS})", self.fmu.getInteger,
                              [var.valueReference])[0]
        return value if 0 <= value <= self.nz else self.nz

    # -- the continuous part -------------------------------------------------------------------
    def set_time(self, t: float):
        self.me_counts["time"] += 1
        status = self.me_raw.set_time(self.raw.handle, ctypes.c_double(t))
        if status > 1:      # the call's text only when it failed: this runs at every right-hand side
            self.fail(set_time_call(t), status)
        self.time = t

    def set_states(self):
        """fmi2SetContinuousStates from ``self.x``."""
        self.me_counts["states"] += 1
        self._status("fmi2SetContinuousStates", self.me_raw.set_states(self.raw.handle, self.x, self._nx))

    def get_states(self):
        """fmi2GetContinuousStates into ``self.x``."""
        self.me_counts["event"] += 1
        self._status("fmi2GetContinuousStates", self._get_states(self.raw.handle, self.x, self._nx))

    def derivatives(self):
        """fmi2GetDerivatives into ``self.dx``."""
        self.me_counts["derivatives"] += 1
        self._status("fmi2GetDerivatives", self.me_raw.get_derivatives(self.raw.handle, self.dx, self._nx))

    def indicators(self):
        """fmi2GetEventIndicators into ``self.z``."""
        self.me_counts["indicators"] += 1
        self._status("fmi2GetEventIndicators", self._get_indicators(self.raw.handle, self.z, self._nz))

    def directional(self, unknowns, n_unknowns, knowns, n_knowns, seeds, out):
        """fmi2GetDirectionalDerivative: ``out`` = d unknowns / d knowns along ``seeds``
        (ctypes arrays and counts, made once by the caller)."""
        self.me_counts["directional"] += 1
        self._status("fmi2GetDirectionalDerivative",
                     self.me_raw.directional(self.raw.handle, unknowns, n_unknowns, knowns, n_knowns, seeds,
                                             out))

    # -- events ------------------------------------------------------------------------------------
    def enter_event_mode(self):
        self.me_counts["event"] += 1
        self._status("fmi2EnterEventMode", self._enter_event(self.raw.handle))

    def new_discrete_states(self) -> fmi2EventInfo:
        """fmi2NewDiscreteStates; the event info it filled (read it before the next call)."""
        self.me_counts["event"] += 1
        self._status("fmi2NewDiscreteStates", self._new_discrete(self.raw.handle, ctypes.byref(self._info)))
        return self._info

    def enter_continuous_time_mode(self):
        self.me_counts["event"] += 1
        self._status("fmi2EnterContinuousTimeMode", self._enter_continuous(self.raw.handle))

    # -- no FMU states in Model Exchange here (canGetAndSetFMUstate is false) -------------------
    def save_state(self):
        raise NotImplementedError(f"{self.name}: a Model Exchange instance is not rolled back; its states are "
                                  "the integrator's")
