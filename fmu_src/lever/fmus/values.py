"""Values an importer sets, judged against the declarations: the variable exists, is of the
call's type, may be set in the instance's phase, and lies in its declared range."""
from __future__ import annotations

import math

from pythonfmu import Boolean, Integer, Real, String

from ..physics.parameters import Parameter, ParameterError
from .recompute import ALL, INPUTS_CHANGED

_KINDS = {Real: "Real", Integer: "Integer", String: "String", Boolean: "Boolean"}


def closed_bounds(p: Parameter) -> tuple[float, float]:
    """The inclusive bounds of what ``p`` accepts: an open bound moved in to the nearest
    double inside it (FMI's min and max are inclusive)."""
    low = math.nextafter(p.low, math.inf) if p.low_open else p.low
    high = math.nextafter(p.high, -math.inf) if p.high_open else p.high
    return low, high


class ValueChecks:
    """``fmi2Set<kind>`` of a ``LeverSlave`` (its ``vars``, ``_settable``, ``_phase``)."""

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
                self._error(f"{call}: '{var.name}' (value reference {vr}) is a {_KINDS[type(var)]} variable; "
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
        self._dirty = ALL if any(p.fixed for p, _ in checked) else max(self._dirty, INPUTS_CHANGED)
