"""Kinds of scene, decided in one place: a *driveline* (engine shaft - lever coupling -
load shaft, its misalignment perhaps driven by a source) or a *rectifier* (the freewheel
rectifier on its own).  The layers above dispatch on ``kind_of`` through registries of
their own (the monolithic reference's solvers, the run report's writers); the physics
objects of a driveline are built from a scene here and nowhere else (``physics``).
"""
from __future__ import annotations

from dataclasses import dataclass

from lever.physics import component_parameters

from harness.description import scene as scenes

#: the FMUs a driveline is made of, in the order of ``roles``
DRIVELINE_FMUS = ("EngineShaft", "LeverCoupling", "LoadShaft")
RECTIFIER_FMU = "FreewheelRectifier"


class NotADriveline(ValueError):
    """The scene has no engine shaft - lever coupling - load shaft chain."""


def roles(scene: scenes.Scene) -> tuple[str | None, str | None, str | None]:
    """The names of the scene's engine shaft, coupling and load shaft (None: missing)."""
    return tuple(scene.component_of(f) for f in DRIVELINE_FMUS)


def is_driveline(scene: scenes.Scene) -> bool:
    return all(roles(scene))


def rectifier(scene: scenes.Scene) -> str | None:
    """The name of the scene's freewheel rectifier, if it has one."""
    return scene.component_of(RECTIFIER_FMU)


#: kind -> test, in the order they are tried (the rectifier first: its scene is never a driveline)
KINDS = {"rectifier": lambda scene: rectifier(scene) is not None, "driveline": is_driveline}


def kind_of(scene: scenes.Scene) -> str | None:
    """``"rectifier"``, ``"driveline"`` or None (a scene of neither kind)."""
    return next((kind for kind, test in KINDS.items() if test(scene)), None)


@dataclass(frozen=True)
class Driveline:
    """The component names of a driveline scene."""
    engine: str
    coupling: str
    load: str


def driveline(scene: scenes.Scene) -> Driveline:
    """The scene's driveline roles; ``NotADriveline`` (the one message saying so) otherwise."""
    engine, coupling, load = roles(scene)
    if not (engine and coupling and load):
        raise NotADriveline(f"scene '{scene.name}' has no {' - '.join(DRIVELINE_FMUS)} chain (a driveline: "
                            "engine shaft - lever coupling - load shaft)")
    return Driveline(engine, coupling, load)


#: the driveline's wiring as its monolithic reference and energy balance assume it:
#: (source role, output, target role, input), roles as in ``Driveline``
DRIVELINE_WIRING = (("engine", "phi", "coupling", "phi1"), ("engine", "w", "coupling", "w1"),
                    ("load", "phi", "coupling", "phi2"), ("load", "w", "coupling", "w2"),
                    ("coupling", "tau1", "engine", "tau"), ("coupling", "tau2", "load", "tau"))
MISALIGNMENT_SOURCE_FMU = "MisalignmentSource"


def driveline_problem(scene: scenes.Scene) -> str | None:
    """Why the standard driveline's reference and energy balance do not describe ``scene``
    (None when they do): they solve engine shaft - lever coupling - load shaft, each once,
    wired shaft angle and speed into the coupling and its torques back into the shafts, the
    misalignment set or driven by a MisalignmentSource.  A torque path through another FMU,
    an input left open, a second shaft is another system, whose error against this
    reference would mean nothing."""
    try:
        names = driveline(scene)
    except NotADriveline as error:
        return str(error)
    for fmu in DRIVELINE_FMUS:
        several = [n for n, c in scene.components.items() if c.fmu == fmu]
        if len(several) > 1:
            return f"scene '{scene.name}' has {len(several)} {fmu} components ({', '.join(several)}); the driveline has one"
    role = {"engine": names.engine, "coupling": names.coupling, "load": names.load}
    declared = {names.engine: component_parameters.ENGINE, names.coupling: component_parameters.COUPLING + (component_parameters.MISALIGNMENT,),
                names.load: component_parameters.LOAD}
    for name, known in declared.items():
        extra = sorted(set(scene.components[name].parameters) - {p.name for p in known})
        if extra:      # e.g. an input held at a value: a torque from outside the reference's equations
            return (f"scene '{scene.name}' sets {', '.join(f'{name}.{x}' for x in extra)}, which the driveline's "
                    f"equations do not take (they take: {', '.join(p.name for p in known)})")
    wired = {(c.source, c.output, c.target, c.input) for c in scene.connections}
    expected = {(role[a], out, role[b], into) for a, out, b, into in DRIVELINE_WIRING}
    missing = [f"{a}.{o} -> {b}.{i}" for a, o, b, i in sorted(expected - wired)]
    if missing:
        return (f"scene '{scene.name}' is not wired as the driveline (engine shaft - lever coupling - load shaft): "
                f"no connection {', '.join(missing)}")
    for c in scene.connections:
        if c.target not in role.values() or (c.source, c.output, c.target, c.input) in expected:
            continue
        source_fmu = scene.components[c.source].fmu if c.source in scene.components else None
        if (c.target, c.input) == (names.coupling, "misalignment") and source_fmu == MISALIGNMENT_SOURCE_FMU:
            continue
        return (f"scene '{scene.name}': connection '{c}' drives the driveline from {source_fmu or c.source}, "
                "outside the engine shaft - lever coupling - load shaft torque path the reference solves")
    return None


def parameters(scene: scenes.Scene, name: str) -> dict:
    """The parameter values the scene gives component ``name`` (quantities with units
    converted; the declared defaults are not filled in)."""
    return {k: scenes.quantity(v, f"{name}.{k}") for k, v in scene.components[name].parameters.items()}


def energy_variables(scene: scenes.Scene) -> list[str]:
    """What a driveline run records for its energy balance (nothing for other kinds)."""
    engine, coupling, load = roles(scene)
    if not (engine and coupling and load):
        return []
    return [f"{engine}.w", f"{engine}.engine_work", f"{load}.w", f"{load}.load_work",
            f"{coupling}.elastic_energy", f"{coupling}.dissipated_power"]


#: the freewheel rectifier FMU's inputs, which a scene may hold at a value among its
#: parameters; the rectifier's physics object has no such parameter
RECTIFIER_INPUTS = ("tau", "tau_rate")


def rectifier_inputs(scene: scenes.Scene) -> dict:
    """The values the scene holds the rectifier's inputs at (those it states)."""
    return {k: v for k, v in parameters(scene, rectifier(scene)).items() if k in RECTIFIER_INPUTS}


def rectifier_model(scene: scenes.Scene):
    """The freewheel rectifier's physics object from the scene's values (the scene must
    have one: ``rectifier``); the inputs it holds are not the model's parameters."""
    values = parameters(scene, rectifier(scene))
    return component_parameters.freewheel_from({k: v for k, v in values.items() if k not in RECTIFIER_INPUTS})


@dataclass(frozen=True)
class DrivelinePhysics:
    """A driveline scene's physics objects, as its FMUs build them (lever.physics.component_parameters)."""
    roles: Driveline
    engine: object
    coupling: object
    load: object


def physics(scene: scenes.Scene) -> DrivelinePhysics:
    """The engine shaft, coupling and load shaft objects of ``scene`` from its parameter
    values (the declared defaults elsewhere); ``NotADriveline`` for another kind, the
    physics' ``ParameterError`` for a value out of its range."""
    names = driveline(scene)
    return DrivelinePhysics(names, component_parameters.engine_from(parameters(scene, names.engine)),
                            component_parameters.coupling_from(parameters(scene, names.coupling)),
                            component_parameters.load_from(parameters(scene, names.load)))
