"""What there is to choose from, and a choice checked: the committed scenes, a scene
loaded with its overrides, the co-simulation masters."""
from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Iterator

from harness.api import inputs as _inputs
from harness.api.inputs import InputError
from harness.description import scene as scene_files
from harness.description import units


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
    strict = _inputs.flag(strict, "strict")
    given = dict(a.split("=", 1) for a in assignments if "=" in a)
    given = {k.strip(): v.strip() for k, v in given.items()}
    overrides_named = _inputs.named("overrides")
    if stop is not None:
        _refuse_both("stop", stop, "experiment.stop", given.get("experiment.stop"), _seconds_or_none)
        assignments.append(f"experiment.stop={stop!r}")
    if strict:
        _refuse_both("strict", True, "experiment.strict", given.get("experiment.strict"),
                     scene_files.coerce)
        assignments.append("experiment.strict=true")
    try:
        if isinstance(scene, scene_files.Scene):
            spec = scene
        elif str(scene).endswith(".ssp"):
            from harness.formats import ssp
            spec = ssp.read_scene(scene)
        else:
            spec = scene_files.load(scene)
        return spec.with_overrides(assignments, overrides_named)
    except scene_files.SceneError as error:
        raise InputError(str(error)) from None


def checked_plan(spec: scene_files.Scene, fmu_dir: Path | None = None):
    """The scene's ``Plan`` (``harness.description.plan.check``, the FMUs of ``fmu_dir``,
    default the scene's or the built ones); InputError saying every refusal (a parameter's
    name, type, unit or range) before anything runs."""
    from harness.description import plan as plans
    from harness.engine.system import SceneInvalid
    from harness.paths import FMUS

    plan = plans.check(spec, fmu_dir=fmu_dir or spec.fmu_dir or FMUS)
    if plan.refusals:
        raise InputError(str(SceneInvalid(spec.name, list(plan.refusals))))
    return plan


def check_agreement(spec: scene_files.Scene, *, master: str | None = None, step: float | None = None,
                    tolerance: float | None = None):
    """InputError when ``master``, ``step`` or ``tolerance`` (``--master``, ``--step``,
    ``--tolerance``) and the scene's ``--set experiment.master``, ``experiment.step`` or
    ``experiment.tolerance`` say different things: the record
    (summary.json, report.md, the plots) states the ``--set`` values, so a run with
    another one in effect would be recorded as what it did not run."""
    if master is not None:
        _refuse_both("master", master, "experiment.master", spec.overrides.get("experiment.master"),
                     scene_files.coerce)
    if step is not None:
        _refuse_both("step", step, "experiment.step", spec.overrides.get("experiment.step"), _seconds_or_none)
    if tolerance is not None:
        _refuse_both("tolerance", tolerance, "experiment.tolerance", spec.overrides.get("experiment.tolerance"),
                     _number_or_none, unit="")


def _seconds_or_none(text: str) -> float | None:
    try:
        return _inputs.seconds(scene_files.coerce(text), "experiment")
    except InputError:
        return None


def _number_or_none(text: str) -> float | None:
    value = scene_files.coerce(text)
    return float(value) if units.is_number(value) else None


def _refuse_both(argument: str, value, key: str, raw: str | None, read, unit: str = " s"):
    """InputError when ``--set key=raw`` (read as ``read(raw)``) is not ``value``, the
    ``argument`` also given."""
    if raw is None:
        return
    said = read(str(raw))
    if isinstance(value, float) and isinstance(said, float) and math.isclose(value, said, rel_tol=1e-12):
        return
    if said == value and type(said) is type(value):
        return
    shown = f"{value:g}{unit}" if isinstance(value, float) else repr(value)
    raise InputError(f"{_inputs.named(argument).given(shown)} and {_inputs.named('overrides').item(key)}={raw} "
                     f"disagree: give one of them (both set the experiment's {key.split('.', 1)[1]})")


def masters(fixed_step: bool = False) -> dict[str, str]:
    """The co-simulation masters: name -> what it does (docs/reference/masters.md);
    ``fixed_step``: only those ``stability_map`` sweeps (no adaptive step, no Model Exchange)."""
    from harness.engine.masters import MASTERS

    if fixed_step:
        from harness.studies.stabilitymap import FIXED_STEP_MASTERS
        return {name: MASTERS[name].description for name in FIXED_STEP_MASTERS}
    return {name: cls.description for name, cls in MASTERS.items()}


def check_masters(*names: str, argument: str = "master"):
    """InputError naming ``argument`` when one of ``names`` is not a master."""
    from harness.engine import masters

    _inputs.names(names, argument)
    try:
        masters.check(*names)
    except masters.UnknownMaster as error:
        shown = repr(names[0]) if len(names) == 1 else repr(list(names))
        raise InputError(f"{_inputs.named(argument).given(shown)}: {error}") from None


@contextlib.contextmanager
def claimed_folder(out: Path, already: bool = False) -> Iterator[Path]:
    """``out`` made, proven writable and locked for the body (InputError when it cannot be,
    or another lever is writing there), then free again - unless this process held it
    before, or ``already`` (the caller claimed it)."""
    from harness.formats import outputs

    if already:
        yield Path(out)
        return
    held = outputs.holds(Path(out))
    try:
        out = outputs.claim(Path(out))
    except outputs.OutputError as error:
        raise InputError(str(error)) from None
    try:
        yield out
    finally:
        if not held:        # a caller's process goes on (a notebook): no lock or open file left behind
            outputs.release(out)
