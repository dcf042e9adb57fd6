"""The base of our FMUs: a pythonfmu slave that declares its variables from the physics'
``Parameter`` lists and follows the FMI 2.0 co-simulation state machine (instantiated ->
initialization -> stepping -> terminated), building the physics and computing its outputs
when they are read.  Its entry points never raise (``guard``); set values are judged by
``values``, states saved and restored by ``states``, the model description written by
``model_description``.
"""
from __future__ import annotations

import json
import math
import operator
from pathlib import Path
from typing import Sequence

from pythonfmu import Boolean, Fmi2Slave, Real, Integer, String, Fmi2Causality, Fmi2Variability, Fmi2Initial
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from ..physics.parameters import Parameter, ParameterError
from .. import __version__
from .declarations import MechanicalPort, Output
from .guard import guarded
from .model_description import START_VALUES_RESOURCE, ModelDescription
from .recompute import ALL, CLEAN, INPUTS_CHANGED
from .states import StateSaving
from .values import ValueChecks, closed_bounds


def _nan_values(self, vrs):
    return [math.nan] * len(vrs)


def _reader_of(names):
    """A getter of the attributes ``names`` of a slave, as a tuple (attrgetter's own for two
    or more; it gives one attribute alone, and nothing for none)."""
    if len(names) > 1:
        return operator.attrgetter(*names)
    if names:
        single = operator.attrgetter(names[0])
        return lambda slave: (single(slave),)
    return lambda slave: ()


_LIVE = ("initialization", "stepping")


class LeverSlave(ValueChecks, StateSaving, ModelDescription, Fmi2Slave):
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
        self._dirty = ALL              # what must be recomputed before outputs are read
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
        self._readers = {}             # value references read -> getter (``_read_reals``)
        self._fast_inputs = {}
        for vr, p in self._settable.items():
            if p.kind == "real" and not p.fixed:
                self._fast_inputs[vr] = (p.name, *closed_bounds(p))
        self._outputs_of = _reader_of([o.name for o in self.OUTPUTS]) if self.OUTPUTS else None   # a tuple
        self._take_configured_start_values()

    def _take_configured_start_values(self):
        """The start values of ``resources/lever_start_values.json`` where the FMU holds one
        (an FMU configured for a scene, e.g. in an SSP export: its model description's start
        values and GUID say the same).  A value that does not fit is refused here, so the
        instance is not made, rather than starting from something else."""
        path = Path(self.resources) / START_VALUES_RESOURCE if self.resources else None
        if path is None or not path.is_file():
            return
        values = json.loads(path.read_text(encoding="utf-8"))
        for name, value in values.items():
            p = self._declared.get(name)
            if not isinstance(p, Parameter):
                raise ParameterError(name, f"{START_VALUES_RESOURCE} sets '{name}', which is no parameter or "
                                           f"input of {type(self).__name__}")
            setattr(self, name, p.check(value))

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
        self._dirty = ALL
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
        if self._model_stale:
            self._build_for_reading()
        if self._dirty and self._phase in _LIVE:
            self._refresh()
        return self._read_reals(vrs)

    #: lists of value references a reader is kept for (a master reads the same few each step)
    READERS_KEPT = 64

    def _read_reals(self, vrs) -> list:
        """The Real variables ``vrs`` as floats, read by a getter made once for each list of
        value references a host reads; an unknown reference is an error (NaN values)."""
        key = tuple(vrs)
        read = self._readers.get(key)
        if read is None:
            names = self._real_names
            if not all(vr in names for vr in key):
                unknown = next(vr for vr in key if vr not in names)
                self._error(f"fmi2GetReal: value reference {unknown} is no Real variable of {type(self).__name__}")
                return _nan_values(self, vrs)
            if len(self._readers) >= self.READERS_KEPT:
                self._readers.clear()
            read = self._readers[key] = _reader_of([names[vr] for vr in key])
        return [*map(float, read(self))]

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
                    self._dirty = INPUTS_CHANGED
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

    def _build_for_reading(self):
        """Parameters set in Initialization Mode: what is read there comes from the model
        they make (judged at fmi2ExitInitializationMode), never from the one before."""
        if self._model_stale and self._phase == "initialization":
            self._try_build(report=False)

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
        self._dirty = ALL

    def _refresh(self):
        if self._build_error is None and not self._model_stale:
            if self._dirty == ALL:
                self._compute_outputs()
            else:
                self._compute_input_outputs()
            self._dirty = CLEAN
            # One test for all outputs: their sum is finite unless one is not (or the sum
            # overflows, which the test below sorts out).
            if self._outputs_of is None:
                return
            total = sum(self._outputs_of(self))
            if total - total == 0.0:
                return
            bad = [o.name for o in self.OUTPUTS if not math.isfinite(getattr(self, o.name))]
            if bad:
                # Reported at every read until the inputs change: never a silent NaN.
                self._dirty = ALL
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
