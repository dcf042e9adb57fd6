"""A shaft: an inertia driven by an external torque model and the coupling torque,
``I * a = M_ext(t, phi, w) + tau`` (MODEL.md sections 4-5).

The coupling torque over a communication step is ``tau + tau_rate * s`` (``s`` the time
into the step): held constant (zero-order hold, ``tau_rate = 0``) or ramped (first-order
hold), as a co-simulation master gives it.  Where the external torque model has a closed-form
solution (linear engine zone, loads that depend on time only) the step is exact, so the
only error a co-simulation makes is the coupling's; otherwise classical RK4 substeps.
"""
from __future__ import annotations

import math

from .friction import ResistingLoad, integrate
from .parameters import ParameterError


class Shaft:
    def __init__(self, inertia: float, external, max_substep: float = 2.5e-4):
        self.inertia = float(inertia)
        self.external = external
        self.max_substep = float(max_substep)
        #: a load that resists the motion (friction, a brake): its torque at rest depends
        #: on the coupling torque, and its stops and breakaways are located in the step
        self.resisting = isinstance(external, ResistingLoad) and external.sticks

    def rates(self, t, phi, w, tau):
        """``(a, M_ext)``: the acceleration with coupling torque ``tau`` and the
        external torque on the shaft (scalars: the harness maps it over arrays)."""
        if self.resisting:
            external = self.external.torque_with(t, phi, w, tau)
        else:
            external = self.external.torque(t, phi, w)
        return (external + tau) / self.inertia, external

    def acceleration(self, t, phi, w, tau):
        return self.rates(t, phi, w, tau)[0]

    def advance(self, t, phi, w, tau, h, tau_rate=0.0):
        """State after ``h`` seconds with coupling torque ``tau + tau_rate * s``:
        ``(phi, w, external_work)``, where ``external_work`` is the work the external
        torque did on the shaft in the step, from the shaft's own energy balance
        ``dKE = W_ext + W_coupling``."""
        if self.resisting:
            phi1, w1, moment, _ = integrate(self.external, self.inertia, t, phi, w, tau, h, tau_rate,
                                            self._substeps(h))
            work = 0.5 * self.inertia * (w1 * w1 - w * w) - tau * (phi1 - phi) - tau_rate * moment
            return phi1, w1, work
        exact = self.external.advance(self.inertia, t, phi, w, tau, h, tau_rate)
        if exact is not None:
            phi1, w1 = exact
        else:
            phi1, w1 = self._rk4(t, phi, w, tau, h, tau_rate)
        coupling_work = tau * (phi1 - phi)
        if tau_rate:
            coupling_work += tau_rate * self._first_moment_of_speed(t, phi, w, tau, h, tau_rate, phi1, w1)
        work = 0.5 * self.inertia * (w1 * w1 - w * w) - coupling_work
        return phi1, w1, work

    def _first_moment_of_speed(self, t, phi, w, tau, h, tau_rate, phi1, w1):
        """``integral of s * w(s) ds`` over the step, from the cubic Hermite interpolant
        of the speed (error O(h^6), far below the coupling's)."""
        a0 = self.acceleration(t, phi, w, tau)
        a1 = self.acceleration(t + h, phi1, w1, tau + tau_rate * h)
        return h * h * (0.15 * w + 0.35 * w1 + h * (a0 / 30.0 - a1 / 20.0))

    #: RK4 substeps one step may take: beyond it the step is refused, not ground through
    #: for minutes (an importer waiting on doStep would hang).
    MAX_SUBSTEPS = 200_000

    #: RK4's stability limit on the real axis is 2.78 (2.83 on the imaginary): substeps
    #: stay below it for the external torque model's fastest rate
    STABLE = 2.5

    def _substeps(self, h):
        """RK4 substeps a step of ``h`` takes (refused beyond ``MAX_SUBSTEPS``)."""
        ratio = h / self.max_substep
        rate = self.external.rate(self.inertia) if hasattr(self.external, "rate") else 0.0
        needed = max(ratio, h * rate / self.STABLE)
        if not needed <= self.MAX_SUBSTEPS:
            why = (f"of max_substep = {self.max_substep:.6g} s" if needed == ratio else
                   f"to stay stable with the external torque's rate {rate:.3g} 1/s")
            raise ParameterError("max_substep", f"a step of h = {h:.6g} s needs {needed:.3g} RK4 substeps {why}, "
                                 f"more than the {self.MAX_SUBSTEPS} allowed per step: take smaller communication "
                                 "steps, a larger 'max_substep' or a smoother characteristic")
        return max(1, math.ceil(needed - 1e-9))

    def _rk4(self, t, phi, w, tau, h, tau_rate=0.0):
        n = self._substeps(h)
        dt = h / n

        def acc(ti, p, v):
            return self.acceleration(ti, p, v, tau + tau_rate * (ti - t))

        for i in range(n):
            ti = t + i * dt
            k1p, k1w = w, acc(ti, phi, w)
            k2p, k2w = w + 0.5 * dt * k1w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k1p, w + 0.5 * dt * k1w)
            k3p, k3w = w + 0.5 * dt * k2w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k2p, w + 0.5 * dt * k2w)
            k4p, k4w = w + dt * k3w, acc(ti + dt, phi + dt * k3p, w + dt * k3w)
            phi += dt * (k1p + 2.0 * k2p + 2.0 * k3p + k4p) / 6.0
            w += dt * (k1w + 2.0 * k2w + 2.0 * k3w + k4w) / 6.0
        return phi, w
