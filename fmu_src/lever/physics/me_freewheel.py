"""The freewheel rectifier's Model Exchange edition (``me_base``): the states of
``freewheel.STATE``, the port torque ``tau`` as input, the disc and flywheel modes as
discrete state.  Its event indicators are ``FreewheelRectifier.event_values`` (the ones the monolithic
reference and the co-simulation edition locate) with hysteresis (``me_base.banded``): the
six gap edges (sign changes both ways; no state changes there, the right-hand side's
branch follows the deflection), each ``ANGLE_BAND`` off its edge on the side the state was
at the last event, and the two mode functions (positive while the mode holds), a slip's
or a sliding flywheel's plus ``SPEED_BAND`` (a slip starts at equal speeds), a stuck one's
plus ``TORQUE_BAND`` (it may be entered with the torque at the capacity); at the event the
update switches (``FreewheelRectifier.switch``) each mode the rectifier's own unbanded rule
says has ended (``ended``).  The start state sits
on every gap's back edge and at rest: without the bands a host's root finding meets
indicators that are zero, or round-off around zero, from the first step on.

Outputs here are the port's (the flywheel's angle, speed and acceleration); the FMU's
other outputs are ``named_outputs`` of the same state.
"""
from __future__ import annotations

from .freewheel import EVENTS, FREE, N_EDGES, STATE, STICK, FreewheelRectifier
from .me_base import ANGLE_BAND, SPEED_BAND, TORQUE_BAND, ModelExchange, banded, der, edge_side


class FreewheelME(ModelExchange):
    STATES = STATE
    INPUTS = ("tau",)
    OUTPUTS = ("phi", "w", "a")
    EVENTS = EVENTS

    def __init__(self, model: FreewheelRectifier):
        self.model = model
        self.disc = self.fly = None
        #: the side of each gap edge the state was on at the last event (``edge_side``)
        self.sides = [1.0] * N_EDGES

    def start(self):
        y, self.disc, self.fly = self.model.start()
        self.initialize(0.0, y, [0.0])
        return y

    def derivatives(self, t, x, u):
        return self.model.derivatives(t, x, self.disc, self.fly, u[0])

    def outputs(self, t, x, u):
        return [x[6], x[7], self.model.forces(t, x, self.disc, self.fly, u[0])[3]]

    def initialize(self, t, x, u):
        """The gap edges' sides from the state (the modes are the edition's)."""
        self.sides = [edge_side(v) for v in self.model.event_values(t, x, self.disc, self.fly, u[0])[:N_EDGES]]

    def modes(self) -> tuple:
        return self.disc, self.fly

    def _mode_band(self, mode: int) -> float:
        return TORQUE_BAND if mode == STICK else (0.0 if mode == FREE else SPEED_BAND)

    def event_indicators(self, t, x, u):
        values = self.model.event_values(t, x, self.disc, self.fly, u[0])
        out = [banded(v, side, ANGLE_BAND) for v, side in zip(values, self.sides)]
        out.append(banded(values[N_EDGES], 1.0, self._mode_band(self.disc)))
        out.append(banded(values[N_EDGES + 1], 1.0, self._mode_band(self.fly)))
        return out

    def ended(self, t, x, u, which: int) -> bool:
        """Whether mode function ``which`` says its mode has ended at ``(t, x)``, by the
        rectifier's own rule (unbanded: a stuck pack or flywheel holds while the torque is
        within its capacity, a slip or slide while its speed is on its side), so the modes
        follow the state wherever an event iteration runs - at the banded root, or where a
        host set the state (a slip ended is equal speeds)."""
        value = self.model.event_values(t, x, self.disc, self.fly, u[0])[which]
        mode = self.disc if which == N_EDGES else self.fly
        return value < 0.0 if mode == STICK else (mode != FREE and value <= 0.0)

    def event_update(self, t, x, u):
        """Switches each mode that has ended (``ended``) - the discs', then the flywheel's,
        each judged at the state the other's switch left - and puts each gap edge's side
        where the state is (a gap edge changes no state)."""
        x = list(x)
        for which in (N_EDGES, N_EDGES + 1):
            if self.ended(t, x, u, which):
                x, self.disc, self.fly = self.model.switch(t, x, self.disc, self.fly, which, u[0])
        self.initialize(t, x, u)
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

    def named_partials(self, t, x, u) -> dict:
        """``{output: {state or input: value}}`` for every output of the FMU
        (``FreewheelRectifier.named_outputs``), analytic (``output_gradients``), the zeros
        left out."""
        columns = STATE + ("tau",)
        return {name: {c: v for c, v in zip(columns, g) if v != 0.0}
                for name, g in self.model.output_gradients(t, x, self.disc, self.fly, u[0]).items()}

    def partials(self, t, x, u):
        rows = self.model.jacobian(t, x, self.disc, self.fly, u[0])
        columns = STATE + ("tau",)
        out = {(der(s), c): v for s, row in zip(STATE, rows) for c, v in zip(columns, row) if v != 0.0}
        out["phi", "phi5"] = out["w", "w5"] = 1.0
        out.update({("a", c): v for c, v in zip(columns, rows[7]) if v != 0.0})
        return out
