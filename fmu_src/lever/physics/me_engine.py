"""The engine shaft's Model Exchange edition (``me_base``): ``I dw/dt = M + tau`` with the
engine torque ``M = Mg(w)`` (``Shaft``) or lagging it, ``Te dM/dt = Mg(w) - M``
(``LaggedShaft``, ``M`` a state), and the engine's work ``dW/dt = M w`` a state, all from
``Shaft.rates`` / ``LaggedShaft.rates`` (the monolithic reference's right-hand side too).

A tabulated characteristic is linear between its points: its slope jumps at each point,
so each point is an event indicator ``w - w_k`` (a solver restarts there instead of
stepping over a kink), with hysteresis (``me_base.banded``: ``SPEED_BAND`` off the point
on the side the speed was at the last event, so a speed that starts or rests at a point
is no indicator at zero); the partials take the slope on the right of a point.
"""
from __future__ import annotations

from .engine import TabulatedCharacteristic
from .me_base import SPEED_BAND, ModelExchange, banded, der, edge_side
from .shaft import LaggedShaft, Shaft


class EngineME(ModelExchange):
    INPUTS = ("tau",)
    OUTPUTS = ("phi", "w", "a", "engine_torque", "engine_work")

    def __init__(self, shaft: Shaft | LaggedShaft, phi_start: float = 0.0, w_start: float = 0.0):
        self.shaft = shaft
        self.lagged = isinstance(shaft, LaggedShaft)
        self.STATES = ("phi", "w", "engine_work") + (("engine_torque",) if self.lagged else ())
        self.characteristic = shaft.external
        table = isinstance(self.characteristic, TabulatedCharacteristic)
        self.EVENTS = tuple(f"speed_point_{k}" for k in range(len(self.characteristic.speeds))) if table else ()
        self._start = (float(phi_start), float(w_start))
        #: the side of each point the speed was on at the last event (``edge_side``)
        self.sides = [1.0] * len(self.EVENTS)

    def start(self):
        return list(self._start) + [0.0] + ([self.shaft.torque_start] if self.lagged else [])

    def rates(self, t, x, u):
        """``(a, M)``: the acceleration and the engine torque."""
        if self.lagged:
            return self.shaft.rates(t, x[0], x[1], u[0], x[3])
        return self.shaft.rates(t, x[0], x[1], u[0])

    def derivatives(self, t, x, u):
        a, m = self.rates(t, x, u)
        if self.lagged:
            return [x[1], a, m * x[1], self.shaft.torque_rate(t, x[0], x[1], x[3])]
        return [x[1], a, m * x[1]]

    def outputs(self, t, x, u):
        a, m = self.rates(t, x, u)
        return [x[0], x[1], a, m, x[2]]

    def initialize(self, t, x, u):
        """The sides of the points from the speed."""
        if self.EVENTS:
            self.sides = [edge_side(x[1] - speed) for speed in self.characteristic.speeds]

    def event_indicators(self, t, x, u):
        if not self.EVENTS:
            return []
        return [banded(x[1] - speed, side, SPEED_BAND) for speed, side in zip(self.characteristic.speeds, self.sides)]

    def event_update(self, t, x, u):
        """A point changes no state: the sides follow the speed."""
        self.initialize(t, x, u)
        return list(x)

    @property
    def dependencies(self):
        # the characteristic depends on the speed unless it is a flat line
        speed = ("w",) if (self.EVENTS or getattr(self.characteristic, "slope", 0.0)) else ()
        if self.lagged:
            torque = ("engine_torque",)
            rate = ("engine_torque", "tau")
            work = ("w", "engine_torque")
            lag = {der("engine_torque"): speed + torque}
        else:
            torque, rate, work, lag = speed, speed + ("tau",), ("w",), {}
        return {der("phi"): ("w",), der("w"): rate, der("engine_work"): work, **lag,
                "phi": ("phi",), "w": ("w",), "a": rate, "engine_torque": torque, "engine_work": ("engine_work",)}

    def partials(self, t, x, u):
        a, m = self.rates(t, x, u)
        w = x[1]
        out = {(der("phi"), "w"): 1.0, ("phi", "phi"): 1.0, ("w", "w"): 1.0, ("engine_work", "engine_work"): 1.0}
        if self.lagged:
            (_, da_dm, da_dtau), (dr_dw, dr_dm) = self.shaft.partials(t, x[0], w, u[0], x[3])
            out[der("w"), "engine_torque"] = out["a", "engine_torque"] = da_dm
            out[der("w"), "tau"] = out["a", "tau"] = da_dtau
            out[der("engine_torque"), "w"], out[der("engine_torque"), "engine_torque"] = dr_dw, dr_dm
            out[der("engine_work"), "w"], out[der("engine_work"), "engine_torque"] = m, w
            out["engine_torque", "engine_torque"] = 1.0
            return out
        _, dm_dw, _ = self.shaft.external_partials(t, x[0], w, u[0])
        _, da_dw, da_dtau = self.shaft.partials(t, x[0], w, u[0])
        out[der("w"), "w"] = out["a", "w"] = da_dw
        out[der("w"), "tau"] = out["a", "tau"] = da_dtau
        out[der("engine_work"), "w"] = dm_dw * w + m
        out["engine_torque", "w"] = dm_dw
        return out
