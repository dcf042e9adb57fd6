"""Divergence handling: the physical bounds of a scene, and the per-step guard that stops
a run within one communication step of going non-finite or past them.

**The rule** (``bounds``).  For the engine - coupling - load driveline:

* *speed bound* ``W`` for both shafts: ``margin`` (default 10) times the largest speed
  the scene's parameters make plausible: the start speeds and the speeds the engine
  characteristic allows under the scene's loads.  For the linear engine ``M1 - K1*w``
  that is the no-load speed ``M1/K1`` and the steady speeds ``(M1 - Mc)/K1`` at the
  load's smallest and largest resistance.  Where no steady speed exists (``K1 = 0``, a
  tabulated characteristic, which holds its first torque below its first speed) the
  speed the largest engine and load torques together could give the whole driveline from
  rest over the run, ``(|Mg|max + |Mc|max) * (stop - start) / (I1 + I2)``, counts too.
* *torque bound* for the coupling torques ``tau1, tau2``: the elastic torque at the
  deflection whose elastic energy equals the kinetic energy of the driveline at the
  speed bound, ``V(theta) = (I1 + I2) W^2 / 2`` (for a linear spring
  ``W sqrt(c (I1 + I2))``), plus the damping torque at a relative speed of
  ``(1 + U12max) W``, times ``U12max`` (``tau2 = U12 * T``).

For a scene with our lever coupling between shafts of other FMUs (a user's engine or load
model) the guard knows only what is ours: where the drive side is our EngineShaft, the
speed bound of both coupling sides is ``margin`` times the largest of its start speed, its
no-load speed and (no steady speed) the speed its largest torque gives its own inertia from
rest over the run - the foreign side's inertia only slows that, its torques are not known
(an assisting foreign torque needs a ``[limits]`` speed).  The coupling torques are checked
for being finite only (their bound needs both inertias); where the drive side is not our
EngineShaft no speed is plausible from the scene's values either, and only finiteness is
checked.  The run's advisor (``lever run``) still predicts the instability beforehand.

A scene overrides any of it in a ``[limits]`` table (``speed`` [rad/s], ``torque``
[N*m], ``margin``), also with ``--set limits.speed=...``; ``inf`` leaves only the
finiteness check.  Every other connected output is checked for being finite.

The guard reads the values the last propagation left in the system's buffers (no FMI
call): one comparison per checked value and step.
"""
from __future__ import annotations

import functools
import math
import sys
from dataclasses import dataclass
from typing import Callable

from lever.physics import component_parameters
from lever.physics.elastic import LinearElasticLaw
from lever.physics.engine import LinearCharacteristic, TabulatedCharacteristic
from lever.physics.friction import ResistingLoad
from lever.physics.load import ConstantLoad, FourierLoad, RandomLoad, SpectrumLoad, TabulatedLoad
from lever.physics.parameters import ParameterError, check_all

from harness.description import plan as plans, scene_kinds
from harness.engine.straight_line import Source

#: default factor between the plausible speeds of a scene and its speed bound
MARGIN = 10.0


class Diverged(RuntimeError):
    """A run left its physical bounds or went non-finite; ``diagnosis`` says where."""

    def __init__(self, message: str, diagnosis: dict | None = None):
        super().__init__(message)
        self.diagnosis = diagnosis or {}


@dataclass
class Bound:
    variable: str        # "component.variable"
    limit: float         # |value| <= limit; inf: finite only
    unit: str
    why: str             # how the limit was derived (for the diagnosis)


def load_range(load) -> tuple[float, float]:
    """Smallest and largest resistance a load model can give."""
    if isinstance(load, ResistingLoad):
        # friction (and a brake) resist either way: the resistance ranges over +- its largest
        low, high = load_range(load.base)
        if load.resistive:
            low, high = min(low, 0.0), max(high, 0.0)
            low, high = -max(-low, high), max(-low, high)
        return low - load.breakaway, high + load.breakaway
    if isinstance(load, SpectrumLoad):
        return load.mean - load.bound, load.mean + load.bound
    if isinstance(load, ConstantLoad):
        return load.mean, load.mean
    if isinstance(load, RandomLoad):
        return load.mean - load.amplitude, load.mean + load.amplitude
    if isinstance(load, TabulatedLoad):
        return min(load.torques), max(load.torques)
    if isinstance(load, FourierLoad):
        spread = sum(math.hypot(a, b) for a, b in zip(load.cosines, load.sines))
        return load.mean - spread, load.mean + spread
    raise TypeError(f"unknown load model {type(load).__name__}")


def plausible_speed(plan: plans.Plan) -> tuple[float, str]:
    """The largest speed a driveline scene's parameters make plausible, and how it was found."""
    physics = plan.driveline.physics.get()
    engine, load = physics.engine, physics.load
    starts = [abs(w) for _, w in plan.driveline.start.get()]
    low, high = load_range(load.external)
    char = engine.external
    candidates = {"start speed": max(starts)}
    if isinstance(char, LinearCharacteristic) and char.slope > 0.0:
        candidates["steady speed of the engine line"] = max(abs(char.steady_speed(m)) for m in (0.0, low, high))
    else:
        if isinstance(char, TabulatedCharacteristic):
            torques = [abs(m) for m in char.torques]
            candidates["speeds of the engine table"] = max(abs(w) for w in char.speeds)
        else:
            torques = [abs(char.stall_torque)]
        span = plan.experiment.stop - plan.experiment.start
        candidates["free acceleration over the run"] = (max(torques) + max(abs(low), abs(high))) * span / (
            engine.inertia + load.inertia)
    which = max(candidates, key=candidates.get)
    return candidates[which], which


def _deflection_at_energy(law, energy: float) -> float:
    """The deflection theta >= 0 with ``V(theta) = energy`` (V is increasing)."""
    if isinstance(law, LinearElasticLaw):
        return math.sqrt(2.0 * energy / law.stiffness)
    high = 1.0
    while law.energy(high) < energy:
        high *= 2.0
    low = 0.0
    for _ in range(100):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if law.energy(mid) < energy else (low, mid)
    return high


def bounds(plan: plans.Plan) -> list[Bound]:
    """The bounds a run of a checked scene is held to (see the module docstring): speeds
    and coupling torques of the driveline, when the scene has one; nothing otherwise."""
    if plan.driveline is None:
        return _coupling_bounds(plan)
    limits = dict(plan.limits.get())
    margin = limits.get("margin", MARGIN)
    out = []
    try:
        built = plan.driveline.physics.get()
        plausible, which = plausible_speed(plan)
    except ParameterError:
        return []    # the FMUs will refuse the parameters with the proper message
    engine, load, coupling = built.engine, built.load, built.coupling
    engine_name, coupling_name, load_name = built.roles.engine, built.roles.coupling, built.roles.load
    if "speed" in limits:
        speed, why = limits["speed"], "set in the scene's [limits]"
    else:
        speed = margin * plausible
        why = f"{margin:g} x the largest plausible speed {plausible:.4g} rad/s ({which})"
    out += [Bound(f"{engine_name}.w", speed, "rad/s", why), Bound(f"{load_name}.w", speed, "rad/s", why)]
    if "torque" in limits:
        torque, why = limits["torque"], "set in the scene's [limits]"
    else:
        ratio = _largest_ratio(coupling.transfer)
        energy = 0.5 * (engine.inertia + load.inertia) * speed * speed
        theta = _deflection_at_energy(coupling.law, energy) if math.isfinite(energy) else math.inf
        torque = max(1.0, ratio) * (float(coupling.law.torque(theta)) + coupling.damping * (1.0 + ratio) * speed)
        why = (f"elastic torque at the driveline's kinetic energy at {speed:.4g} rad/s "
               f"({energy:.4g} J) plus damping torque")
    out += [Bound(f"{coupling_name}.tau1", torque, "N.m", why), Bound(f"{coupling_name}.tau2", torque, "N.m", why)]
    return out


def _coupling_bounds(plan: plans.Plan) -> list[Bound]:
    """The speed bound of a scene with our coupling and our engine shaft beside another
    FMU (module docstring); nothing for a scene without them."""
    coupling = plan.roles[1] if plan.roles else None
    if coupling is None:
        return []
    into = {c.input: c for c in plan.connections if c.target == coupling}
    sides = [into.get(k) for k in ("w1", "w2")]
    limits = dict(plan.limits.get())
    torques = [Bound(f"{coupling}.{t}", limits["torque"], "N.m", "set in the scene's [limits]")
               for t in ("tau1", "tau2")] if "torque" in limits else []
    if sides[0] is None or sides[0].source != plan.roles[0]:
        return torques
    try:
        values = check_all(component_parameters.ENGINE, scene_kinds.parameters(plan.scene, sides[0].source))
        engine = component_parameters.engine_of(values)
    except (ParameterError, ValueError):
        return torques
    char = engine.external
    candidates = {"start speed": abs(values["w_start"])}
    if isinstance(char, LinearCharacteristic) and char.slope > 0.0:
        candidates["no-load speed of the engine line"] = abs(char.steady_speed(0.0))
    else:
        torques = [abs(m) for m in char.torques] if isinstance(char, TabulatedCharacteristic) else [
            abs(char.stall_torque)]
        span = plan.experiment.stop - plan.experiment.start
        candidates["the engine's free acceleration over the run"] = max(torques) * span / engine.inertia
    if "speed" in limits:
        speed, why = limits["speed"], "set in the scene's [limits]"
    else:
        which = max(candidates, key=candidates.get)
        margin = limits.get("margin", MARGIN)
        speed = margin * candidates[which]
        why = f"{margin:g} x the largest plausible speed {candidates[which]:.4g} rad/s ({which})"
    return [Bound(f"{c.source}.{c.output}", speed, "rad/s", why) for c in sides if c is not None] + torques


class Guard:
    """Checks, after every communication step, the bounded variables and the finiteness
    of every connected output, from the system's buffers.  ``check`` raises ``Diverged``
    with a diagnosis: which component (and FMU), which variable, its value and bound,
    the time, the master, its step size and the step's number."""

    def __init__(self, system, master: str, step: float):
        self.master, self.step = master, step
        self._system = system
        self._limited = {b.variable: b for b in bounds(system.plan)}
        missing = [v for v in self._limited if (v.partition(".")[0], v.partition(".")[2]) not in system.index]
        if missing:
            system.expose(missing)
        self.watch()

    def watch(self):
        """Take the buffers to check from the system as it is wired now.  A master that
        exposes outputs of its own re-plans the system's buffers, so the run calls this
        again once the master is made (else the guard would read buffers no longer filled)."""
        system, limited = self._system, self._limited
        scene = system.scene
        checks, self._bounds = [], []
        for (component, variable), i in system.index.items():
            name = f"{component}.{variable}"
            connected = any(c.source == component and c.output == variable for c in scene.connections)
            if name not in limited and not connected:
                continue
            bound = limited.get(name) or Bound(name, math.inf, "", "finite")
            # an unlimited bound tests finiteness: +-inf must fail it as NaN does
            limit = bound.limit if math.isfinite(bound.limit) else sys.float_info.max
            checks.append((system.buffers[component][1], i, -limit, limit, len(self._bounds)))
            self._bounds.append((component, scene.components[component].fmu, variable, bound))
        self._checks = tuple(checks)
        self.check = self._compiled(self._checks)

    def _compiled(self, checks) -> Callable[[float, int], None]:
        """``check(t, step_index)``: every bound of ``checks`` tested in one function of
        straight-line tests (``harness.engine.straight_line``), the loop ``interpret`` walks."""
        source = Source("guard", "t, step_index")
        for values, i, low, high, k in checks:
            value = f"{source.elements(values, 'outputs')}[{i}]"
            low, high = source.name(low, "low"), source.name(high, "high")
            component, _, variable, _ = self._bounds[k]
            source.line(f"if not {low} <= {value} <= {high}:", f"{component}.{variable}")
            source.line(f"    fail({k}, {value}, t, step_index)")
        source.bound["fail"] = self._fail
        return source.function()

    def interpret(self, t: float, step_index: int):
        """What ``check`` does, by walking the checks (the reference its code is tested against)."""
        for values, i, low, high, k in self._checks:
            if not low <= values[i] <= high:           # NaN fails both comparisons, +-inf the largest floats
                self._fail(k, values[i], t, step_index)

    def _fail(self, k, value, t, step_index):
        component, fmu, variable, bound = self._bounds[k]
        unit = f" {bound.unit}" if bound.unit else ""
        if math.isfinite(value):
            what = (f"{component}.{variable} = {value:.6g}{unit} exceeds its physical bound "
                    f"{bound.limit:.4g}{unit} ({bound.why})")
            kind = "bound"
        else:
            what = f"{component}.{variable} = {value} is not finite"
            kind = "non-finite"
        # (the run appends the master, its step size and the number of steps taken)
        message = f"diverged: {what}; component {component} (FMU {fmu}), at t = {t:.6g} s, communication step {step_index}"
        raise Diverged(message, {"kind": kind, "component": component, "fmu": fmu, "variable": variable,
                                 "value": float(value), "bound": bound.limit, "bound_rule": bound.why,
                                 "time": t, "master": self.master, "step": self.step,
                                 "step_index": step_index})


@functools.lru_cache(maxsize=64)
def _largest_ratio(transfer) -> float:
    """The coupling's largest speed ratio U12, at 1024 angles a revolution (a transfer function
    is made once a process for the same values: so is this)."""
    return max(transfer.ratio(2.0 * math.pi * k / 1024) for k in range(1024))
