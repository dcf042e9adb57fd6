"""The partial derivatives of a Model Exchange FMU's outputs and state derivatives:
``fmi2GetDirectionalDerivative`` and ``fmi3GetOutputDerivatives``.

Directional derivatives are the physics' partials, analytic: those of the physics' model's
outputs and derivatives (``partials``), and for an FMU output beyond them (the freewheel's
torques, flags and energies) the model's ``named_partials``; an output with neither is
refused with fmi2Error and a sentence, never approximated.  The explicit time part of
``fmi3GetOutputDerivatives`` is a central difference in time (``_time_partials``) with a
step independent of the time itself.
"""
from __future__ import annotations

import math

from ..physics.me_base import der
from .base import _nan_values

#: an FMU output beyond the physics' model's outputs: its partials are the model's
#: ``named_partials`` (refused where it has none)
_NUMERICAL = "named"

#: the step [s] of the central difference in time of ``_time_partials``: fixed, not scaled
#: with |t| (at t = 1e6 s a relative step was 1 s against 450 rad/s tones), the differences
#: taken over the step as the floating-point times realise it.  Relative error about
#: (omega h)^2 / 6 + ulp(omega t) / (omega h) for a component of angular frequency omega:
#: 3e-6 + 7e-6 for a 450 rad/s tone at t = 1e6 s (docs/hosts.md)
TIME_STEP = 1e-5


class PartialDerivatives:
    """The partial derivatives of a ``ModelExchangeSlave`` (lever.fmus.model_exchange, whose
    states, inputs and physics' model they are taken at), in both interfaces."""

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
