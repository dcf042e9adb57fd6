"""Building the FMUs from Python: ``build``, the built FMU file of a model, and what to do
when no C compiler can be run (the build's hint)."""
from __future__ import annotations

import importlib.util as _importlib_util
from pathlib import Path
from typing import Callable

from harness.api import inputs as _inputs
from harness.api.inputs import InputError
from harness.description import scene as scene_files
from harness.paths import BUILD, FMUS


class BuildError(RuntimeError):
    """The FMUs could not be built (no C compiler, a failed compliance check, ...)."""


#: what to do without a C compiler (the FMUs' native entry is compiled when they are built)
NO_COMPILER = ("the FMUs' native entry is C, compiled when they are built: install a C compiler "
               "(Debian/Ubuntu: sudo apt install gcc; Fedora: sudo dnf install gcc; macOS: xcode-select --install) "
               "or name one with CC (e.g. CC=clang lever build)")


def _with_compiler_hint(error: Exception) -> str:
    """The build's message, with what to do when no C compiler could be run."""
    return f"{error}; {NO_COMPILER}" if "cannot run" in str(error) and NO_COMPILER not in str(error) else str(error)


def _build_module():
    spec = _importlib_util.spec_from_file_location("_lever_build_fmus", BUILD / "fmus.py")
    module = _importlib_util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build(force: bool = False, fmu_dir: Path | None = None, log: Callable[[str], None] | None = None) -> Path:
    """Build the FMUs into ``fmu_dir`` (default ``harness.paths.FMUS``) when they are
    missing or older than their sources; return the folder.  BuildError when the build
    fails (no C compiler: the message says what to install)."""
    fmu_dir = _inputs.folder(fmu_dir, "fmu_dir") or Path(FMUS)
    module = _build_module()
    if force or not module.is_current(fmu_dir):
        try:
            module.build(fmu_dir, force=force, log=log or (lambda *_: None))
        except RuntimeError as error:
            raise BuildError(_with_compiler_hint(error)) from None
    return fmu_dir


def fmu_path(model: str, fmi: int = 2) -> Path:
    """The built FMU file of ``model`` (``"EngineShaft"``, ``"LeverCoupling"``, ...), built
    first when missing or stale: what fmpy's ``simulate_fmu`` or another host takes, in a
    checkout (build/fmus) and in a pip installation (the user's cache folder) alike.
    ``fmi=3``: its FMI 3.0 edition."""
    from harness.paths import fmi3_dir

    if fmi not in (2, 3) or isinstance(fmi, bool):
        raise InputError(f"fmi={fmi!r}: 2 or 3 (the FMI edition)")
    folder = build()
    folder = folder if fmi == 2 else fmi3_dir(folder)
    known = sorted(p.stem for p in folder.glob("*.fmu"))
    if model not in known:
        hint = scene_files.did_you_mean(model, known) if isinstance(model, str) else ""
        raise InputError(f"model={model!r}{hint}: one of {', '.join(known)}")
    return folder / f"{model}.fmu"
