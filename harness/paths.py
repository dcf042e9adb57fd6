"""Where the project's files are.

Two layouts.  In a checkout (``make``, ``pip install -e .``) everything is where the
repository has it: scenes and references under ``resources/``, the FMU build inputs under
``build/``, the built FMUs in ``build/fmus/`` and results in ``results/``.  A package
installed with ``pip install .`` carries the same inputs inside itself
(``harness/_project/``, read-only); it builds its FMUs into the per-user cache
(``platformdirs.user_cache_dir``, e.g. ``~/.cache/lever-cosim/<version>/fmus``) and writes
results under the folder it is run from (``./results``).  ``LEVER_FMU_DIR`` chooses
the FMUs' folder in either layout.  What the harness caches (references, the benchmark's
twins) lives in the per-user cache in either layout, never in the checkout (``harness.cache``).
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


def version() -> str:
    """The package's version (as installed; in a checkout run without an installation, the
    ``lever`` package's)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("lever-cosim")
    except PackageNotFoundError:
        from lever import __version__
        return __version__


def user_cache() -> Path:
    """The per-user cache folder of this version (``platformdirs.user_cache_dir``,
    ``~/.cache/lever-cosim/<version>`` on Linux): one folder per version, so two installed
    versions never rebuild or read each other's files."""
    import platformdirs

    return Path(platformdirs.user_cache_dir("lever-cosim", appauthor=False, version=version()))


def _fmu_dir() -> Path:
    chosen = os.environ.get("LEVER_FMU_DIR")
    if chosen:
        return Path(chosen).expanduser().resolve()
    return BUILD / "fmus" if not INSTALLED else user_cache() / "fmus"


FMUS = _fmu_dir()
RESULTS = Path.cwd() / "results" if INSTALLED else ROOT / "results"


def fmi3_dir(fmu_dir: Path = FMUS) -> Path:
    """Where the FMI 3.0 editions of the FMUs in ``fmu_dir`` are: ``fmus3`` beside a folder
    named ``fmus``, else ``<fmu_dir>/fmi3`` (as build/fmus.py puts them)."""
    here = Path(fmu_dir).resolve()
    return here.with_name("fmus3") if here.name == "fmus" else here / "fmi3"
