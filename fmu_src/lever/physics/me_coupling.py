"""The lever coupling's Model Exchange edition (``me_base``): no states, direct feedthrough
from the flanges' angles and speeds (and the misalignment, when a source drives it) to the
torques, with the analytic partials of ``LeverCoupling.partials`` and
``CouplingFamily.alpha_partials``.  Smooth everywhere (the tabulated law is C1): no events.
"""
from __future__ import annotations

from .coupling import CouplingFamily, LeverCoupling
from .me_base import ModelExchange

_FLANGES = ("phi1", "w1", "phi2", "w2")


class CouplingME(ModelExchange):
    """``coupling`` a ``LeverCoupling`` (misalignment fixed) or a ``CouplingFamily`` (the
    misalignment an input)."""

    OUTPUTS = ("tau1", "tau2", "U12", "theta", "elastic_energy", "dissipated_power")

    def __init__(self, coupling: LeverCoupling | CouplingFamily):
        self.family = coupling if isinstance(coupling, CouplingFamily) else None
        self.INPUTS = _FLANGES + (("misalignment",) if self.family else ())
        fixed = coupling.start if self.family else coupling
        self._law, self._damping = fixed.law, fixed.damping
        self._fixed = None if self.family else coupling
        #: whether U12 varies with the driven angle (no: synchronous, or no deformation)
        self._periodic = bool(self.family) or bool(fixed.transfer.coefficients)

    def start(self):
        return []

    def coupling_at(self, u) -> LeverCoupling:
        return self._fixed if self.family is None else self.family.at(u[4])

    def derivatives(self, t, x, u):
        return []

    def outputs(self, t, x, u):
        r = self.coupling_at(u).evaluate(u[0], u[1], u[2], u[3])
        return [r.tau1, r.tau2, r.ratio, r.deflection, r.energy, r.dissipation]

    @property
    def dependencies(self):
        damped = self._damping > 0.0
        speeds = ("w1", "w2") if damped else ()
        ratio = ("phi2",) if self._periodic else ()
        alpha = ("misalignment",) if self.family else ()
        angles = ("phi1", "phi2") + alpha
        torque = ("phi1",) + speeds[:1] + ("phi2",) + speeds[1:] + alpha
        return {"tau1": torque, "tau2": torque, "U12": ratio + alpha, "theta": angles,
                "elastic_energy": angles, "dissipated_power": (speeds + ratio + alpha) if damped else ()}

    def partials(self, t, x, u):
        phi1, w1, phi2, w2 = u[0], u[1], u[2], u[3]
        coupling = self.coupling_at(u)
        r = coupling.evaluate(phi1, w1, phi2, w2)
        d_tau1, d_tau2 = coupling.partials(phi1, w1, phi2, w2)
        slope = coupling.transfer.ratio_slope(phi2)
        elastic = self._law.torque(r.deflection)
        twice = 2.0 * self._damping * r.deflection_rate
        out = {}
        for k, name in enumerate(_FLANGES):
            out["tau1", name], out["tau2", name] = d_tau1[k], d_tau2[k]
        out["U12", "phi2"] = slope
        out["theta", "phi1"], out["theta", "phi2"] = 1.0, -r.ratio
        out["elastic_energy", "phi1"], out["elastic_energy", "phi2"] = elastic, -elastic * r.ratio
        out["dissipated_power", "w1"] = twice
        out["dissipated_power", "w2"] = -twice * r.ratio
        out["dissipated_power", "phi2"] = -twice * slope * w2
        if self.family:
            alpha = u[4]
            d_position, d_ratio = self.family.alpha_slopes(alpha, phi2)
            out["tau1", "misalignment"], out["tau2", "misalignment"] = self.family.alpha_partials(
                alpha, phi1, w1, phi2, w2)
            out["U12", "misalignment"] = d_ratio
            out["theta", "misalignment"] = -d_position
            out["elastic_energy", "misalignment"] = -elastic * d_position
            out["dissipated_power", "misalignment"] = -twice * w2 * d_ratio
        return out
