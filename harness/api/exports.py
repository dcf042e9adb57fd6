"""A scene written for other tools: an SSP archive or one container FMU."""
from __future__ import annotations

from pathlib import Path

from harness.api import inputs as _inputs
from harness.api.building import build
from harness.api.choices import load
from harness.api.inputs import InputError
from harness.description import scene as scene_files
from harness.paths import FMUS


def export(scene: str | Path | scene_files.Scene = "kavz685", to: str = "ssp", overrides=None, *,
           out: Path | str | None = None) -> tuple[Path, dict[str, str], list[str]]:
    """``lever export-ssp`` (``to="ssp"``: an SSP archive) and ``lever export-container``
    (``to="container"``: one FMU holding the scene's FMUs): the scene with ``overrides``
    written to ``out`` (default results/<to>/<scene>.<suffix>).  Returns the file, what each
    engine needs to run it with its values (engine -> a command line) and what some engines
    would run otherwise than the scene says (sentences; none when the file carries every
    value)."""
    from harness.engine.system import SceneInvalid
    from harness.paths import RESULTS

    if to == "ssp":
        from harness.formats import ssp
        write, suffix, how_to_run = ssp.export, "ssp", ssp.how_to_run
    elif to == "container":
        from harness.formats import container
        write, suffix, how_to_run = container.build_container, "fmu", lambda *_: ({}, [])
    else:
        raise InputError(f"to={to!r}: ssp or container")
    spec = load(scene, overrides)
    out = _inputs.folder(out)
    build()
    out = Path(out) if out else RESULTS / to / f"{spec.name}.{suffix}"
    fmu_dir = spec.fmu_dir or FMUS
    try:
        path = write(spec, out, fmu_dir)
    except SceneInvalid as error:
        raise InputError(str(error)) from None
    return (path, *how_to_run(spec, path, fmu_dir))
