"""The coupling as a compliant two-flange element (docs/physics.md#linear-law-and-damping).

    theta    = phi1 - Phi(phi2)                 elastic deflection
    thetadot = w1 - U12(phi2) * w2
    T        = T_el(theta) + b * thetadot       torque in the elastic element
    tau1     = -T                               torque on the drive shaft
    tau2     = U12 * T                          torque on the driven shaft

so that ``tau1*w1 + tau2*w2 = -(dV/dt + b*thetadot^2)``: the power the shafts give the
coupling is stored in the rubber or dissipated in it, exactly.  (The monograph's
potential (3.18) multiplies the periodic U12 by the growing angle phi2 and is not used.)
"""
from __future__ import annotations

import math
from typing import NamedTuple

from .elastic import LinearElasticLaw, TabulatedElasticLaw, elastic_law
from .kinematics import BlendedTransferFunction, TransferFunction, transfer_function
from .parameters import ParameterError


class CouplingResult(NamedTuple):
    tau1: float          # torque on the drive shaft [N.m]
    tau2: float          # torque on the driven shaft [N.m]
    ratio: float         # U12 [1]
    deflection: float    # theta [rad]
    deflection_rate: float  # thetadot [rad/s]
    torque: float        # T, torque in the elastic element [N.m]
    energy: float        # V(theta), elastic energy [J]
    dissipation: float   # b*thetadot^2, dissipated power [W]


class LeverCoupling:
    """Transfer function + elastic law + linear damping."""

    def __init__(self, transfer: TransferFunction, law, damping: float):
        if not (math.isfinite(damping) and damping >= 0.0):
            raise ParameterError("damping", f"parameter 'damping' (b) = {damping} is outside its allowed range "
                                 "[0, inf) N.m.s/rad")
        self.transfer = transfer
        self.law = law
        self.damping = float(damping)

    def evaluate(self, phi1, w1, phi2, w2) -> CouplingResult:
        position, ratio = self.transfer.evaluate(phi2)
        theta = phi1 - position
        theta_dot = w1 - ratio * w2
        torque = self.law.torque(theta) + self.damping * theta_dot
        return CouplingResult(-torque, ratio * torque, ratio, theta, theta_dot, torque,
                              self.law.energy(theta), self.damping * theta_dot * theta_dot)

    def torques(self, phi1, w1, phi2, w2) -> tuple[float, float]:
        """Just ``(tau1, tau2)``: the hot path of the reference solver."""
        position, ratio = self.transfer.evaluate(phi2)
        torque = self.law.torque(phi1 - position) + self.damping * (w1 - ratio * w2)
        return -torque, ratio * torque

    def partials(self, phi1, w1, phi2, w2) -> tuple[tuple, tuple]:
        """``(dtau1/dx, dtau2/dx)`` for ``x = (phi1, w1, phi2, w2)``, analytic: with the
        law's stiffness ``k = dT_el/dtheta`` and ``U' = dU12/dphi2`` (``dPhi/dphi2 = U12``),

            dT/dphi1 = k,  dT/dw1 = b,  dT/dphi2 = -k U12 - b U' w2,  dT/dw2 = -b U12
            dtau1 = -dT,   dtau2 = U12 dT (+ T U' for phi2)"""
        position, ratio = self.transfer.evaluate(phi2)
        theta = phi1 - position
        torque = self.law.torque(theta) + self.damping * (w1 - ratio * w2)
        k, b = self.law.stiffness_at(theta), self.damping
        slope = self.transfer.ratio_slope(phi2)
        d_phi2 = -k * ratio - b * slope * w2
        d_w2 = -b * ratio
        return ((-k, -b, -d_phi2, -d_w2),
                (ratio * k, ratio * b, ratio * d_phi2 + torque * slope, ratio * d_w2))

    def eigen_estimate(self, inertia_drive: float, inertia_driven: float) -> tuple[float, float]:
        """Undamped eigenfrequency [rad/s] and damping ratio of the two-inertia chain
        about U12 = 1, from the nominal stiffness: for step-size and stability advice."""
        return coupling_mode(self.law.nominal_stiffness, self.damping, inertia_drive, inertia_driven)


def coupling_mode(stiffness: float, damping: float, inertia_drive: float, inertia_driven: float,
                  engine_slope: float = 0.0, driven_slope: float = 0.0) -> tuple[float, float]:
    """Undamped eigenfrequency ``omega_n = sqrt(c / I_red)`` [rad/s], ``I_red = I1*I2/(I1 + I2)``,
    and modal damping ratio of the two-inertia chain's coupling mode about U12 = 1.  The
    drive shaft moves ``I2/(I1 + I2)`` of the deflection, so an engine slope ``K1`` damps
    the mode too, and the driven shaft's ``I1/(I1 + I2)`` lets a viscous load ``b_v`` damp it:
    ``zeta = (b + K1 (I2/(I1 + I2))^2 + b_v (I1/(I1 + I2))^2) / (2 sqrt(c I_red))``."""
    reduced = inertia_drive * inertia_driven / (inertia_drive + inertia_driven)
    share = inertia_driven / (inertia_drive + inertia_driven)
    driven_share = inertia_drive / (inertia_drive + inertia_driven)
    return (math.sqrt(stiffness / reduced),
            (damping + engine_slope * share ** 2 + driven_slope * driven_share ** 2)
            / (2.0 * math.sqrt(stiffness * reduced)))


class CouplingFamily:
    """One coupling whose misalignment varies in time (its ``misalignment`` input driven
    by a source).  At its start misalignment it is exactly ``LeverCoupling``; at any
    other alpha the transfer function is the linear blend of the exact ones at the
    neighbouring multiples of ``NODE`` (0.05 deg): building an exact one takes
    milliseconds (a Fourier analysis), evaluating a blend two Horner passes.  The blend
    is exact at the nodes and off by O(NODE^2 d2U12/dalpha2), below 1e-6 in U12 at the
    coupling's operating angles.  Where a node lies outside the defined range (next to
    45 deg) the exact transfer function at alpha is used; outside the range itself the
    exact one refuses (``ParameterError`` naming the misalignment)."""

    NODE = math.radians(0.05)
    NODES = 4096       # exact transfer functions kept (a few kB each): 0 ... 75 deg fits
    CACHE = 256        # couplings kept by alpha

    def __init__(self, transfer_at, law, damping: float, start_alpha: float):
        self._transfer_at = transfer_at      # alpha -> TransferFunction
        self._law, self._damping = law, damping
        self.start_alpha = float(start_alpha)
        self.start = LeverCoupling(transfer_at(self.start_alpha), law, damping)
        self._nodes: dict[int, TransferFunction] = {}
        self._couplings: dict[float, LeverCoupling] = {self.start_alpha: self.start}

    def _node(self, k: int) -> TransferFunction:
        transfer = self._nodes.get(k)
        if transfer is None:
            if len(self._nodes) > self.NODES:
                self._nodes.clear()
            transfer = self._nodes[k] = self._transfer_at(k * self.NODE)
        return transfer

    def at(self, alpha: float) -> LeverCoupling:
        coupling = self._couplings.get(alpha)
        if coupling is not None:
            return coupling
        position = alpha / self.NODE
        k = math.floor(position)
        if abs(position - round(position)) < 1e-9:           # on a node
            try:
                transfer = self._node(round(position))
            except ParameterError:                           # a node just beyond the range (75 deg)
                transfer = self._transfer_at(alpha)
        else:
            try:
                transfer = BlendedTransferFunction(self._node(k), self._node(k + 1), alpha)
            except ParameterError:                           # a node beyond the defined range
                transfer = self._transfer_at(alpha)
        if len(self._couplings) > self.CACHE:
            self._couplings = {self.start_alpha: self.start}
        coupling = self._couplings[alpha] = LeverCoupling(transfer, self._law, self._damping)
        return coupling


    def alpha_slopes(self, alpha, phi2) -> tuple[float, float]:
        """``(dPhi/dalpha, dU12/dalpha)`` at driven angle ``phi2`` of the coupling
        ``at(alpha)``: the blend is linear in alpha between nodes, so this is its slope; on
        a node, the right-hand one (the blend up to the next node).  Next to the kinematic
        limit, where ``at`` uses the exact transfer function (no node beyond), the
        left-hand blend's; with no node on either side there is none (``ParameterError``)."""
        position = alpha / self.NODE
        k = round(position) if abs(position - round(position)) < 1e-9 else math.floor(position)
        try:
            blend = BlendedTransferFunction(self._node(k), self._node(k + 1), alpha)
        except ParameterError:
            try:
                blend = BlendedTransferFunction(self._node(k - 1), self._node(k), alpha)
            except ParameterError:
                raise ParameterError("misalignment", f"parameter 'misalignment' (alpha) = {math.degrees(alpha):.6g} "
                                     "deg: no node of the transfer function's blend on either side, so no "
                                     "derivative with respect to alpha there") from None
        return blend.alpha_slopes(phi2)

    def alpha_partials(self, alpha, phi1, w1, phi2, w2) -> tuple[float, float]:
        """``(dtau1/dalpha, dtau2/dalpha)`` of the coupling ``at(alpha)`` (``alpha_slopes``):
        ``dT/dalpha = -k dPhi/dalpha - b w2 dU12/dalpha``, ``dtau1 = -dT``,
        ``dtau2 = U12 dT + T dU12/dalpha``."""
        d_position, d_ratio = self.alpha_slopes(alpha, phi2)
        result = self.at(alpha).evaluate(phi1, w1, phi2, w2)
        d_torque = -self._law.stiffness_at(result.deflection) * d_position - self._damping * w2 * d_ratio
        return -d_torque, result.ratio * d_torque + result.torque * d_ratio


def build_coupling(transfer_mode: str, alpha: float, support_deformation: float, hinge_deformation: float,
                   c: float, b: float, elastic_table: str = "") -> LeverCoupling:
    """The one constructor the FMU, the reference solver and the tests share."""
    transfer = transfer_function(transfer_mode, alpha, support_deformation, hinge_deformation)
    return LeverCoupling(transfer, elastic_law(c, elastic_table), b)


__all__ = ["LeverCoupling", "CouplingFamily", "CouplingResult", "build_coupling", "coupling_mode", "LinearElasticLaw", "TabulatedElasticLaw"]
