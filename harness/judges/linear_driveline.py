"""The stand-in for ``harness.engine.system.System`` the stability analysis steps
(``harness.judges.stability``): the scene's three components - the port on the drive side,
our lever coupling, the port on the driven side - with the FMUs' own model descriptions
(ports, time-derivative relations, output dependencies) but the linear two-inertia model
computed in Python, with the same exact shaft integrators our shaft FMUs use.  The real
master classes step it, so a one-step map is the one of the masters as implemented.

A port is our EngineShaft or LoadShaft (the default wiring), or another FMU the scene
connects to the coupling (``Port``: its file and the names of its angle, speed and torque):
the stand-in then carries that FMU's model description, so a master holds the torque of a
port that declares no ``tau_rate`` input, as it does on the real FMU.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from lever.physics.coupling import build_coupling
from lever.physics.engine import LinearCharacteristic
from lever.physics.friction import ResistingLoad
from lever.physics.load import ConstantLoad
from lever.physics.shaft import LaggedShaft, Shaft

from harness.description import scene as scenes
from harness.description.fmu_description import read_description, time_derivatives
from harness.engine.interface import CallCounts, RawCalls
from harness.engine.system import System, feedthrough_components
from harness.paths import FMUS


@dataclass(frozen=True)
class Port:
    """A shaft the coupling is connected to: ``fmu`` the file of a foreign FMU ("" for our
    shaft FMU of that side), the names of its angle and speed outputs and torque input."""
    fmu: str = ""
    phi: str = "phi"
    w: str = "w"
    tau: str = "tau"


@dataclass(frozen=True)
class Wiring:
    """The stand-in's two ports (default: our EngineShaft and LoadShaft)."""
    engine: Port = Port()
    load: Port = Port()


OURS = Wiring()


@lru_cache(maxsize=16)
def _description(path: str, mtime: float):
    return read_description(path)


def _read(path: Path):
    if not path.exists():
        raise FileNotFoundError(f"{path} is missing: build the FMUs first (lever build)")
    return _description(str(path), path.stat().st_mtime)


def _descriptions(fmu_dir: Path, wiring: Wiring) -> dict:
    return {"engine": _read(Path(wiring.engine.fmu) if wiring.engine.fmu else Path(fmu_dir) / "EngineShaft.fmu"),
            "coupling": _read(Path(fmu_dir) / "LeverCoupling.fmu"),
            "load": _read(Path(wiring.load.fmu) if wiring.load.fmu else Path(fmu_dir) / "LoadShaft.fmu")}


class _LinearComponent(CallCounts):
    """One component of the stand-in: the FMU's model description, values by value
    reference, and the interface the masters and ``System`` use
    (``harness.engine.interface.CoSimComponent``, its raw calls included)."""

    def __init__(self, name: str, description):
        self.name = name
        self.description = description
        self.variables = {v.name: v for v in description.modelVariables}
        self.values = {v.valueReference: 0.0 for v in description.modelVariables if v.type == "Real"}
        self._vr = {v.name: v.valueReference for v in description.modelVariables}
        self._start_counts()
        self.time = 0.0
        self.raw = RawCalls(None, self._get, self._set, self._raw_step)

    def variable(self, name):
        return self.variables[name]

    def vr(self, name):
        return self._vr[name]

    def __getitem__(self, name):
        return self.values[self._vr[name]]

    def __setitem__(self, name, value):
        self.values[self._vr[name]] = float(value)

    def real_buffer(self, names):
        names = list(names)
        return (ctypes.c_uint * len(names))(*[self.vr(n) for n in names]), (ctypes.c_double * len(names))()

    def _outputs(self):
        """Recompute the outputs from the inputs and the state."""

    def _get(self, handle, vrs, n, values):
        self._outputs()
        for i in range(n):
            values[i] = self.values[vrs[i]]
        return 0

    def _set(self, handle, vrs, n, values):
        for i in range(n):
            self.values[vrs[i]] = values[i]
        return 0

    def read(self, vrs, values):
        self.count("get")
        self._get(None, vrs, len(vrs), values)

    def write(self, vrs, values):
        self.count("set")
        self._set(None, vrs, len(vrs), values)

    def do_step(self, t, h):
        self.count("step")
        self._advance(t, h)
        self.time = t + h

    def _raw_step(self, handle, t, h, no_set_prior_state):
        self._advance(t, h)
        self.time = t + h
        return 0

    def _advance(self, t, h):
        pass

    def fail(self, call, status):
        raise RuntimeError(f"linear stand-in {self.name}: {call} returned status {status}")

    def save_state(self):
        return dict(self.values)

    def restore_state(self, state, time):
        self.values = dict(state)
        self.time = time

    def free_state(self, state):
        pass

    def free(self):
        pass


class _LinearShaft(_LinearComponent):
    def __init__(self, name, description, shaft: Shaft, port: Port = Port()):
        super().__init__(name, description)
        self.shaft = shaft
        self.port = port
        # the torque's derivative inputs the description declares (a master ramps them in,
        # fmu_description.time_derivatives); a port without them gets the torque held
        derivative_of = {of: name for name, of in time_derivatives(description).items()}
        self._rate = derivative_of.get(port.tau)
        self._accel = derivative_of.get(self._rate) if self._rate else None
        # the output a master reads as the speed's time derivative (the midpoint prediction)
        self._a = derivative_of.get(port.w)

    @property
    def phi(self) -> float:
        return self[self.port.phi]

    @property
    def w(self) -> float:
        return self[self.port.w]

    def set_motion(self, phi: float, w: float):
        self[self.port.phi], self[self.port.w] = phi, w

    def _inputs(self):
        return (self[self.port.tau], self[self._rate] if self._rate else 0.0,
                self[self._accel] if self._accel else 0.0)

    def _outputs(self):
        if self._a:
            self[self._a] = self.shaft.acceleration(self.time, self.phi, self.w, self[self.port.tau])

    def _advance(self, t, h):
        tau, rate, accel = self._inputs()
        phi, w, _ = self.shaft.advance(t, self.phi, self.w, tau, h, rate, accel)
        self.set_motion(phi, w)


class _LinearLaggedShaft(_LinearShaft):
    """The drive shaft with a lagged engine: the torque M is state, kept where the FMU
    reports it (``engine_torque``), so the masters' saved states carry it."""

    def _outputs(self):
        if self._a:
            self[self._a] = self.shaft.acceleration(self.time, self.phi, self.w, self[self.port.tau],
                                                    self["engine_torque"])

    def _advance(self, t, h):
        tau, rate, accel = self._inputs()
        phi, w, torque, _ = self.shaft.advance(t, self.phi, self.w, self["engine_torque"], tau, h, rate, accel)
        self.set_motion(phi, w)
        self["engine_torque"] = torque


class _LinearCoupling(_LinearComponent):
    def __init__(self, name, description, stiffness, damping):
        super().__init__(name, description)
        self.coupling = build_coupling("synchronous", 0.0, 0.0, 0.0, stiffness, damping)

    def _outputs(self):
        self["tau1"], self["tau2"] = self.coupling.torques(self["phi1"], self["w1"], self["phi2"], self["w2"])


def connections(wiring: Wiring) -> tuple[str, ...]:
    """The stand-in's six connections, in the ports' names."""
    e, l = wiring.engine, wiring.load
    return (f"engine.{e.phi} -> coupling.phi1", f"engine.{e.w} -> coupling.w1", f"load.{l.phi} -> coupling.phi2",
            f"load.{l.w} -> coupling.w2", f"coupling.tau1 -> engine.{e.tau}", f"coupling.tau2 -> load.{l.tau}")


DRIVELINE_CONNECTIONS = connections(OURS)


def _driven_load(model):
    """The linear load of the stand-in: none, or the load's viscous friction alone (smooth:
    ``lever.physics.friction``, no sticking without Coulomb friction)."""
    if not model.driven_slope:
        return ConstantLoad(0.0)
    return ResistingLoad(ConstantLoad(0.0), "active", 0.0, 0.0, model.driven_slope)


class LinearDriveline(System):
    """``System`` with the linear two-inertia model (``stability.TwoInertia``) in place of
    the FMUs (same wiring, same model descriptions, same propagation code)."""

    def __init__(self, model, step: float, fmu_dir: Path = FMUS):
        wiring = getattr(model, "wiring", None) or OURS
        descriptions = _descriptions(fmu_dir, wiring)
        self.model = model
        self.scene = scenes.Scene(
            name="linear-driveline", description="linearised two-inertia driveline",
            components={"engine": scenes.ComponentSpec(wiring.engine.fmu or "EngineShaft"),
                        "coupling": scenes.ComponentSpec("LeverCoupling"),
                        "load": scenes.ComponentSpec(wiring.load.fmu or "LoadShaft")},
            connections=[scenes.parse_connection(c) for c in connections(wiring)],
            experiment=scenes.Experiment(start=0.0, stop=1e9, step=step), record=[], features=set())
        self.record = []
        line = LinearCharacteristic(0.0, model.engine_slope)
        engine = (_LinearLaggedShaft("engine", descriptions["engine"],
                                     LaggedShaft(model.drive_inertia, line, model.engine_lag, 0.0), wiring.engine)
                  if model.engine_lag > 0.0 else
                  _LinearShaft("engine", descriptions["engine"], Shaft(model.drive_inertia, line), wiring.engine))
        self.components = {
            "engine": engine,
            "coupling": _LinearCoupling("coupling", descriptions["coupling"], model.stiffness, model.damping),
            "load": _LinearShaft("load", descriptions["load"], Shaft(model.driven_inertia, _driven_load(model)),
                                 wiring.load),
        }
        self.feedthrough = feedthrough_components(self.scene, {n: c.description for n, c in self.components.items()})
        self.stateful = [n for n in self.scene.components if n not in self.feedthrough]
        self._plan()

    @property
    def lagged(self) -> bool:
        return self.model.engine_lag > 0.0

    def set_state(self, phi1, w1, phi2, w2, torque=0.0, t=0.0):
        """Put the shafts (and a lagged engine's torque) in a state and make the system
        consistent (as after a step)."""
        for component in self.components.values():
            for vr in component.values:
                component.values[vr] = 0.0
            component.time = t
        engine, load = self.components["engine"], self.components["load"]
        engine.set_motion(phi1, w1)
        load.set_motion(phi2, w2)
        if self.lagged:
            engine["engine_torque"] = torque
        self.propagate()

    def state(self) -> list[float]:
        """``[phi1, w1, phi2, w2]``, and the engine torque when it lags."""
        engine, load = self.components["engine"], self.components["load"]
        return [engine.phi, engine.w, load.phi, load.w] + ([engine["engine_torque"]] if self.lagged else [])

    def motion(self, role: str) -> tuple[str, str]:
        """The names of the angle and the speed of the port ``role`` ("engine", "load")."""
        port = self.components[role].port
        return port.phi, port.w
