"""``LeverCoupling`` FMU: the compliant element, ``phi1, w1, phi2, w2 -> tau1, tau2``
(Modelica's GenerationOfFMUs causality), with direct feedthrough and no state."""
from __future__ import annotations

from ..physics import component_parameters
from ..physics.component_parameters import COUPLING, MISALIGNMENT
from ..physics.me_coupling import CouplingME
from ..physics.parameters import Parameter, ParameterError
from .base import LeverSlave
from .declarations import MechanicalPort, Output
from .guard import guarded
from .model_exchange import ModelExchangeSlave
from .recompute import ALL

_BIG = 1e12


class LeverCoupling(ModelExchangeSlave):
    DESCRIPTION = ("Lever-articulated (harness-lever) drive-shaft coupling with elastic elements: "
                   "theta = phi1 - Phi(phi2), T = T_el(theta) + b*(w1 - U12*w2), tau1 = -T, tau2 = U12*T")
    PARAMETERS = COUPLING
    INPUTS = (
        Parameter("phi1", 0.0, "rad", "angle of the drive shaft flange", -_BIG, _BIG, fixed=False),
        Parameter("w1", 0.0, "rad/s", "speed of the drive shaft flange", -_BIG, _BIG, fixed=False),
        Parameter("phi2", 0.0, "rad", "angle of the driven shaft flange", -_BIG, _BIG, fixed=False),
        Parameter("w2", 0.0, "rad/s", "speed of the driven shaft flange", -_BIG, _BIG, fixed=False),
        MISALIGNMENT,
    )
    OUTPUTS = (
        Output("tau1", "N.m", "torque the coupling applies to the drive shaft (= -T)"),
        Output("tau2", "N.m", "torque the coupling applies to the driven shaft (= U12*T)"),
        Output("U12", "1", "transfer function U12 = dPhi/dphi2 at the driven angle"),
        Output("theta", "rad", "elastic deflection theta = phi1 - Phi(phi2)"),
        Output("elastic_energy", "J", "potential energy stored in the elastic elements"),
        Output("dissipated_power", "W", "power dissipated in the elastic elements, b*thetadot^2"),
    )
    FEEDTHROUGH = True
    EQUATIONS = (
        "theta = phi1 - Phi(phi2)   (elastic deflection; Phi the driven shaft's angle seen through the coupling)",
        "U12 = dPhi/dphi2   (transfer function: 1 if synchronous; from the half-coupling function g if kinematic)",
        "T = T_el(theta) + b*(w1 - U12*w2)   (T_el = c*theta, or the tabulated elastic law)",
        "tau1 = -T,  tau2 = U12*T",
        "tau1*w1 + tau2*w2 = -(dV/dt + b*thetadot^2)   (V = elastic_energy; the coupling creates no energy)",
    )
    PORTS = (
        MechanicalPort("drive_flange", "tau1", "w1", "phi1", "flange on the drive (engine) shaft"),
        MechanicalPort("driven_flange", "tau2", "w2", "phi2", "flange on the driven (load) shaft"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._family = None   # the coupling at any misalignment (the input may vary in time)
        self._misalignment_vr = self._vr_of["misalignment"]

    def _build(self):
        # exact at the misalignment the model is built with; blended elsewhere (CouplingFamily)
        self._family = component_parameters.coupling_family_from(self._values() | {"misalignment": self.misalignment})

    # judged by set_real below beyond its declared range: the native entry never holds it
    JUDGED_INPUTS = ("misalignment",)

    @guarded()
    def set_real(self, vrs, values):
        # The declared range of the misalignment input is the synchronous mode's; what the
        # built coupling takes (kinematic: alpha + tilt < 45 deg) is judged here, at the set
        # while stepping (before, at fmi2ExitInitializationMode, with the parameters), so that
        # a value the outputs cannot be computed for is refused and never applied.
        if self._is_channel(vrs):
            return ModelExchangeSlave.set_real.__wrapped__(self, vrs, values)
        self._take_point()
        if self._misalignment_vr not in vrs:       # the hot path: the flanges' angles and speeds
            return LeverSlave.set_real.__wrapped__(self, vrs, values)
        before = {vr: getattr(self, self._real_names[vr]) for vr in vrs if vr in self._real_names}
        alpha = self.misalignment
        LeverSlave.set_real.__wrapped__(self, vrs, values)
        if self.misalignment == alpha or self._family is None or self._model_stale or self._phase != "stepping":
            return
        try:
            self._family.at(self.misalignment)
        except ParameterError as error:
            refused = self.misalignment
            for vr, value in before.items():
                setattr(self, self._real_names[vr], value)
            self._dirty = ALL
            self._error(f"fmi2SetReal: input 'misalignment' = {refused!r} rad cannot be taken by this coupling: "
                        f"{error}; nothing of this call was applied, 'misalignment' stays {alpha!r}")

    def _me_physics(self):
        return CouplingME(self._family)

    def _physics_key(self):
        return self._family

    def _coupling_for(self, alpha):
        return self._family.at(alpha)

    def _compute_outputs(self):
        r = self._coupling_for(self.misalignment).evaluate(self.phi1, self.w1, self.phi2, self.w2)
        self.tau1, self.tau2, self.U12, self.theta = r.tau1, r.tau2, r.ratio, r.deflection
        self.elastic_energy, self.dissipated_power = r.energy, r.dissipation

    def _advance(self, t, h):
        return None  # no state: the outputs follow the inputs

    # The family is exact at the misalignment it was built with and blended elsewhere:
    # a restored state rebuilds it at that same angle, so it continues exactly.
    def _internal_state(self) -> dict:
        return {"start_misalignment": self._family.start_alpha if self._family is not None else None}

    def _internal_problem(self, internal) -> str | None:
        alpha = internal.get("start_misalignment", "missing") if isinstance(internal, dict) else "missing"
        if not (isinstance(internal, dict) and set(internal) == {"start_misalignment"}
                and (alpha is None or (type(alpha) is float and MISALIGNMENT.problem(alpha) is None))):
            return (f"internal state {internal!r}: it needs start_misalignment, the angle the coupling was built "
                    f"at, in {MISALIGNMENT.range_text()}")
        return None

    def _restore_internal_state(self, state: dict):
        alpha = state["start_misalignment"]
        if alpha is not None and (self._family is None or self._family.start_alpha != alpha):
            self._family = component_parameters.coupling_family_from(self._values() | {"misalignment": alpha})
