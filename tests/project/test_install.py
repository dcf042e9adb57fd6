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
        skipped |= {"fmus", "fmus3", "tmp"}
    return skipped


def _start(args, cwd: Path, env: dict) -> tuple[list, subprocess.Popen]:
    return args, subprocess.Popen(args, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(started: tuple[list, subprocess.Popen], timeout: float = 900) -> subprocess.CompletedProcess:
    args, process = started
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        stdout, stderr = process.communicate()
        raise AssertionError(f"{' '.join(map(str, args))} took more than {timeout} s:\n{stdout}\n{stderr}") from None
    done = subprocess.CompletedProcess(args, process.returncode, stdout, stderr)
    assert done.returncode == 0, f"{' '.join(map(str, args))} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done


def _run(args, cwd: Path, env: dict, timeout: float = 900) -> subprocess.CompletedProcess:
    return _finish(_start(args, cwd, env), timeout)


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
    for needed in ("constraints.txt", "build/fmus.py", "build/fmi3.py", "build/shim/compile.py",
                   "build/shim/lever_fmi2_shim.c", "build/shim/lever_fmi3_shim.c", "build/shim/lever_fmi2_abi.h",
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
    # (what the copy took of the checkout's build/: its sources, not its products)
    sources = [p.name for p in (REPO / "build").iterdir()]
    copied = sorted(set(sources) - _ignore(str(REPO / "build"), sources))
    assert sorted(p.name for p in (clone / "build").iterdir()) == copied


def test_an_installed_lever_builds_runs_and_validates_from_another_folder(installed):
    lever, work, env, site, _, _ = installed
    package = site / "harness" / "_project"
    before = sorted(str(p.relative_to(package)) for p in package.rglob("*"))

    listed = _run([lever, "scenes"], cwd=work, env=env).stdout
    assert "kavz685 " in listed and "freewheel_rectifier" in listed

    _run([lever, "build"], cwd=work, env=env)
    fmus = Path(env["XDG_CACHE_HOME"]) / "lever-cosim"
    built = sorted(str(p.relative_to(fmus)) for p in fmus.rglob("*.fmu"))
    expected = sorted(f"{edition}/{name}.fmu" for name in FMU_NAMES for edition in ("fmus", "fmus3"))
    assert [p.split("/", 1)[1] for p in built] == expected, f"the FMUs are not in the user's cache {fmus}: {built}"

    # a user's own scene, by path: the installed kavz685 without plots (the run by name
    # draws them; drawing is most of what a short run costs)
    scene_file = work / "my_scene.toml"
    features = 'features = ["reference", "energy_balance", "plots"]'
    text = (package / "resources" / "scenes" / "kavz685.toml").read_text()
    assert features in text
    scene_file.write_text(text.replace(features, 'features = ["reference", "energy_balance"]'))
    # Three commands from the work folder, started together (each writes a folder of its
    # own, and a user may well run two at once): the machine's second core runs one while
    # the first draws the run's plots - those of the time views: 0.1 s is less than a
    # revolution of the driven shaft, so the three plots over its angle are not drawn.
    started = [_start([lever, "run", "kavz685", "--stop", "0.1", "--no-progress"], cwd=work, env=env),
               _start([lever, "run", str(scene_file), "--stop", "0.3", "--no-reference", "--no-progress",
                       "--out", "by_path"], cwd=work, env=env),
               _start([lever, "validate", "EngineShaft"], cwd=work, env=env)]
    try:
        ran, _, checked = [_finish(s) for s in started]
    finally:
        for _, process in started:      # the others, when one failed
            if process.poll() is None:
                process.kill()
                process.wait()
    assert (work / "results" / "kavz685" / "summary.json").is_file(), ran.stdout + ran.stderr
    assert list((work / "results" / "kavz685").glob("*.png")), "the run drew no plots"
    assert (work / "by_path" / "traces.csv").is_file()
    assert "EngineShaft: PASS" in checked.stdout
    assert (work / "results" / "validate" / "EngineShaft" / "validation.json").is_file()

    after = sorted(str(p.relative_to(package)) for p in package.rglob("*") if "__pycache__" not in p.parts)
    assert after == [p for p in before if "__pycache__" not in p], "lever wrote into the installed package"
