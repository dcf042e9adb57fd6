"""Kinds of scene, decided in one place: a *driveline* (engine shaft - lever coupling -
load shaft, its misalignment perhaps driven by a source) or a *rectifier* (the freewheel
rectifier on its own).  The layers above dispatch on ``kind_of`` through registries of
their own (the monolithic reference's solvers, the run report's writers); the physics
objects of a driveline are built from a scene here and nowhere else (``physics``).
"""
from __future__ import annotations

from dataclasses import dataclass

from lever.physics import catalogue

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


def parameters(scene: scenes.Scene, name: str) -> dict:
    """The parameter values the scene gives component ``name`` (quantities with units
    converted; the catalogue's defaults are not filled in)."""
    return {k: scenes.quantity(v, f"{name}.{k}") for k, v in scene.components[name].parameters.items()}


def energy_variables(scene: scenes.Scene) -> list[str]:
    """What a driveline run records for its energy balance (nothing for other kinds)."""
    engine, coupling, load = roles(scene)
    if not (engine and coupling and load):
        return []
    return [f"{engine}.w", f"{engine}.engine_work", f"{load}.w", f"{load}.load_work",
            f"{coupling}.elastic_energy", f"{coupling}.dissipated_power"]


def rectifier_model(scene: scenes.Scene):
    """The freewheel rectifier's physics object from the scene's values (the scene must
    have one: ``rectifier``)."""
    return catalogue.freewheel_from(parameters(scene, rectifier(scene)))


@dataclass(frozen=True)
class DrivelinePhysics:
    """A driveline scene's physics objects, as its FMUs build them (lever.physics.catalogue)."""
    roles: Driveline
    engine: object
    coupling: object
    load: object


def physics(scene: scenes.Scene) -> DrivelinePhysics:
    """The engine shaft, coupling and load shaft objects of ``scene`` from its parameter
    values (the catalogue's defaults elsewhere); ``NotADriveline`` for another kind, the
    physics' ``ParameterError`` for a value out of its range."""
    names = driveline(scene)
    return DrivelinePhysics(names, catalogue.engine_from(parameters(scene, names.engine)),
                            catalogue.coupling_from(parameters(scene, names.coupling)),
                            catalogue.load_from(parameters(scene, names.load)))
