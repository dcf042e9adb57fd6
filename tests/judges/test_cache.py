"""The cache (harness.cache): every entry keyed on the code that computes it - every source
file of the harness and the physics, the scenes and data, the versions - so that an edit of
any module the references run (plan.py among them), in a copy of the code, misses the cache;
the cache lives in LEVER_CACHE_DIR or the user's cache folder, never in the checkout."""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from harness import api, cache, paths
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.judges import fmu_reference, monolithic
from harness.studies.bench import do_nothing_twins
from harness.studies.cases import CaseLog

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def own_cache(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv("LEVER_CACHE_DIR", str(folder))
    return folder


@pytest.fixture
def code_copy(tmp_path, monkeypatch) -> dict[str, Path]:
    """A copy of everything ``code_digest`` reads, which the digest reads from now on
    (``name -> path`` of the copy's files); the digest computed anew."""
    copies = []
    for root, pattern in cache.roots():
        copy = tmp_path / "copy" / str(len(copies)) / root.name
        shutil.copytree(root, copy, ignore=shutil.ignore_patterns("__pycache__", "_project"))
        copies.append((copy, pattern))
    monkeypatch.setattr(cache, "roots", lambda: copies)
    cache.code_digest.cache_clear()
    yield cache.source_files()
    cache.code_digest.cache_clear()


def _edit(path: Path):
    path.write_text(path.read_text() + "\n# edited\n")


def test_the_digest_reads_every_module_a_reference_runs(own_cache, fmu_dir):
    """Every module of the harness and the physics loaded while the monolithic reference
    and a made one are computed is among the files digested (names below the packages)."""
    plan = plans.check(scenes.load("kavz685").with_overrides(["experiment.stop=0.02"]))
    times = np.linspace(0.0, 0.02, 21)
    monolithic.solve(plan, times)
    fmu_reference.reference(plan, times, source="model-exchange")
    digested = {path.resolve() for path in cache.source_files().values()}
    packages = (paths.CODE / "harness", Path(sys.modules["lever"].__file__).resolve().parent)
    loaded = {Path(m.__file__).resolve() for m in list(sys.modules.values()) if getattr(m, "__file__", None)}
    ran = {path for path in loaded if any(path.is_relative_to(p) for p in packages)}
    assert len(ran) > 40 and ran <= digested, sorted(map(str, ran - digested))
    for module in ("harness/description/plan.py", "harness/description/scene_kinds.py", "harness/judges/monolithic.py",
                   "harness/judges/fmu_reference.py", "harness/engine/run.py", "lever/physics/coupling.py"):
        assert any(str(path).endswith(module) for path in ran & digested), module
    assert paths.SCENES / "kavz685.toml" in digested


def test_an_edit_of_any_module_a_reference_runs_changes_the_digest(code_copy, fmu_dir):
    """In a copy of the code (whose digest is the checkout's: the names are the files' own
    below their package), an edit of each module the references run, of a scene and of a
    data table changes the digest; the untouched copy's is the original's."""
    import harness.judges.fmu_reference  # noqa: F401 - loaded, as a made reference loads it

    original = cache.digest_of(cache.source_files(), cache.versions())
    cache.code_digest.cache_clear()
    assert cache.code_digest() == original
    packages = {name.split("/")[0] for name in code_copy}
    assert {"harness", "lever", "scenes", "data"} <= packages
    loaded = {Path(m.__file__).resolve() for m in list(sys.modules.values()) if getattr(m, "__file__", None)}
    real = {name: path for name, path in _real_files().items() if path.resolve() in loaded}
    assert "harness/description/plan.py" in real and "lever/physics/coupling.py" in real
    edited = sorted(real) + ["scenes/kavz685.toml", next(n for n in code_copy if n.startswith("data/"))]
    for name in edited:
        copy = code_copy[name]
        kept = copy.read_bytes()
        _edit(copy)
        assert cache.digest_of(cache.source_files(), cache.versions()) != original, name
        copy.write_bytes(kept)
    assert cache.digest_of(cache.source_files(), cache.versions()) == original


def _real_files() -> dict[str, Path]:
    import lever

    return cache.source_files([(paths.CODE / "harness", "*.py"), (Path(lever.__file__).resolve().parent, "*.py")])


def test_an_edited_plan_misses_the_cached_reference(own_cache, code_copy):
    """The monolithic reference solved and cached, found again; with plan.py edited (in
    the copy the digest reads) it is solved anew into an entry of its own."""
    spec = scenes.load("kavz685").with_overrides(["experiment.stop=0.02"])
    times = np.linspace(0.0, 0.02, 21)
    first = monolithic.solve(spec, times)
    again = monolithic.solve(spec, times)
    assert not first.info.get("cached") and again.info.get("cached")
    _edit(code_copy["harness/description/plan.py"])
    cache.code_digest.cache_clear()
    after = monolithic.solve(spec, times)
    assert not after.info.get("cached")
    stored = list((own_cache / "references").rglob("reference-kavz685-*.npz"))
    assert len(stored) == 2 and len({p.parent for p in stored}) == 2        # one folder of entries a code


def test_an_upgrade_misses_the_cache(monkeypatch):
    before = cache.digest_of(cache.source_files(), cache.versions())
    monkeypatch.setattr(paths, "version", lambda: "99.0")
    assert "lever-cosim 99.0" in cache.versions()
    assert cache.digest_of(cache.source_files(), cache.versions()) != before


def test_the_made_reference_the_twins_and_the_case_logs_are_keyed_on_the_code(own_cache, fmu_dir, monkeypatch,
                                                                                tmp_path):
    plan = plans.check(scenes.load("kavz685").with_overrides(["experiment.stop=0.02"]))
    times = np.linspace(0.0, 0.02, 21)
    made = fmu_reference.reference(plan, times, source="model-exchange")
    assert not made.info.get("cached")
    assert fmu_reference.reference(plan, times, source="model-exchange").info.get("cached")
    coupling = fmu_dir / f"{scenes.load('kavz685').components['coupling'].fmu}.fmu"
    twin_key = do_nothing_twins.twin_key(coupling)
    log = CaseLog(tmp_path / "study", {"study": "t"})
    log.record("a", {"status": "ok"})

    monkeypatch.setattr(cache, "code_digest", lambda: "another-code")
    assert not fmu_reference.reference(plan, times, source="model-exchange").info.get("cached")
    assert do_nothing_twins.twin_key(coupling) != twin_key
    again = CaseLog(tmp_path / "study", {"study": "t"})
    assert len(again) == 0 and again.set_aside is not None


def test_the_cache_is_where_lever_cache_dir_says_else_the_users_cache_of_this_version(tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "mine"))
    assert cache.folder() == tmp_path / "mine" and cache.part("references") == tmp_path / "mine" / "references"
    monkeypatch.delenv("LEVER_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    if sys.platform.startswith("linux"):
        assert cache.folder() == tmp_path / "xdg" / "lever-cosim" / paths.version()
    assert not cache.folder().is_relative_to(REPO)
    with pytest.raises(ValueError, match="one of references, do-nothing-twins, unit-factors"):
        cache.part("results")


def test_lever_cache_says_where_and_how_much_and_clears(lever, tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("LEVER_CACHE_DIR", str(folder))
    current = cache.entries("references")
    assert current == folder / "references" / cache.code_digest()
    current.mkdir(parents=True)
    (current / "reference-x.npz").write_bytes(b"0" * 1500)
    (folder / "references" / "other-code").mkdir()
    (folder / "references" / "other-code" / "reference-x.npz").write_bytes(b"0" * 500)
    (folder / "do-nothing-twins" / "other-code" / "abc").mkdir(parents=True)
    (folder / "do-nothing-twins" / "other-code" / "abc" / "EngineShaft.fmu").write_bytes(b"0" * 2000)
    (folder / "fmus").mkdir()
    (folder / "fmus" / "kept.fmu").write_bytes(b"0")           # not the cache's: a pip installation's FMUs
    held = api.cache()
    assert held["folder"] == folder and held["cleared"] is None
    assert held["total"] == {"files": 3, "bytes": 4000, "stale_files": 2, "stale_bytes": 2500}
    shown = lever("cache")
    assert shown.exit_code == 0 and f"cache: {folder}" in shown.output
    assert "references: 2 files, 2.0 kB" in shown.output
    assert "in all: 3 files, 4.0 kB (2 files, 2.5 kB of them stale)" in shown.output
    stale = lever("cache", "--clear-stale")
    assert stale.exit_code == 0 and "removed: 2 files, 2.5 kB (stale)" in stale.output
    assert [p.name for p in (folder / "references").iterdir()] == [cache.code_digest()]
    assert api.cache()["total"] == {"files": 1, "bytes": 1500, "stale_files": 0, "stale_bytes": 0}
    cleared = lever("cache", "--clear")
    assert cleared.exit_code == 0 and "removed: 1 file, 1.5 kB" in cleared.output
    assert sorted(p.name for p in folder.iterdir()) == ["fmus"]
    assert api.cache()["total"]["files"] == 0


# -- the checkout stays as it was ----------------------------------------------------------------

#: what a run may add to a checkout without changing it: Python's byte code, the test
#: session's own cache (other workers write there meanwhile; this test's runs do not)
BESIDE = ("__pycache__", ".pytest_cache", ".hypothesis", ".venv")


def _checkout_files() -> dict[Path, float]:
    session = Path(cache.folder()).resolve()
    out = {}
    for path in REPO.rglob("*"):
        inside = path.relative_to(REPO).parts
        if any(part in BESIDE for part in inside) or path.resolve().is_relative_to(session) or not path.is_file():
            continue
        out[path] = path.stat().st_mtime_ns
    return out


def test_a_run_and_a_bench_of_a_users_scene_leave_the_checkout_as_it_was(fmu_dir, tmp_path, monkeypatch):
    """The user's-FMU scene (examples/user_fmu, its FMU built in a temporary folder) run and
    benchmarked with their output folders elsewhere, the cache at its default place (the
    user's cache folder, here a temporary one): no file of the checkout added or changed, the
    made reference in the user's cache."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("user_fmu_build", REPO / "examples" / "user_fmu" / "build_fmu.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    folder = tmp_path / "user_fmu"
    build.build(folder)
    text = (REPO / "examples" / "user_fmu" / "user_driveline.toml").read_text()
    (folder / "user_driveline.toml").write_text(text.replace("stop = 2.0", "stop = 0.02")
                                                .replace("transient = 0.5", "transient = 0.01"))
    before = _checkout_files()
    monkeypatch.delenv("LEVER_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user-cache"))
    monkeypatch.chdir(tmp_path)
    run = api.run(folder / "user_driveline.toml", out=tmp_path / "run", notify=lambda *_: None)
    assert run.ok and run.summary["reference"]["source"] == "extrapolated co-simulation"
    bench = api.bench(folder / "user_driveline.toml", repeats=1, only=["jacobi"], peers=False, monolithic=False,
                      fmi_editions=False, out=tmp_path / "bench")
    assert bench["cases"]
    made = list(cache.part("references").rglob("fmu-reference-user_driveline-*.npz"))
    assert len(made) == 1 and made[0].is_relative_to(tmp_path / "user-cache")
    monkeypatch.undo()           # the session's cache again, left out of the files compared
    after = _checkout_files()
    added = sorted(str(p.relative_to(REPO)) for p in set(after) - set(before))
    changed = sorted(str(p.relative_to(REPO)) for p in set(after) & set(before) if after[p] != before[p])
    assert (added, changed) == ([], [])


def test_the_benchs_twins_go_to_the_cache(own_cache, fmu_dir):
    built = do_nothing_twins.twins(scenes.load("kavz685"), fmu_dir)
    assert built.is_relative_to(own_cache / "do-nothing-twins" / cache.code_digest())
    assert sorted(p.name for p in built.glob("*.fmu")) == ["EngineShaft.fmu", "LeverCoupling.fmu", "LoadShaft.fmu"]
    assert do_nothing_twins.twins(scenes.load("kavz685"), fmu_dir) == built          # built once, then reused
