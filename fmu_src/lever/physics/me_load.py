"""The load shaft's Model Exchange edition (``me_base``): ``I dw/dt = M + tau`` with the
load's external torque ``M = -Mc`` (and friction), the work the load absorbs ``dW/dt = -M w``
a state.

A load that can stick (``friction.ResistingLoad`` with Coulomb friction, stiction or a
brake) has a discrete mode: slipping in direction ``+1``/``-1`` (``M`` the slip torque,
smooth up to the stop) or held (``0``: at rest, static friction balances the drive, every
derivative 0), the same modes the monolithic reference switches.  Its event indicator is
positive while the mode holds, with hysteresis (``me_base.banded``): ``direction * w +
SPEED_BAND`` slipping (a breakaway starts at rest; the stop comes when the speed has
reversed by the band, and puts the shaft at rest), ``hold - |net| + TORQUE_BAND`` held (it
may be entered with the drive at the breakaway torque).
"""
from __future__ import annotations

import math

from .friction import ResistingLoad
from .load import FourierLoad, SpectrumLoad, TabulatedLoad
from .me_base import SPEED_BAND, TORQUE_BAND, ModelExchange, banded, der
from .shaft import Shaft

HELD = 0


def base_law(load):
    """The load's law without its friction (``ResistingLoad.base``), or the load itself."""
    return load.base if isinstance(load, ResistingLoad) else load


def depends_on_angle(load) -> bool:
    """Whether the load's resistance depends on the driven angle."""
    base = base_law(load)
    return isinstance(base, FourierLoad) or (isinstance(base, SpectrumLoad) and base.order_amplitude != 0.0)


class LoadME(ModelExchange):
    STATES = ("phi", "w", "load_work")
    INPUTS = ("tau",)
    OUTPUTS = ("phi", "w", "a", "load_torque", "load_work")

    def __init__(self, shaft: Shaft, phi_start: float = 0.0, w_start: float = 0.0):
        self.shaft = shaft
        self.friction = shaft.external if shaft.resisting else None
        self.EVENTS = ("stick_slip",) if self.friction else ()
        self._start = (float(phi_start), float(w_start))
        #: +1/-1 slipping, HELD at rest; None without friction that sticks
        self.mode = None
        base = base_law(shaft.external)
        #: a time-table load's table (its points are time events), resolved once here
        self._time_table = base.table if isinstance(base, TabulatedLoad) else None

    def start(self):
        return list(self._start) + [0.0]

    def mode_at(self, t, x, u) -> int:
        """The memoryless law's mode (``ResistingLoad``): held where it sticks, else the
        direction of the speed, at rest the direction of the net torque."""
        if self.friction.stuck(t, x[0], x[1], u[0]):
            return HELD
        if x[1] != 0.0:
            return int(math.copysign(1.0, x[1]))
        return int(math.copysign(1.0, self.friction.breakaway_margin(t, x[0], u[0])[1]))

    def initialize(self, t, x, u):
        """Sets the mode where the inputs are first known (end of initialization)."""
        if self.friction:
            self.mode = self.mode_at(t, x, u)

    def modes(self) -> tuple:
        return (self.mode,)

    def rates(self, t, x, u):
        """``(a, M)`` in the current mode."""
        if self.friction is None:
            return self.shaft.rates(t, x[0], x[1], u[0])
        if self.mode == HELD:
            return 0.0, -u[0]
        m = self.friction.slip_torque(t, x[0], x[1], self.mode)
        return (m + u[0]) / self.shaft.inertia, m

    def derivatives(self, t, x, u):
        if self.mode == HELD:
            return [0.0, 0.0, 0.0]
        a, m = self.rates(t, x, u)
        return [x[1], a, -m * x[1]]

    def outputs(self, t, x, u):
        a, m = self.rates(t, x, u)
        return [x[0], x[1], a, -m, x[2]]

    def event_indicators(self, t, x, u):
        if self.friction is None:
            return []
        if self.mode == HELD:
            return [banded(-self.friction.breakaway_margin(t, x[0], u[0])[0], 1.0, TORQUE_BAND)]
        return [banded(self.mode * x[1], 1.0, SPEED_BAND)]

    def event_update(self, t, x, u):
        """A stop puts the shaft at rest exactly and the stick condition decides; a
        breakaway slips off in the direction of the net torque."""
        x = list(x)
        if self.friction is None:
            return x
        # decided by the law's own rule, unbanded: the mode follows the state wherever an
        # event iteration runs (at the banded root, or where a host set the state)
        if self.mode == HELD:
            margin, net = self.friction.breakaway_margin(t, x[0], u[0])
            if margin > 0.0:
                self.mode = int(math.copysign(1.0, net))
        elif self.mode * x[1] <= 0.0:
            x[1] = 0.0
            self.mode = self.mode_at(t, x, u)
        return x

    def next_time_event(self, t: float) -> float | None:
        """A time-table load's next point after ``t``, or None.  Its torque's slope jumps
        there, and a held shaft's breakaway margin with it: over a steep piece (a brake
        released in 10 ms) the margin can cross zero and back within one of the
        integrator's steps, which a held shaft (every derivative 0) lets grow long - a
        root finder that compares signs at the steps' ends would miss the breakaway."""
        return self._time_table.next_time(t) if self._time_table is not None else None

    @property
    def dependencies(self):
        external = self.shaft.external
        angle = ("phi",) if depends_on_angle(external) else ()
        speed = ("w",) if getattr(external, "viscous", 0.0) else ()
        held = ("tau",) if self.friction else ()
        rate = angle + speed + ("tau",)
        return {der("phi"): ("w",), der("w"): rate, der("load_work"): angle + ("w",),
                "phi": ("phi",), "w": ("w",), "a": rate, "load_torque": angle + speed + held,
                "load_work": ("load_work",)}

    def external_partials(self, t, x, u):
        """``(dM/dphi, dM/dw, dM/dtau)`` in the current mode."""
        if self.friction is None:
            return self.shaft.external_partials(t, x[0], x[1], u[0])
        if self.mode == HELD:
            return 0.0, 0.0, -1.0
        return self.friction.slip_partials(t, x[0], x[1], self.mode) + (0.0,)

    def partials(self, t, x, u):
        out = {("phi", "phi"): 1.0, ("w", "w"): 1.0, ("load_work", "load_work"): 1.0}
        dm = self.external_partials(t, x, u)
        for name, d in zip(("phi", "w", "tau"), dm):
            out["load_torque", name] = -d
        if self.mode == HELD:
            return out
        a, m = self.rates(t, x, u)
        inertia = self.shaft.inertia
        out[der("phi"), "w"] = 1.0
        for name, d in zip(("phi", "w", "tau"), dm):
            out[der("w"), name] = out["a", name] = (d + (name == "tau")) / inertia
        out[der("load_work"), "phi"] = -dm[0] * x[1]
        out[der("load_work"), "w"] = -(dm[1] * x[1] + m)
        return out
