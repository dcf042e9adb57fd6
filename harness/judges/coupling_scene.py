"""The two-inertia chain of any scene with our LeverCoupling: what the stability analysis
(``harness.judges.stability``) needs, read from the scene where the ports are our shafts
and measured where they are not.

The coupling is ours, so its stiffness and damping come from the scene's values.  Each of
its two sides must be one shaft: ``P.phi_out -> coupling.phi1``, ``P.w_out -> coupling.w1``
and ``coupling.tau1 -> P.tau_in`` from and to the same component ``P`` (and the same for
``phi2``, ``w2``, ``tau2``).  A side that is our EngineShaft (drive side) or LoadShaft
(driven side) is read from its parameters, as for our own scenes; any other FMU is
measured from outside (``harness.judges.port_probe``): its inertia and its damping, the
slope of its torque in its speed - from its Model Exchange derivatives where it offers
them with its speed a state, else by probe runs of its co-simulation interface.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lever.physics import component_parameters
from lever.physics.engine import LinearCharacteristic
from lever.physics.parameters import check_all

from harness.description import plan as plans, scene_kinds
from harness.description import scene as scenes
from harness.judges import port_probe
from harness.judges.linear_driveline import Port, Wiring
from harness.paths import FMUS

COUPLING_FMU = "LeverCoupling"


class NoCouplingModel(scene_kinds.NotADriveline):
    """The scene has no lever coupling between two shafts the analysis can model."""


def what_is_needed(scene_name: str, problem: str) -> str:
    return (f"scene '{scene_name}': {problem}.  Stability analysis needs our {COUPLING_FMU} between two shafts: "
            "on each side one component wired P.<angle> -> coupling.phi1, P.<speed> -> coupling.w1, "
            "coupling.tau1 -> P.<torque> (and phi2, w2, tau2 on the other side); a side that is not our "
            "EngineShaft or LoadShaft is measured by short probe runs of its FMU")


@dataclass(frozen=True)
class Side:
    """One side of the coupling: the shaft's inertia, the slope of its torque in its
    speed, its torque lag (our lagged engine only) and, when measured, its PortModel."""
    component: str
    inertia: float
    slope: float
    lag: float = 0.0
    measured: port_probe.PortModel | None = None


@dataclass(frozen=True)
class Chain:
    drive: Side
    driven: Side
    stiffness: float
    damping: float
    wiring: Wiring


def engine_side(values: dict) -> tuple[float, float, float]:
    """``(inertia, slope K1, lag Te)`` of our EngineShaft from its checked values (a
    tabulated characteristic by its slope at the starting speed)."""
    characteristic = component_parameters.engine_of(values).external
    if isinstance(characteristic, LinearCharacteristic):
        slope = characteristic.slope
    else:
        w, dw = values["w_start"], max(1e-3, 1e-3 * abs(values["w_start"]))
        slope = -(characteristic.torque(0.0, 0.0, w + dw) - characteristic.torque(0.0, 0.0, w - dw)) / (2 * dw)
    lag = values["torque_lag"] if values["torque_lag"] >= component_parameters.SHORTEST_LAG else 0.0
    return values["inertia"], max(0.0, slope), lag


def _port(scene: scenes.Scene, coupling: str, k: int) -> tuple[str, Port]:
    """The component on side ``k`` (1, 2) of the coupling and the names of its port."""
    into = {c.input: c for c in scene.connections if c.target == coupling}
    out = [c for c in scene.connections if c.source == coupling and c.output == f"tau{k}"]
    phi, w = into.get(f"phi{k}"), into.get(f"w{k}")
    if phi is None or w is None or not out:
        missing = [n for n, c in ((f"phi{k}", phi), (f"w{k}", w)) if c is None] + ([] if out else [f"tau{k}"])
        raise NoCouplingModel(what_is_needed(scene.name, f"{coupling}.{', '.join(missing)} is not connected"))
    shaft = phi.source
    if w.source != shaft or all(c.target != shaft for c in out):
        raise NoCouplingModel(what_is_needed(
            scene.name, f"side {k} of {coupling} is not one shaft ({coupling}.phi{k} from {phi.source}, "
                        f"w{k} from {w.source}, tau{k} to {', '.join(c.target for c in out)})"))
    tau = next(c for c in out if c.target == shaft)
    return shaft, Port("", phi.output, w.output, tau.input)


def chain(scene: scenes.Scene, fmu_dir: Path = FMUS, say=None) -> Chain:
    """The coupling's chain of ``scene`` (module docstring); ``NoCouplingModel`` says what
    is missing, ``port_probe.ProbeRefused`` which FMU refused its probes and why."""
    coupling = scene.component_of(COUPLING_FMU)
    if coupling is None:
        raise NoCouplingModel(what_is_needed(scene.name, f"it has no {COUPLING_FMU}"))
    (drive, drive_port), (driven, driven_port) = _port(scene, coupling, 1), _port(scene, coupling, 2)
    law = _law(scene, coupling)
    plan = None
    sides, ports = [], []
    for name, port, ours in ((drive, drive_port, "EngineShaft"), (driven, driven_port, "LoadShaft")):
        fmu = scene.components[name].fmu
        if scenes.fmu_name(fmu) == ours and not scenes.is_fmu_path(fmu) and (port.phi, port.w, port.tau) == (
                "phi", "w", "tau"):
            sides.append(_our_side(scene, name, ours))
            ports.append(Port())
            continue
        plan = plan or plans.check(scene, fmu_dir=fmu_dir)
        if plan.refusals:
            raise NoCouplingModel(what_is_needed(scene.name, "it cannot run: " + "; ".join(plan.refusals)))
        path = plan.paths[name]
        measured = port_probe.probe(name, path, dict(plan.start_values.get(name, {})), port.tau, port.w,
                                    scene.experiment.step, say)
        sides.append(Side(name, measured.inertia, max(0.0, measured.damping), 0.0, measured))
        ports.append(Port(str(path), port.phi, port.w, port.tau))
    return Chain(sides[0], sides[1], law.law.nominal_stiffness, law.damping, Wiring(*ports))


def _law(scene: scenes.Scene, coupling: str):
    return component_parameters.coupling_of(*component_parameters.check_coupling(
        scene_kinds.parameters(scene, coupling)))


def coupling_values(scene: scenes.Scene) -> tuple[float, float]:
    """``(stiffness, damping)`` of the scene's coupling [N*m/rad, N*m*s/rad] (a tabulated
    elastic law by its nominal stiffness), from its values alone: what a map of a scene
    whose ports cannot be measured still sweeps about.  ``NoCouplingModel`` as ``chain``."""
    coupling = scene.component_of(COUPLING_FMU)
    if coupling is None:
        raise NoCouplingModel(what_is_needed(scene.name, f"it has no {COUPLING_FMU}"))
    _port(scene, coupling, 1), _port(scene, coupling, 2)
    law = _law(scene, coupling)
    return law.law.nominal_stiffness, law.damping


def _our_side(scene: scenes.Scene, name: str, fmu: str) -> Side:
    if fmu == "EngineShaft":
        inertia, slope, lag = engine_side(check_all(component_parameters.ENGINE, scene_kinds.parameters(scene, name)))
        return Side(name, inertia, slope, lag)
    values = check_all(component_parameters.LOAD, scene_kinds.parameters(scene, name))
    return Side(name, values["inertia"], values["viscous_damping"])
