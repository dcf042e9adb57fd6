"""The freewheel rectifier's Model Exchange edition (``me_base``): the states of
``freewheel.STATE``, the port torque ``tau`` as input, the disc and flywheel modes as
discrete state.  Its event indicators are ``FreewheelRectifier.event_values``: the six gap
edges (sign changes both ways; no state changes there, the right-hand side's branch
follows the deflection) and the two mode functions (positive while the mode holds;
``FreewheelRectifier.switch`` at zero), the ones the monolithic reference locates.

Outputs here are the port's (the flywheel's angle, speed and acceleration); the FMU's
other outputs are ``named_outputs`` of the same state.
"""
from __future__ import annotations

from .freewheel import EVENTS, N_EDGES, STATE, FreewheelRectifier
from .me_base import ModelExchange, der


class FreewheelME(ModelExchange):
    STATES = STATE
    INPUTS = ("tau",)
    OUTPUTS = ("phi", "w", "a")
    EVENTS = EVENTS

    def __init__(self, model: FreewheelRectifier):
        self.model = model
        self.disc = self.fly = None

    def start(self):
        y, self.disc, self.fly = self.model.start()
        return y

    def derivatives(self, t, x, u):
        return self.model.derivatives(t, x, self.disc, self.fly, u[0])

    def outputs(self, t, x, u):
        return [x[6], x[7], self.model.forces(t, x, self.disc, self.fly, u[0])[3]]

    def event_indicators(self, t, x, u):
        return self.model.event_values(t, x, self.disc, self.fly, u[0])

    def event_update(self, t, x, u):
        """Switches each mode whose function has reached zero (a gap edge changes no state)."""
        values = self.event_indicators(t, x, u)
        x = list(x)
        for which in (N_EDGES, N_EDGES + 1):
            if values[which] <= 0.0:
                x, self.disc, self.fly = self.model.switch(t, x, self.disc, self.fly, which, u[0])
        return x

    @property
    def dependencies(self):
        # the chain is a line: each body's acceleration depends on its neighbours' angles
        # and speeds only (the rocker is prescribed)
        deps = {der(s): d for s, d in zip(STATE, (
            ("w2",), ("phi2", "w2", "phi3", "w3", "phi4", "w4"), ("w3",), ("phi2", "w2", "phi3", "w3", "phi4", "w4"),
            ("w4",), ("phi3", "w3", "phi4", "w4", "phi5", "w5"), ("w5",), ("phi4", "w4", "phi5", "w5", "tau"),
            ("phi2", "w2"), ("phi4", "w4", "phi5", "w5", "tau"),
            ("phi2", "w2", "w3", "w4", "w5")))}
        deps.update({"phi": ("phi5",), "w": ("w5",), "a": deps[der("w5")]})
        return deps

    def partials(self, t, x, u):
        rows = self.model.jacobian(t, x, self.disc, self.fly, u[0])
        columns = STATE + ("tau",)
        out = {(der(s), c): v for s, row in zip(STATE, rows) for c, v in zip(columns, row) if v != 0.0}
        out["phi", "phi5"] = out["w", "w5"] = 1.0
        out.update({("a", c): v for c, v in zip(columns, rows[7]) if v != 0.0})
        return out
