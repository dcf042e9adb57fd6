"""The unsplit driveline (engine shaft - lever coupling - load shaft) as one system of
ODEs: the right-hand side the monolithic reference integrates and its analytic Jacobian
(docs/physics.md#model-exchange-interface).

State ``y = [phi1, w1, phi2, w2, W_engine, W_load, E_dissipated]`` (``+ [M]``, the engine
torque, for a lagged engine).  The right-hand side is made of the same functions the
Model Exchange editions use (``Shaft.rates``, ``LaggedShaft.rates``/``torque_rate``,
``LeverCoupling.evaluate``, ``ResistingLoad.slip_torque``) and the Jacobian of their
partials (``LeverCoupling.partials``, ``Shaft.partials``, ``LaggedShaft.partials``).
"""
from __future__ import annotations

from .shaft import LaggedShaft, Shaft

#: a resisting load's mode: slipping (+1/-1), held (0); None: the load has none (or the
#: memoryless law of ``Shaft.rates`` decides)
HELD = 0


class Driveline:
    """``engine`` a ``Shaft`` or ``LaggedShaft``; ``coupling_at(t)`` the ``LeverCoupling``
    at time ``t`` (one coupling, or a family's at the misalignment of the time); ``load``
    a ``Shaft``."""

    def __init__(self, engine: Shaft | LaggedShaft, coupling_at, load: Shaft):
        self.engine, self.coupling_at, self.load = engine, coupling_at, load
        self.lagged = isinstance(engine, LaggedShaft)
        self.size = 8 if self.lagged else 7

    def derivatives(self, t, y, mode=None) -> list:
        """``dy/dt``; ``mode`` the resisting load's (None: ``Shaft.rates``' own law)."""
        p1, v1, p2, v2 = y[0], y[1], y[2], y[3]
        r = self.coupling_at(t).evaluate(p1, v1, p2, v2)
        if self.lagged:
            # the engine torque M lags its characteristic: an eighth state, after the works
            a1, m1 = self.engine.rates(t, p1, v1, r.tau1, y[7])
            lag_rate = [self.engine.torque_rate(t, p1, v1, y[7])]
        else:
            a1, m1 = self.engine.rates(t, p1, v1, r.tau1)
            lag_rate = []
        if mode is None:
            a2, m2 = self.load.rates(t, p2, v2, r.tau2)
        elif mode == HELD:
            return [v1, a1, 0.0, 0.0, m1 * v1, 0.0, r.dissipation] + lag_rate
        else:
            m2 = self.load.external.slip_torque(t, p2, v2, mode)
            a2 = (m2 + r.tau2) / self.load.inertia
        return [v1, a1, v2, a2, m1 * v1, -m2 * v2, r.dissipation] + lag_rate

    def jacobian(self, t, y, mode=None) -> list[list[float]]:
        """``d(dy/dt)/dy``, analytic, dense rows (see docs/physics.md for the terms)."""
        n = self.size
        jac = [[0.0] * n for _ in range(n)]
        p1, v1, p2, v2 = y[0], y[1], y[2], y[3]
        coupling = self.coupling_at(t)
        r = coupling.evaluate(p1, v1, p2, v2)
        d_tau1, d_tau2 = coupling.partials(p1, v1, p2, v2)
        jac[0][1] = 1.0
        if self.lagged:
            (_, da_dm, da_dtau), (dr_dw, dr_dm) = self.engine.partials(t, p1, v1, r.tau1, y[7])
            jac[1][7] = da_dm
            jac[4][1], jac[4][7] = y[7], v1
            jac[7][1], jac[7][7] = dr_dw, dr_dm
        else:
            _, dm_dw, _ = self.engine.external_partials(t, p1, v1, r.tau1)
            _, da_dw, da_dtau = self.engine.partials(t, p1, v1, r.tau1)
            jac[1][1] = da_dw
            jac[4][1] = dm_dw * v1 + self.engine.rates(t, p1, v1, r.tau1)[1]
        for j in range(4):
            jac[1][j] += da_dtau * d_tau1[j]
        twice = 2.0 * coupling.damping * r.deflection_rate
        jac[6][1], jac[6][2], jac[6][3] = twice, -twice * coupling.transfer.ratio_slope(p2) * v2, -twice * r.ratio
        if mode == HELD:
            return jac
        jac[2][3] = 1.0
        if mode is None:
            dm = self.load.external_partials(t, p2, v2, r.tau2)
            m2 = self.load.rates(t, p2, v2, r.tau2)[1]
        else:
            dm = self.load.external.slip_partials(t, p2, v2, mode) + (0.0,)
            m2 = self.load.external.slip_torque(t, p2, v2, mode)
        inertia = self.load.inertia
        jac[3][2] += dm[0] / inertia
        jac[3][3] += dm[1] / inertia
        jac[5][2] = -dm[0] * v2
        jac[5][3] = -(dm[1] * v2 + m2)
        for j in range(4):
            jac[3][j] += (dm[2] + 1.0) / inertia * d_tau2[j]
            jac[5][j] -= dm[2] * v2 * d_tau2[j]
        return jac
