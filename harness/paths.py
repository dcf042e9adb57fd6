"""Where the project's files are.

Two layouts.  In a checkout (``make``, ``pip install -e .``) everything is where the
repository has it: scenes and references under ``resources/``, the FMU build inputs under
``build/``, the built FMUs in ``build/fmus/`` and results in ``results/``.  A package
installed with ``pip install .`` carries the same inputs inside itself
(``harness/_project/``, read-only); it builds its FMUs into the per-user cache
(``platformdirs.user_cache_dir``, e.g. ``~/.cache/lever-cosim/<version>/fmus``) and writes
results under the folder it is run from (``./results``).  ``LEVER_FMU_DIR`` chooses
the FMUs' folder in either layout.
"""
import os
from pathlib import Path

_HERE = Path(__file__).resolve().parent
#: the folder that holds the ``harness`` package (a checkout, or site-packages)
CODE = _HERE.parent
#: True for a package installed with pip (not editable): the project's files are inside it
INSTALLED = (_HERE / "_project").is_dir()
ROOT = _HERE / "_project" if INSTALLED else CODE
RESOURCES = ROOT / "resources"
SCENES = RESOURCES / "scenes"
DATA = RESOURCES / "data"
BUILD = ROOT / "build"


def _fmu_dir() -> Path:
    chosen = os.environ.get("LEVER_FMU_DIR")
    if chosen:
        return Path(chosen).expanduser().resolve()
    if not INSTALLED:
        return BUILD / "fmus"
    from importlib.metadata import version

    import platformdirs

    # one folder per version: two installed versions never rebuild each other's FMUs
    return Path(platformdirs.user_cache_dir("lever-cosim", appauthor=False, version=version("lever-cosim"))) / "fmus"


FMUS = _fmu_dir()
RESULTS = Path.cwd() / "results" if INSTALLED else ROOT / "results"


def fmi3_dir(fmu_dir: Path = FMUS) -> Path:
    """Where the FMI 3.0 editions of the FMUs in ``fmu_dir`` are: ``fmus3`` beside a folder
    named ``fmus``, else ``<fmu_dir>/fmi3`` (as build/fmus.py puts them)."""
    here = Path(fmu_dir).resolve()
    return here.with_name("fmus3") if here.name == "fmus" else here / "fmi3"
