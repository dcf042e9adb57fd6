"""`pip install <clone>` (not editable) gives a `lever` that works from any folder: the
wheel carries the scenes, references, data and FMU build inputs; `lever build` builds the
FMUs into the user's cache, `lever run` and `lever validate` write under the folder they
are run from, and nothing is written into the installed package or the clone's build/.

Offline and without build isolation: the wheel is built by this environment's pinned
setuptools from a copy of the checkout, and installed without dependencies into a fresh
virtual environment that sees this environment's packages through a .pth file."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from lever.fmus.registry import NAMES as FMU_NAMES

REPO = Path(__file__).resolve().parents[2]

#: what a clone has that a checkout in use adds: left out of the copy the wheel is built from
GENERATED = {".venv", ".git", "results", ".setuptools-build", ".hypothesis", ".pytest_cache", "__pycache__",
             "mutants"}


def _ignore(folder: str, names: list[str]) -> set[str]:
    here = Path(folder).resolve()
    skipped = {n for n in names if n in GENERATED or n.endswith((".egg-info", ".fmu", ".pyc"))}
    if here == REPO / "build":
        skipped |= {"fmus", "tmp"}
    return skipped


def _run(args, cwd: Path, env: dict, timeout: float = 900) -> subprocess.CompletedProcess:
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(map(str, args))} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(the venv's lever, a work folder outside the clone, the environment, the venv's
    site-packages, the clone's copy)"""
    root = tmp_path_factory.mktemp("install")
    clone = root / "clone"
    shutil.copytree(REPO, clone, ignore=_ignore)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("LEVER_", "PYTHON"))}
    env["XDG_CACHE_HOME"] = str(root / "cache")           # platformdirs' user cache on Linux
    env["PIP_NO_INDEX"] = "1"
    wheels = root / "wheels"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", str(wheels), str(clone)], cwd=clone, env=env)
    venv = root / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=root, env=env)
    python = venv / "bin" / "python"
    site = Path(subprocess.check_output([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                        text=True).strip())
    (site / "project_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    wheel = next(wheels.glob("lever_cosim-*.whl"))
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q",
          str(wheel)], cwd=root, env=env)
    work = root / "work"
    work.mkdir()
    return venv / "bin" / "lever", work, env, site, clone, wheel


def test_the_wheel_carries_what_an_installed_lever_needs_and_leaves_the_clones_build_folder_alone(installed):
    _, _, _, _, clone, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    project = "harness/_project/"
    for needed in ("constraints.txt", "build/fmus.py", "build/shim/compile.py", "build/shim/lever_fmi2_shim.c",
                   "resources/scenes/kavz685.toml", "resources/reference/kavz685/kavz685_ref.csv",
                   "resources/reference/EngineShaft/EngineShaft_in.csv",
                   "resources/data/monograph/harmonics_driven.csv", "tests/c_host/minimal_importer.c"):
        assert project + needed in names, f"the wheel lacks {needed}"
    # every package of the harness (pyproject.toml lists them one by one)
    packages = sorted(str(p.relative_to(REPO)) for p in (REPO / "harness").rglob("__init__.py"))
    assert [p for p in packages if p not in names] == []
    scenes = {p.name for p in (REPO / "resources" / "scenes").glob("*.toml")}
    assert {n.rsplit("/", 1)[1] for n in names if n.startswith(project + "resources/scenes/")} == scenes
    assert not [n for n in names if n.endswith(".fmu") or "/build/fmus/" in n or "/results/" in n]
    # setuptools' own build folder is not the project's build/ (it would leave build/lib there)
    copied = sorted(p.name for p in (REPO / "build").iterdir() if p.name not in _ignore(str(REPO / "build"),
                                                                                         [p.name]))
    assert sorted(p.name for p in (clone / "build").iterdir()) == copied == ["docs.py", "fmus.py", "shim"]


def test_an_installed_lever_builds_runs_and_validates_from_another_folder(installed):
    lever, work, env, site, _, _ = installed
    package = site / "harness" / "_project"
    before = sorted(str(p.relative_to(package)) for p in package.rglob("*"))

    listed = _run([lever, "scenes"], cwd=work, env=env).stdout
    assert "kavz685 " in listed and "freewheel_rectifier" in listed

    _run([lever, "build"], cwd=work, env=env)
    fmus = Path(env["XDG_CACHE_HOME"]) / "lever-cosim"
    built = sorted(p.name for p in fmus.rglob("*.fmu"))
    assert built == sorted(f"{name}.fmu" for name in FMU_NAMES), f"the FMUs are not in the user's cache {fmus}: {built}"

    ran = _run([lever, "run", "kavz685", "--stop", "0.5", "--no-progress"], cwd=work, env=env)
    assert (work / "results" / "kavz685" / "summary.json").is_file(), ran.stdout + ran.stderr
    scene_file = work / "my_scene.toml"
    shutil.copy(package / "resources" / "scenes" / "kavz685.toml", scene_file)
    _run([lever, "run", str(scene_file), "--stop", "0.3", "--no-reference", "--no-progress", "--out", "by_path"],
         cwd=work, env=env)
    assert (work / "by_path" / "traces.csv").is_file()

    checked = _run([lever, "validate", "EngineShaft"], cwd=work, env=env)
    assert "EngineShaft: PASS" in checked.stdout
    assert (work / "results" / "validate" / "EngineShaft" / "validation.json").is_file()

    after = sorted(str(p.relative_to(package)) for p in package.rglob("*") if "__pycache__" not in p.parts)
    assert after == [p for p in before if "__pycache__" not in p], "lever wrote into the installed package"
