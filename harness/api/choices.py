"""What there is to choose from, and a choice checked: the committed scenes, a scene
loaded with its overrides, the co-simulation masters."""
from __future__ import annotations

from pathlib import Path

from harness.api import inputs as _inputs
from harness.api.inputs import InputError
from harness.description import scene as scene_files


def scenes() -> dict[str, str]:
    """The committed scenes (resources/scenes): name -> description (an unreadable one:
    its error), as ``lever scenes`` lists them."""
    from harness.paths import SCENES

    out = {}
    for path in sorted(SCENES.glob("*.toml")):
        try:
            out[path.stem] = scene_files.load(path).description
        except scene_files.SceneError as error:
            out[path.stem] = f"(invalid: {error})"
    return out


#: the former name of ``scenes()``
scenes_list = scenes


def load(scene: str | Path | scene_files.Scene = "kavz685", overrides=None, *, stop: float | None = None,
         strict: bool = False) -> scene_files.Scene:
    """The scene (a name in resources/scenes, a .toml file, an SSP archive .ssp, or a Scene)
    with ``overrides`` (a dict ``{"component.parameter": value}`` or ``--set`` strings) and
    ``stop``; InputError on bad input."""
    scene = _inputs.scene_argument(scene)
    assignments = _inputs.assignments(overrides)
    stop = _inputs.seconds(stop, "stop")
    if stop is not None:
        assignments.append(f"experiment.stop={stop!r}")
    if strict:
        assignments.append("experiment.strict=true")
    try:
        if isinstance(scene, scene_files.Scene):
            spec = scene
        elif str(scene).endswith(".ssp"):
            from harness.formats import ssp
            spec = ssp.read_scene(scene)
        else:
            spec = scene_files.load(scene)
        return spec.with_overrides(assignments)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def masters(fixed_step: bool = False) -> dict[str, str]:
    """The co-simulation masters: name -> what it does (docs/reference/masters.md);
    ``fixed_step``: only those ``stability_map`` sweeps (no adaptive step, no Model Exchange)."""
    from harness.engine.masters import MASTERS

    if fixed_step:
        from harness.studies.stabilitymap import FIXED_STEP_MASTERS
        return {name: MASTERS[name].description for name in FIXED_STEP_MASTERS}
    return {name: cls.description for name, cls in MASTERS.items()}


def check_masters(*names: str):
    """InputError when one of ``names`` is not a master."""
    from harness.engine import masters

    _inputs.names(names, "master")
    try:
        masters.check(*names)
    except masters.UnknownMaster as error:
        raise InputError(str(error)) from None
