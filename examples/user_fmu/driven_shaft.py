"""A user's own driven-shaft FMU, as a user writes one with pythonfmu: a shaft of inertia J
driven by the torque ``tau`` and held back by a constant torque and one proportional to its
speed,

    J dw/dt = tau - resisting_torque - speed_coefficient * w,    dphi/dt = w.

Inputs ``tau``; outputs ``phi``, ``w``.  pythonfmu 0.7 cannot declare units, so none of its
variables has one (in FMI: an unknown unit).  Over a communication step the torque is held
and the linear equation solved exactly, so the step's only error is the held input's."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class DrivenShaft(Fmi2Slave):

    author = "a user of the lever harness"
    description = "Driven shaft: inertia, constant and speed-proportional resisting torque"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.inertia = 0.161
        self.resisting_torque = 60.0
        self.speed_coefficient = 1.25
        self.w_start = 39.0
        self.tau = 0.0
        self.phi = 0.0
        self.w = self.w_start
        for name in ("inertia", "resisting_torque", "speed_coefficient", "w_start"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed))
        self.register_variable(Real("tau", causality=Fmi2Causality.input))
        self.register_variable(Real("phi", causality=Fmi2Causality.output))
        self.register_variable(Real("w", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.w = self.w_start

    def do_step(self, current_time, step_size):
        decay = self.speed_coefficient / self.inertia
        settled = (self.tau - self.resisting_torque) / self.speed_coefficient
        fade = math.exp(-decay * step_size)
        self.phi += settled * step_size + (self.w - settled) * (1.0 - fade) / decay
        self.w = settled + (self.w - settled) * fade
        return True

    # the full state for masters that roll a step back (fmi2GetFMUstate/SetFMUstate)
    def _get_fmu_state(self):
        return {"phi": self.phi, "w": self.w, "tau": self.tau}

    def _set_fmu_state(self, state):
        self.phi, self.w, self.tau = state["phi"], state["w"], state["tau"]
