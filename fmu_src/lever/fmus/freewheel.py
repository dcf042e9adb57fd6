"""``FreewheelRectifier`` FMU: the whole rectifier chain - prescribed rocker, half-couplings
on their ball ramps, friction discs, torsion shaft, gear mesh and output flywheel - in one
FMU, because its gaps and stiff contacts (2000-5000 rad/s) must be stepped by one
integrator with located events (docs/record/decisions.md).

Its port is the output shaft, with a shaft's causality (``tau -> phi, w, a``, no direct
feedthrough of ``phi, w``): a downstream model can be coupled through a compliant element
as the project's shafts are.  Left unconnected, ``tau = 0``."""
from __future__ import annotations

import math

from ..physics import component_parameters
from ..physics.freewheel import EVENTS, FREE, STATE, STICK
from ..physics.me_freewheel import FreewheelME
from ..physics.parameters import Parameter, ParameterError
from .declarations import Output
from .model_exchange import ModelExchangeSlave, StateVariable

_PORT = ("tau",)
_BODIES = (("half_coupling", "phi2", "w2"), ("driven", "phi3", "w3"), ("torsion_end", "phi4", "w4"))
_ANGLES = ("half_coupling_angle", "driven_angle", "torsion_end_angle", "phi")
_SPEEDS = ("half_coupling_speed", "driven_speed", "torsion_end_speed", "w")


class FreewheelRectifier(ModelExchangeSlave):
    DESCRIPTION = ("Axial freewheel vibration rectifier (rocker phi0 (1 - cos(omega t)), ball ramps with gap z1, "
                   "friction discs with stick/slip, torsion shaft with gap z2, gear mesh with gap z3, flywheel J5)")
    PARAMETERS = component_parameters.FREEWHEEL
    INPUTS = (
        Parameter("tau", 0.0, "N.m", "torque a downstream element applies to the output shaft (flywheel)",
                  -1e9, 1e9, fixed=False),
        Parameter("tau_rate", 0.0, "N.m/s", "rate of change of tau over the coming step (0: tau held)",
                  -1e13, 1e13, fixed=False, derivative_of="tau"),
    )
    # FEEDTHROUGH is off: an output depends on no input unless its depends_on says so.
    OUTPUTS = (
        Output("phi", "rad", "angle of the output shaft (flywheel, element 5)"),
        Output("w", "rad/s", "speed of the output shaft", derivative_of="phi"),
        Output("a", "rad/s2", "acceleration of the output shaft (with the current input torque)", derivative_of="w",
               depends_on=_PORT),
        Output("rocker_angle", "rad", "phi1, rocker (element 1)"),
        Output("rocker_speed", "rad/s", "w1, rocker"),
        Output("rocker_acceleration", "rad/s2", "a1, rocker"),
        Output("half_coupling_angle", "rad", "phi2, half-couplings (element 2)"),
        Output("half_coupling_speed", "rad/s", "w2, half-couplings"),
        Output("half_coupling_acceleration", "rad/s2", "a2, half-couplings"),
        Output("driven_angle", "rad",
               "phi3, driven parts of the freewheel = input end of the torsion shaft (element 3)"),
        Output("driven_speed", "rad/s", "w3, driven parts"),
        Output("driven_acceleration", "rad/s2", "a3, driven parts"),
        Output("torsion_end_angle", "rad", "phi4, output end of the torsion shaft (element 4)"),
        Output("torsion_end_speed", "rad/s", "w4, output end of the torsion shaft"),
        Output("torsion_end_acceleration", "rad/s2", "a4, output end of the torsion shaft"),
        Output("msm_deflection", "rad", "e = phi1 - phi2: > 0 engaged, in [-z1, 0] axial gap, < -z1 pocket end"),
        Output("torsion_twist", "rad", "phi3 - phi4: > 0 twisted forward, in [-z2, 0] spline gap"),
        Output("mesh_deflection", "rad", "phi4 - phi5: > 0 driving contact, in [-z3, 0] backlash"),
        Output("msm_contact", "1", "+1 engaged (discs clamped), 0 axial gap open, -1 pocket end (dragged back)"),
        Output("torsion_contact", "1", "+1 driving flank, 0 spline gap open, -1 back flank"),
        Output("mesh_contact", "1", "+1 driving flank, 0 backlash open, -1 back flank"),
        Output("disc_slip", "1", "0 discs stuck, +1 slipping with w2 > w3, -1 with w2 < w3"),
        Output("flywheel_stuck", "1", "1 while the output's resistance holds the flywheel still"),
        Output("rocker_torque", "N.m", "T12, torque the rocker applies to the half-couplings"),
        Output("disc_torque", "N.m", "torque the half-couplings pass to the driven parts through the discs"),
        Output("disc_capacity", "N.m", "torque the discs can pass before they slip"),
        Output("torsion_torque", "N.m", "T34, torque in the torsion shaft"),
        Output("mesh_torque", "N.m", "T45, torque in the gear mesh"),
        Output("resistance", "N.m", "torque of the output's resistance against the flywheel", depends_on=_PORT),
        Output("input_work", "J", "work the rocker has done since the start, integral of T12*w1 dt"),
        Output("output_work", "J", "work delivered to the resistance and the port since the start"),
        Output("kinetic_energy", "J", "kinetic energy of elements 2-5"),
        Output("elastic_energy", "J", "potential energy of the ramps, torsion shaft and mesh"),
        Output("dissipated_energy", "J", "energy dissipated since the start (discs, balls, dampers)"),
        Output("events", "1", "events located since the start (gap edges, stick/slip changes)"),
    )

    # Model Exchange: the state vector (``freewheel.STATE``) is the bodies' angles and speeds
    # and the energies, all outputs already; the modes (discs, flywheel) are discrete states.
    ME_STATES = tuple(
        s for body, phi, w in _BODIES for s in (
            StateVariable(f"{body}_angle", f"{body}_speed", "", phi, "rad"),
            StateVariable(f"{body}_speed", f"{body}_acceleration", "", w, "rad/s"))) + (
        StateVariable("phi", "w", "", "phi5", "rad"), StateVariable("w", "a", "", "w5", "rad/s"),
        StateVariable("input_work", "der(input_work)", "", "input_work", "J",
                      derivative_description="power the rocker puts in, T12*w1"),
        StateVariable("output_work", "der(output_work)", "", "output_work", "J",
                      derivative_description="power delivered to the resistance and the port"),
        StateVariable("dissipated_energy", "der(dissipated_energy)", "", "dissipated_energy", "J",
                      derivative_description="power dissipated in the discs, balls and dampers"))
    ME_EVENT_INDICATORS = len(EVENTS)
    # The outputs beyond the port's: the rocker's follow the time alone, the modes and the
    # event count change at events only; the rest on the states they are made of (the
    # torques on every body's motion: the contacts' branches couple them).
    ME_OUTPUT_DEPENDENCIES = {
        "rocker_angle": (), "rocker_speed": (), "rocker_acceleration": (),
        "msm_deflection": ("half_coupling_angle",), "msm_contact": ("half_coupling_angle",),
        "torsion_twist": ("driven_angle", "torsion_end_angle"), "torsion_contact": ("driven_angle", "torsion_end_angle"),
        "mesh_deflection": ("torsion_end_angle", "phi"), "mesh_contact": ("torsion_end_angle", "phi"),
        "disc_slip": (), "flywheel_stuck": (), "events": (),
        **{name: _ANGLES + _SPEEDS for name in ("rocker_torque", "disc_torque", "disc_capacity", "torsion_torque",
                                                 "mesh_torque")},
        "resistance": _ANGLES + _SPEEDS + ("tau",),
        "kinetic_energy": _SPEEDS, "elastic_energy": _ANGLES,
    }

    _me_integrated = False    # Model Exchange: states set since the last event

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._model = None
        self._y = None
        self._disc = 0
        self._fly = FREE
        self._events = 0

    def _build(self):
        self._model = component_parameters.freewheel_from(self._values())

    def _reset_state(self):
        self._y, self._disc, self._fly = self._model.start()
        self._events = 0

    def _x(self):
        return list(self._y)

    def _set_x(self, x):
        self._y = [float(v) for v in x]
        self._me_integrated = True

    def _me_physics(self):
        model = FreewheelME(self._model)
        model.disc, model.fly = self._disc, self._fly
        return model

    def _physics_key(self):
        return self._model

    def _me_output_values(self, model, t, x, u):
        return self._model.named_outputs(t, x, model.disc, model.fly, u[0], self._events)

    def _modes_from_co_simulation(self):
        self._me_model.disc, self._me_model.fly = self._disc, self._fly
        self._me_model.initialize(self._time, self._x_physics(), self._u())

    def _events_settled(self, t, x, u):
        # an event the integrator stopped at (not the event iteration of the initialisation)
        if self._me_integrated:
            self._events += 1
        self._me_integrated = False
        self._disc, self._fly = self._me_model.disc, self._me_model.fly

    def _compute_outputs(self):
        values = self._model.named_outputs(self._time, self._y, self._disc, self._fly, self.tau, self._events)
        for name, value in values.items():
            setattr(self, name, value)

    def _advance(self, t, h):
        try:
            y, disc, fly, n = self._model.advance(t, h, self._y, self._disc, self._fly, self.tau, self.tau_rate)
        except (RuntimeError, ParameterError) as error:
            return f"{error}; the state was not updated"
        except ArithmeticError as error:     # the state ran away within a substep
            return (f"the state overflowed within the step ({type(error).__name__}: {error}) with input tau = "
                    f"{self.tau:.6g} N.m: RK4 substeps of max_substep = {self.max_substep:.6g} s are unstable "
                    "for these stiffnesses, dampings and inertias; take a smaller 'max_substep'; the state was not "
                    "updated")
        if not all(math.isfinite(v) and abs(v) < 1e15 for v in y):
            bad = ", ".join(f"{name} = {v:.6g}" for name, v in zip(STATE, y) if not (math.isfinite(v) and abs(v) < 1e15))
            return f"the state became non-finite or unbounded ({bad}) with input tau = {self.tau:.6g} N.m"
        self._y, self._disc, self._fly = y, disc, fly
        self._events += n
        return None

    def _internal_state(self) -> dict:
        return {"y": list(self._y) if self._y is not None else None, "disc": self._disc, "fly": self._fly,
                "events": self._events}

    def _internal_problem(self, internal) -> str | None:
        if not (isinstance(internal, dict) and set(internal) == {"y", "disc", "fly", "events"}):
            return f"internal state {internal!r}: it needs y, disc, fly and events"
        y = internal["y"]
        if y is not None and not (isinstance(y, list) and len(y) == len(STATE)
                                  and all(type(v) in (int, float) and math.isfinite(v) and abs(v) < 1e15 for v in y)):
            return f"internal state y = {y!r}: it must be {len(STATE)} finite numbers ({', '.join(STATE)})"
        if internal["disc"] not in (STICK, 1, -1) or type(internal["disc"]) is not int:
            return f"internal state disc = {internal['disc']!r}: it must be {STICK}, 1 or -1"
        if internal["fly"] not in (STICK, 1, -1, FREE) or type(internal["fly"]) is not int:
            return f"internal state fly = {internal['fly']!r}: it must be {STICK}, 1, -1 or {FREE}"
        if not (type(internal["events"]) is int and internal["events"] >= 0):
            return f"internal state events = {internal['events']!r}: it must be a count >= 0"
        return None

    def _restore_internal_state(self, state: dict):
        self._y = None if state["y"] is None else list(state["y"])
        self._disc, self._fly, self._events = state["disc"], state["fly"], state["events"]


__all__ = ["FreewheelRectifier", "EVENTS"]
