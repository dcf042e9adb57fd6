"""Loads that resist the motion (docs/physics.md#active-and-resistive-loads-friction): Coulomb friction with
stiction, viscous friction, and the technological resistance ``Mc = Mm +- dM`` applied as
a brake - against the motion, holding the shaft at rest - instead of as an active torque.

A ``ResistingLoad`` wraps any load of ``lever.physics.load`` (its ``Mc(t, phi)``) and
splits the torque on the shaft into

* ``active(t, phi)``: what does not depend on the motion (``-Mc`` for an active load, 0
  when ``Mc`` is a brake);
* ``slip(t, phi)``: the magnitude of the kinetic resistance, ``Fc + max(Mc, 0)`` for a
  brake (a brake does not drive: a negative ``Mc`` brakes with 0), ``Fc`` otherwise;
* ``hold(t, phi)``: the largest torque static friction holds at rest, the breakaway
  ``Fs`` (+ ``max(Mc, 0)`` for a brake);
* the viscous part ``-b_v * w``.

The law (Karnopp's): a moving shaft (``w != 0``) feels ``active - sign(w) slip - b_v w``;
a shaft at rest (``w == 0.0`` exactly) with a net driving torque ``net = active + tau``
stays at rest while ``|net| <= hold`` (static friction gives ``-tau``: the shaft's
acceleration is 0), and otherwise slips off in the direction of ``net``.  Whether the
shaft sticks is therefore a function of its state and input: a stuck shaft is one at
``w == 0.0`` exactly (the integrators below put it there when they locate the stop),
and its serialized speed carries the stuck flag.

``Shaft`` (``lever.physics.shaft``) integrates a shaft with such a load by RK4 substeps of
fixed slip direction, locating inside the step each stop (``w`` through zero) and each
breakaway (``|net|`` through ``hold``); the monolithic reference switches the same modes
with scipy's events, with the same functions of this module.
"""
from __future__ import annotations

import math

from .parameters import ParameterError

DIRECTIONS = ("active", "resistive")


class ResistingLoad:
    """A load ``base`` (with ``base.resistance(t, phi, w)`` = ``Mc``) plus friction;
    ``direction`` "resistive" makes ``Mc`` itself a brake (see the module docstring)."""

    def __init__(self, base, direction: str = "active", coulomb: float = 0.0, breakaway: float = 0.0,
                 viscous: float = 0.0):
        self.base = base
        self.resistive = direction == "resistive"
        self.direction = direction
        self.coulomb = float(coulomb)          # Fc [N.m]
        self.breakaway = float(breakaway)      # Fs >= Fc [N.m]
        self.viscous = float(viscous)          # b_v [N.m.s/rad]
        self.mean = base.mean
        #: whether the shaft can stick (Coulomb friction, stiction or a brake); without, the
        #: load is smooth (viscous only) and the shaft takes plain RK4 substeps
        self.sticks = self.resistive or self.coulomb > 0.0 or self.breakaway > 0.0

    # -- the parts of the law -------------------------------------------------------------
    def parts(self, t, phi) -> tuple[float, float, float]:
        """``(active, slip, hold)`` at time ``t`` and angle ``phi``."""
        mc = self.base.resistance(t, phi, 0.0)
        if self.resistive:
            brake = mc if mc > 0.0 else 0.0
            return 0.0, self.coulomb + brake, self.breakaway + brake
        return -mc, self.coulomb, self.breakaway

    def slip_torque(self, t, phi, w, direction: float) -> float:
        """External torque on a shaft slipping in ``direction`` (+1 or -1; kept through a
        substep, so the right-hand side stays smooth up to the located stop)."""
        active, slip, _ = self.parts(t, phi)
        return active - direction * slip - self.viscous * w

    def slip_partials(self, t, phi, w, direction: float) -> tuple[float, float]:
        """``(d/dphi, d/dw)`` of ``slip_torque``: the wrapped load's angle slope (a brake's
        only where ``Mc > 0``, as ``parts`` clips it; at ``Mc = 0`` the side where it is 0)
        and the viscous ``-b_v``."""
        slope = self.base.resistance_slope(t, phi, 0.0)
        if self.resistive:
            slope = direction * slope if self.base.resistance(t, phi, 0.0) > 0.0 else 0.0
        return -slope, -self.viscous

    def breakaway_margin(self, t, phi, tau) -> tuple[float, float]:
        """``(|net| - hold, net)`` at rest with coupling torque ``tau``: the shaft breaks
        away where the margin is positive, in the direction of ``net``."""
        active, _, hold = self.parts(t, phi)
        net = active + tau
        return abs(net) - hold, net

    def torque_with(self, t, phi, w, tau) -> float:
        """The external torque on the shaft in state ``(phi, w)`` with coupling torque
        ``tau`` (the whole law; scalars only)."""
        if w != 0.0:
            return self.slip_torque(t, phi, w, math.copysign(1.0, w))
        margin, net = self.breakaway_margin(t, phi, tau)
        if margin <= 0.0:
            return -tau                      # held: static friction balances the drive
        return self.slip_torque(t, phi, w, math.copysign(1.0, net))

    def stuck(self, t, phi, w, tau) -> bool:
        return w == 0.0 and self.breakaway_margin(t, phi, tau)[0] <= 0.0

    def resistance(self, t, phi, w):
        """``Mc`` of the wrapped load (what the scene calls the technological load)."""
        return self.base.resistance(t, phi, w)

    def torque(self, t, phi, w):
        """The external torque where the coupling torque is not known (no stiction
        applies: at rest the kinetic part is left out)."""
        direction = 0.0 if w == 0.0 else math.copysign(1.0, w)
        return self.slip_torque(t, phi, w, direction)

    def rate(self, inertia: float) -> float:
        """Fastest rate [1/s] of the shaft's own dynamics: the viscous pole and the
        wrapped load's angle stiffness (for a stable RK4 substep)."""
        own = self.viscous / inertia
        base = self.base.rate(inertia) if hasattr(self.base, "rate") else 0.0
        return max(own, base)

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        return None     # no closed form: the shaft integrates with located events

    #: stops and breakaways one communication step may hold before it is refused as chatter
    MAX_EVENTS = 10_000


def integrate(load: ResistingLoad, inertia: float, t: float, phi: float, w: float, tau: float, h: float,
              tau_rate: float, substeps: int) -> tuple[float, float, float, int]:
    """One communication step ``[t, t + h]`` of a shaft with a resisting load and coupling
    torque ``tau + tau_rate * s``: ``(phi, w, moment, events)`` with ``moment`` the
    integral of ``s * w(s) ds`` (the ramp's share of the coupling's work) and ``events``
    the number of stops and breakaways located.  RK4 in ``substeps`` equal substeps, each
    with the slip direction fixed; a substep over which ``w`` passes zero is cut at the
    zero (regula falsi on the RK4 step's length), the shaft is put at rest exactly and the
    stick condition decides; at rest the breakaway is located by bisection of the margin."""
    dt = h / substeps
    s = 0.0
    moment = 0.0
    events = 0
    margin, net = load.breakaway_margin(t, phi, tau)
    stuck = w == 0.0 and margin <= 0.0
    direction = math.copysign(1.0, w) if w != 0.0 else math.copysign(1.0, net)
    while s < h:
        step = min(dt, h - s)
        if h - s - step < 1e-12 * h:
            step = h - s
        if stuck:
            end = s + step
            margin_end, _ = load.breakaway_margin(t + end, phi, tau + tau_rate * end)
            if margin_end <= 0.0:
                s = end
                continue
            low, high = s, end              # margin <= 0 at low, > 0 at high
            for _ in range(200):
                mid = 0.5 * (low + high)
                if not low < mid < high:
                    break
                if load.breakaway_margin(t + mid, phi, tau + tau_rate * mid)[0] <= 0.0:
                    low = mid
                else:
                    high = mid
            s = high
            _, net = load.breakaway_margin(t + s, phi, tau + tau_rate * s)
            direction = math.copysign(1.0, net)
            stuck = False
            events += 1
        else:
            new = _rk4(load, inertia, t, s, phi, w, moment, tau, tau_rate, step, direction)
            if new[1] * direction > 0.0:
                phi, w, moment = new
                s += step
                continue
            # w reached or passed zero in this substep: cut it at the zero
            low, high = 0.0, step            # w * direction > 0 at low, <= 0 at high
            w_low, w_high = w * direction, new[1] * direction
            cut = new
            side = 0
            for _ in range(100):
                x = low + (high - low) * w_low / (w_low - w_high) if w_low != w_high else 0.5 * (low + high)
                if not low < x < high:
                    x = 0.5 * (low + high)
                    if not low < x < high:
                        break
                trial = _rk4(load, inertia, t, s, phi, w, moment, tau, tau_rate, x, direction)
                value = trial[1] * direction
                if value > 0.0:
                    low, w_low = x, value
                    if side == -1:
                        w_high *= 0.5        # Illinois: the stale end's weight halved
                    side = -1
                else:
                    high, w_high, cut = x, value, trial
                    if side == 1:
                        w_low *= 0.5
                    side = 1
                if high - low <= 1e-14 * h:
                    break
            phi, _, moment = cut
            w = 0.0
            s += high
            events += 1
            margin, net = load.breakaway_margin(t + s, phi, tau + tau_rate * s)
            if margin <= 0.0:
                stuck = True
            else:
                direction = math.copysign(1.0, net)
        if events > ResistingLoad.MAX_EVENTS:
            raise ChatterError(t, h, events)
    return phi, w, moment, events


class ChatterError(ParameterError):
    def __init__(self, t, h, events):
        super().__init__("breakaway_torque", f"the shaft stopped and broke away more than {ResistingLoad.MAX_EVENTS} times in the "
                         f"step from t = {t:.9g} s of h = {h:.6g} s (chattering friction): take smaller steps")


def _rk4(load, inertia, t, s, phi, w, moment, tau, tau_rate, dt, direction):
    """One RK4 step of ``(phi, w, moment)`` from ``s`` (time into the communication step)
    with the slip direction held."""

    def acc(x, p, v):
        return (load.slip_torque(t + x, p, v, direction) + tau + tau_rate * x) / inertia

    k1p, k1w, k1m = w, acc(s, phi, w), s * w
    mid = s + 0.5 * dt
    w2 = w + 0.5 * dt * k1w
    k2p, k2w, k2m = w2, acc(mid, phi + 0.5 * dt * k1p, w2), mid * w2
    w3 = w + 0.5 * dt * k2w
    k3p, k3w, k3m = w3, acc(mid, phi + 0.5 * dt * k2p, w3), mid * w3
    w4 = w + dt * k3w
    k4p, k4w, k4m = w4, acc(s + dt, phi + dt * k3p, w4), (s + dt) * w4
    return (phi + dt * (k1p + 2.0 * k2p + 2.0 * k3p + k4p) / 6.0,
            w + dt * (k1w + 2.0 * k2w + 2.0 * k3w + k4w) / 6.0,
            moment + dt * (k1m + 2.0 * k2m + 2.0 * k3m + k4m) / 6.0)
