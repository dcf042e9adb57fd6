"""``EngineShaft`` and ``LoadShaft`` FMUs: inertia elements, ``tau -> phi, w, a``
(Modelica's GenerationOfFMUs causality), no feedthrough.  Each integrates its own shaft
inside ``do_step`` with the coupling torque held over the step (exactly where the
physics has a closed form)."""
from __future__ import annotations

import bisect
import math

from ..physics import component_parameters
from ..physics.me_engine import EngineME
from ..physics.me_load import LoadME
from ..physics.parameters import Parameter, ParameterError
from ..physics.shaft import LaggedShaft
from .declarations import MechanicalPort, Output
from .model_exchange import ModelExchangeSlave, StateVariable

_MOTION = (StateVariable("phi", "w", "phi", "phi", "rad"), StateVariable("w", "a", "w", "w", "rad/s"))


class _ShaftSlave(ModelExchangeSlave):
    INPUTS = (
        Parameter("tau", 0.0, "N.m", "torque the coupling applies to this shaft", -1e12, 1e12, fixed=False),
        # FMI 2 input derivatives, which pythonfmu cannot take, as an input of its own: a
        # master that knows how the torque changes over the step passes its slope here.
        Parameter("tau_rate", 0.0, "N.m/s", "rate of change of tau over the coming step (first-order hold; "
                  "0: tau held)", -1e15, 1e15, fixed=False, derivative_of="tau"),
        # A master extrapolating the torque by a quadratic sends it whole: tau stays the
        # coupling's torque now (so the acceleration read with it is consistent).
        Parameter("tau_accel", 0.0, "N.m/s2", "second derivative of tau over the coming step (the shaft takes "
                  "the ramp with the same mean and first moment; 0: tau + tau_rate*s)", -1e18, 1e18, fixed=False,
                  derivative_of="tau_rate"),
    )
    PORTS = (MechanicalPort("flange", "tau", "w", "phi", "the shaft's flange to the coupling"),)
    #: name of the output carrying the external torque and its work, set by subclasses
    TORQUE_OUTPUT = WORK_OUTPUT = ""
    SIGN = 1.0   # external torque on the shaft = SIGN * (reported torque)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._shaft = None
        self._external = 0.0    # external torque at the current time and state

    def _make_shaft(self):
        raise NotImplementedError

    def _build(self):
        self._shaft = self._make_shaft()

    def _reset_state(self):
        self.phi, self.w = float(self.phi_start), float(self.w_start)
        setattr(self, self.WORK_OUTPUT, 0.0)

    def _compute_outputs(self):
        self.a, self._external = self._shaft.rates(self._time, self.phi, self.w, self.tau)
        setattr(self, self.TORQUE_OUTPUT, self.SIGN * self._external)

    def _compute_input_outputs(self):
        # Only the acceleration depends on the torque input: Shaft.rates' own expression
        # with the external torque of this time and state, not evaluated again.
        self.a = (self._external + self.tau) / self._shaft.inertia

    def _advance(self, t, h):
        phi, w, work = self._shaft.advance(t, self.phi, self.w, self.tau, h, self.tau_rate, self.tau_accel)
        if not (abs(phi) < 1e15 and abs(w) < 1e12):
            # name the offending state variable first: the importer's diagnosis reads it
            bad = "w" if not abs(w) < 1e12 else "phi"
            return (f"state variable '{bad}' became non-finite or unbounded (phi = {phi:.6g} rad, "
                    f"w = {w:.6g} rad/s; allowed |phi| < 1e15 rad, |w| < 1e12 rad/s) with input "
                    f"tau = {self.tau:.6g} N.m; the state was not updated")
        self.phi, self.w = phi, w
        setattr(self, self.WORK_OUTPUT, getattr(self, self.WORK_OUTPUT) + self.SIGN * work)
        return None


_SHAFT_OUTPUTS = (
    Output("phi", "rad", "shaft angle"),
    Output("w", "rad/s", "shaft speed", derivative_of="phi"),
    Output("a", "rad/s2", "shaft acceleration (with the current input torque)", derivative_of="w",
           depends_on=("tau",)),
)


class EngineShaft(_ShaftSlave):
    DESCRIPTION = ("Drive shaft with the engine's static characteristic, optionally lagged: I1*a = M + tau, "
                   "Te*dM/dt = Mg(w) - M (M = Mg(w) when Te = 0)")
    PARAMETERS = component_parameters.ENGINE
    OUTPUTS = _SHAFT_OUTPUTS + (
        Output("engine_torque", "N.m", "torque M the engine applies to the drive shaft (Mg(w), or its lagged "
               "value when torque_lag > 0)"),
        Output("engine_work", "J", "work done by the engine since the start, integral of M*w dt"),
    )
    TORQUE_OUTPUT, WORK_OUTPUT, SIGN = "engine_torque", "engine_work", 1.0
    # The number of states is the model description's, whatever the parameters: without
    # lag the engine torque's state stays at torque_start (derivative 0, used by nothing).
    ME_STATES = _MOTION + (
        StateVariable("engine_work", "der(engine_work)", "engine_work", "engine_work", "J",
                      derivative_description="power of the engine M*w"),
        StateVariable("lagged_torque", "der(lagged_torque)", "_torque", "engine_torque", "N.m",
                      "engine torque M as a state when torque_lag > 0 (else it stays torque_start, unused)",
                      "rate of the lagged engine torque (Mg(w) - M)/Te"),
    )
    # A tabulated characteristic's slope jumps at its points: one indicator, positive while
    # the speed stays between the points around it (any number of points in one).
    ME_EVENT_INDICATORS = 1
    ME_STRUCTURE_CASES = ({}, {"torque_lag": 0.1}, {"characteristic": "0:600; 40:620; 80:0"})
    EQUATIONS = (
        "dphi/dt = w",
        "I1*dw/dt = M + tau(t),  tau(t) = tau + tau_rate*(t - t_k) over the step from t_k (with tau_accel: the ramp "
        "with the mean and first moment of tau + tau_rate*s + tau_accel*s^2/2)",
        "Mg(w) = M1 - K1*w   (stall_torque, torque_slope), or the tabulated characteristic",
        "M = Mg(w) when torque_lag Te = 0; else Te*dM/dt = Mg(w) - M, M(0) = torque_start",
        "engine_work = integral of M*w dt",
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._torque = 0.0      # the lagged engine torque M, a state (torque_lag > 0)

    def _make_shaft(self):
        return component_parameters.engine_from(self._values())

    def _me_physics(self):
        return EngineME(self._shaft, self.phi_start, self.w_start)

    def _physics_key(self):
        return self._shaft

    def _events_settled(self, t, x, u):
        model = self._me_model
        self._segment = bisect.bisect_right(model.characteristic.speeds, x[1]) if model.EVENTS else 0

    def _fold_indicators(self, values):
        if not values:
            return [1.0]
        k = self._segment
        below = values[k - 1] if k > 0 else math.inf        # w - (the point below)
        above = -values[k] if k < len(values) else math.inf   # (the point above) - w
        return [min(below, above)]

    @property
    def _lagged(self) -> bool:
        return isinstance(self._shaft, LaggedShaft)

    def _reset_state(self):
        super()._reset_state()
        self._torque = float(self.torque_start)

    def _compute_outputs(self):
        if not self._lagged:
            return super()._compute_outputs()
        self.a, self._external = self._shaft.rates(self._time, self.phi, self.w, self.tau, self._torque)
        self.engine_torque = self._external

    def _advance(self, t, h):
        if not self._lagged:
            return super()._advance(t, h)
        phi, w, torque, work = self._shaft.advance(t, self.phi, self.w, self._torque, self.tau, h, self.tau_rate,
                                                   self.tau_accel)
        if not (abs(phi) < 1e15 and abs(w) < 1e12 and abs(torque) < 1e15):
            bad = "w" if not abs(w) < 1e12 else "phi" if not abs(phi) < 1e15 else "engine_torque"
            return (f"state variable '{bad}' became non-finite or unbounded (phi = {phi:.6g} rad, w = {w:.6g} rad/s, "
                    f"engine_torque = {torque:.6g} N.m) with input tau = {self.tau:.6g} N.m; the state was not updated")
        self.phi, self.w, self._torque = phi, w, torque
        self.engine_work += work
        return None

    # The lagged torque is state: saved and restored with the rest (an engine answering
    # instantly keeps none of its own: its internal state stays empty).
    def _internal_state(self) -> dict:
        return {"engine_torque": self._torque} if self._lagged else {}

    def _internal_problem(self, internal) -> str | None:
        if internal == {}:
            return None
        value = internal.get("engine_torque") if isinstance(internal, dict) else None
        if isinstance(internal, dict) and set(internal) == {"engine_torque"} and type(value) is float \
                and math.isfinite(value):
            return None
        return (f"internal state {internal!r}: it needs engine_torque, the lagged engine torque M [N.m], "
                "finite (or nothing, for an engine without lag)")

    def _restore_internal_state(self, state: dict):
        if self._lagged:
            if "engine_torque" not in state:
                raise ParameterError("torque_lag", "the state has no lagged engine torque, but torque_lag > 0: "
                                     "it is a state of an engine without lag")
            self._torque = state["engine_torque"]


class LoadShaft(_ShaftSlave):
    DESCRIPTION = "Driven shaft with the technological load: I2*a = tau - Mc(t, phi, w)"
    PARAMETERS = component_parameters.LOAD
    OUTPUTS = _SHAFT_OUTPUTS + (
        # At rest static friction balances the coupling torque: then the load torque
        # depends on the input directly.
        Output("load_torque", "N.m", "torque the load and the friction resist the shaft with (positive when it "
               "opposes positive rotation; at rest the holding torque)", depends_on=("tau",)),
        Output("load_work", "J", "work absorbed by the load and the friction since the start, integral of "
               "load_torque*w dt"),
    )
    TORQUE_OUTPUT, WORK_OUTPUT, SIGN = "load_torque", "load_work", -1.0
    ME_STATES = _MOTION + (
        StateVariable("load_work", "der(load_work)", "load_work", "load_work", "J",
                      derivative_description="power the load and the friction absorb"),
    )
    # stick/slip of the friction (1.0, no event, without friction that sticks)
    ME_EVENT_INDICATORS = 1
    ME_STRUCTURE_CASES = ({}, {"order_share": 0.5, "random_amplitude": 10.0}, {"viscous_damping": 1.0},
                          {"friction_torque": 1.0, "breakaway_torque": 2.0})
    EQUATIONS = (
        "dphi/dt = w",
        "I2*dw/dt = tau(t) - Mc(t, phi, w) - F(w, tau),  tau(t) = tau + tau_rate*(t - t_k) over the step from t_k "
        "(with tau_accel: the ramp with the mean and first moment of tau + tau_rate*s + tau_accel*s^2/2)",
        "Mc = Mm (constant); Mm + seeded multisine bounded by dM, with shares of dM at Ak*sin(k*phi + psi) and in "
        "seeded tones at 415...425 rad/s (random); angle-periodic Fourier series (fourier); linear interpolation "
        "in a time series (table)",
        "load_direction resistive: Mc is a brake, max(Mc, 0)*sign(w) against the motion, holding at rest",
        "F = Fc*sign(w) + b_v*w while w != 0; at w = 0 the shaft stays at rest while |net| <= Fs (+ the brake), "
        "net = tau - Mc (active) or tau (resistive); stops and breakaways are located inside doStep",
        "load_work = integral of (Mc + F)*w dt",
    )

    def _make_shaft(self):
        return component_parameters.load_from(self._values())

    def _me_physics(self):
        return LoadME(self._shaft, self.phi_start, self.w_start)

    def _physics_key(self):
        return self._shaft

    def _compute_input_outputs(self):
        if self._shaft.resisting:       # the holding torque at rest depends on tau
            self._compute_outputs()
        else:
            super()._compute_input_outputs()
