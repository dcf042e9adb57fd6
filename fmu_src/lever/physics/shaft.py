"""A shaft: an inertia driven by an external torque model and the coupling torque,
``I * a = M_ext(t, phi, w) + tau`` (MODEL.md sections 4-5).

The coupling torque ``tau`` is held constant over a communication step (that is what a
co-simulation master gives a shaft).  Where the external torque model has a closed-form
solution (linear engine zone, loads that depend on time only) the step is exact, so the
only error a co-simulation makes is the coupling's; otherwise classical RK4 substeps.
"""
from __future__ import annotations

import math


class Shaft:
    def __init__(self, inertia: float, external, max_substep: float = 2.5e-4):
        self.inertia = float(inertia)
        self.external = external
        self.max_substep = float(max_substep)

    def rates(self, t, phi, w, tau):
        """``(a, M_ext)``: the acceleration with coupling torque ``tau`` and the
        external torque on the shaft (floats or numpy arrays alike)."""
        external = self.external.torque(t, phi, w)
        return (external + tau) / self.inertia, external

    def acceleration(self, t, phi, w, tau):
        return self.rates(t, phi, w, tau)[0]

    def advance(self, t, phi, w, tau, h):
        """State after ``h`` seconds with held ``tau``: ``(phi, w, external_work)``,
        where ``external_work`` is the work the external torque did on the shaft in
        the step, from the shaft's own energy balance ``dKE = W_ext + tau * dphi``."""
        exact = self.external.advance(self.inertia, t, phi, w, tau, h)
        if exact is not None:
            phi1, w1 = exact
        else:
            phi1, w1 = self._rk4(t, phi, w, tau, h)
        work = 0.5 * self.inertia * (w1 * w1 - w * w) - tau * (phi1 - phi)
        return phi1, w1, work

    def _rk4(self, t, phi, w, tau, h):
        n = max(1, math.ceil(h / self.max_substep - 1e-9))
        dt = h / n
        acc = self.acceleration
        for i in range(n):
            ti = t + i * dt
            k1p, k1w = w, acc(ti, phi, w, tau)
            k2p, k2w = w + 0.5 * dt * k1w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k1p, w + 0.5 * dt * k1w, tau)
            k3p, k3w = w + 0.5 * dt * k2w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k2p, w + 0.5 * dt * k2w, tau)
            k4p, k4w = w + dt * k3w, acc(ti + dt, phi + dt * k3p, w + dt * k3w, tau)
            phi += dt * (k1p + 2.0 * k2p + 2.0 * k3p + k4p) / 6.0
            w += dt * (k1w + 2.0 * k2w + 2.0 * k3w + k4w) / 6.0
        return phi, w
