"""Outputs you can trust, and SSP archives handled with care.

The output folder is checked before a run (under a file, unwritable: exit 2 and a
sentence at once) and locked (a second writer is refused); an earlier run's files that a
run does not write are removed and report.md names only files that exist; a run whose
traces would not fit in memory is refused with "use --stream".  An SSP archive that would
unpack too large or to too many files is refused before unpacking; the unpacked copy is a
temporary folder, removed at the end of the process and at once when refused."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

from harness.description import scene as scenes
from harness.engine import component
from harness.formats import outputs, ssp

SHORT = ["--set", "experiment.stop=0.3", "--set", "experiment.transient=0.1"]
# Where a test is about the folder, not the plots: shorter than one revolution of the driven
# shaft (about 0.16 s), so the three plots over its angle are not drawn.
BRIEF_OVERRIDES = ["experiment.stop=0.1", "experiment.transient=0"]
BRIEF = [arg for override in BRIEF_OVERRIDES for arg in ("--set", override)]


def _run(lever, *args):
    return lever("run", "kavz685", *SHORT, *args)


@pytest.fixture(scope="module")
def earlier_run(lever, tmp_path_factory, fmu_dir) -> Path:
    """A run's folder with the reference and every plot: what the tests of a second run
    into the same folder start from (each on a copy of its own)."""
    out = tmp_path_factory.mktemp("earlier") / "run"
    result = _run(lever, "--out", out)
    assert result.exit_code == 0, result.output
    return out


def _copy_of(earlier: Path, where: Path) -> Path:
    out = where / "run"
    shutil.copytree(earlier, out, ignore=shutil.ignore_patterns(".lever.lock"))
    assert (out / "reference.csv").exists() and (out / "vs_reference.png").exists()
    return out


# -- the output folder ------------------------------------------------------------------------

def _no_run(monkeypatch):
    """A run that fails the test if it starts: what is refused is refused before any stepping
    (a bound in seconds held only on an idle machine)."""
    from harness.engine import run

    monkeypatch.setattr(run, "simulate", lambda *a, **k: pytest.fail("the run started before the refusal"))


def test_out_under_a_file_is_refused_before_the_run(lever, tmp_path, fmu_dir, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    _no_run(monkeypatch)
    result = _run(lever, "--out", blocker / "results")
    assert result.exit_code == 2
    assert f"is under {blocker}, which is a file, not a folder" in result.output and "Traceback" not in result.output
    result = _run(lever, "--out", blocker)
    assert result.exit_code == 2 and "is a file, not a folder" in result.output


def test_unwritable_out_is_refused(lever, tmp_path, fmu_dir):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    # root writes whatever a folder's mode says; /sys refuses even root
    target = Path("/sys/lever-results") if os.geteuid() == 0 else locked / "results"
    try:
        result = _run(lever, "--out", target)
        assert result.exit_code == 2 and "cannot write there (permission denied)" in result.output, result.output
    finally:
        locked.chmod(0o700)


def test_a_folder_that_refuses_writes_is_refused(tmp_path, monkeypatch):
    # as an unwritable folder does for a user who is not root: the probe write fails
    def refuse(self, data):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(Path, "write_bytes", refuse)
    with pytest.raises(outputs.OutputError, match="cannot write there \\(permission denied\\)"):
        outputs.check(tmp_path / "out")


def test_a_second_writer_is_refused_and_the_lock_dies_with_its_holder(lever, tmp_path, fmu_dir):
    out = tmp_path / "busy"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from harness.formats import outputs; "
                               f"outputs.claim({str(out)!r}); print('held', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        # the writers are this process (`lever` in-process), the holder another one
        second = lever("run", "kavz685", *BRIEF, "--out", out)
        assert second.exit_code == 2
        assert "another lever run is writing there" in second.stderr and f"pid {holder.pid}" in second.stderr
        assert not (out / "traces.csv").exists()
    finally:
        holder.kill()                     # a crash: the kernel drops the lock
        holder.wait()
    again = lever("run", "kavz685", *BRIEF, "--no-reference", "--no-plots", "--out", out)
    assert again.exit_code == 0, again.output
    assert (out / "traces.csv").exists()


def test_one_process_may_claim_its_folder_twice(tmp_path):
    first = outputs.claim(tmp_path / "x")
    try:
        assert outputs.claim(tmp_path / "x") == tmp_path / "x"
    finally:
        outputs.release(first)


def test_a_rerun_removes_what_it_does_not_write_and_the_report_names_what_exists(lever, earlier_run, tmp_path):
    out = _copy_of(earlier_run, tmp_path)
    (out / "notes.txt").write_text("the user's own file")
    # without the reference and the plots: the earlier run's reference and every plot of it
    # are files this run does not write
    result = _run(lever, "--out", out, "--no-reference", "--no-plots")
    assert result.exit_code == 0, result.output
    assert not (out / "reference.csv").exists() and not list(out.glob("*.png"))
    assert (out / "notes.txt").exists()                      # not a run's file: kept
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["files"]) == sorted(p.name for p in out.iterdir() if p.name not in (".lever.lock",
                                                                                             "notes.txt"))
    report = (out / "report.md").read_text()
    named = set(re.findall(r"[\w.]+\.(?:png|csv)", report))
    assert named and all((out / name).exists() for name in named)
    assert "reference.csv" not in report and "vs_reference.png" not in report


def test_a_failed_run_leaves_no_reference_of_an_earlier_one(lever, earlier_run, tmp_path):
    out = _copy_of(earlier_run, tmp_path)
    # diverges after 8 steps: traces and plots of those, no reference
    result = _run(lever, "--out", out, "--set", "coupling.stiffness=1e6", "--master", "jacobi")
    assert result.exit_code == 1 and "diverged" in result.output
    assert not (out / "reference.csv").exists() and not (out / "vs_reference.png").exists()
    assert len((out / "traces.csv").read_text().splitlines()) < 20
    report = (out / "report.md").read_text()
    assert "reference.csv" not in report and "vs_reference.png" not in report and "speeds.png" in report


def test_traces_that_would_not_fit_in_memory_are_refused_with_a_pointer_to_stream(lever, tmp_path, fmu_dir,
                                                                                   monkeypatch):
    _no_run(monkeypatch)
    result = _run(lever, "--step", "1e-9", "--set", "experiment.stop=100", "--out", tmp_path / "huge")
    assert result.exit_code == 2, result.output
    assert "use --stream" in result.output and "GiB" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "huge" / "traces.csv").exists()


# -- SSP archives -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def exported(tmp_path_factory, fmu_dir) -> Path:
    return ssp.export(scenes.load("kavz685"), tmp_path_factory.mktemp("ssp") / "kavz685.ssp", fmu_dir)


def _scratch_folders() -> set[str]:
    return set(component._scratch)


def test_an_archive_that_unpacks_too_large_is_refused_before_unpacking(exported, tmp_path, monkeypatch):
    bomb = tmp_path / "bomb.ssp"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", "<x/>")
        z.writestr("resources/zeros.bin", b"\0" * (8 << 20))     # 8 MiB of zeros: 8 kB in the archive
    assert bomb.stat().st_size < 100_000
    monkeypatch.setattr(ssp, "MAX_UNPACKED_BYTES", 4 << 20)
    before = _scratch_folders()
    with pytest.raises(scenes.SceneError, match=r"would unpack to 8 MiB, more than the 4 MiB allowed"):
        ssp.read_scene(bomb)
    assert _scratch_folders() == before                             # nothing was unpacked


def test_the_default_limit_refuses_a_gigabyte_bomb_on_the_command_line(lever, tmp_path):
    bomb = tmp_path / "gigabyte.ssp"
    # a directory that declares 2 GiB: what unpacking would write (zipfile stops a member at its
    # declared size); written with a stored member of that declared size but no data needed
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_STORED) as z:
        z.writestr("SystemStructure.ssd", "<x/>")
    data = bytearray(bomb.read_bytes())
    # patch the central directory's uncompressed size of the one member to 2 GiB
    central = data.rindex(b"PK\x01\x02")
    data[central + 24:central + 28] = (2 << 30).to_bytes(4, "little")
    bomb.write_bytes(bytes(data))
    result = lever("run", str(bomb), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2, result.output
    assert "would unpack to 2,048 MiB, more than the 1,024 MiB allowed" in result.output


def test_an_archive_of_too_many_files_is_refused(tmp_path, monkeypatch):
    many = tmp_path / "many.ssp"
    with zipfile.ZipFile(many, "w") as z:
        z.writestr("SystemStructure.ssd", "<x/>")
        for i in range(50):
            z.writestr(f"resources/{i}.txt", "")
    monkeypatch.setattr(ssp, "MAX_FILES", 40)
    with pytest.raises(scenes.SceneError, match="holds 51 files, more than the 40"):
        ssp.read_scene(many)


def test_the_unpacked_copy_is_temporary_and_a_broken_one_is_removed_at_once(exported, tmp_path):
    scene = ssp.read_scene(exported)
    where = Path(scene.fmu_dir).parent
    assert where.is_dir() and where.parent == Path(tempfile.gettempdir()) and str(where) in component._scratch
    # broken: an SSD that does not parse
    broken = tmp_path / "broken.ssp"
    with zipfile.ZipFile(exported) as source, zipfile.ZipFile(broken, "w") as z:
        for item in source.infolist():
            z.writestr(item, b"<not xml" if item.filename == "SystemStructure.ssd" else source.read(item))
    before = _scratch_folders()
    with pytest.raises(scenes.SceneError, match="does not parse"):
        ssp.read_scene(broken)
    assert all(not Path(f).exists() for f in _scratch_folders() - before)


def test_a_lever_run_of_an_archive_leaves_no_unpacked_copy(lever_process, exported, tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    done = lever_process.run("run", exported, *BRIEF, "--no-reference", "--out", tmp_path / "out", timeout=120,
                             env={**os.environ, "TMPDIR": str(scratch)})
    assert done.returncode == 0, done.stderr
    assert list(scratch.iterdir()) == []


def _open_files_under(folder) -> list[str]:
    """The files this process has open under ``folder``."""
    opened = []
    for fd in os.listdir(f"/proc/{os.getpid()}/fd"):
        try:
            opened.append(os.readlink(f"/proc/{os.getpid()}/fd/{fd}"))
        except OSError:         # the listing's own descriptor, closed by now
            pass
    return [path for path in opened if path.startswith(str(folder))]


def _claimable_by_another_process(folder) -> bool:
    other = subprocess.run([sys.executable, "-c", "from harness.formats import outputs; "
                            f"outputs.claim({str(folder)!r}); print('held')"], capture_output=True, text=True)
    return other.returncode == 0 and other.stdout.strip() == "held"


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="counts open files through /proc")
def test_a_python_caller_gets_each_folder_back_when_the_call_returns(tmp_path, fmu_dir):
    """A notebook or a script makes run after run in one process: each call's lock on its
    folder (and the open lock file) ends with the call, so a thousand runs do not exhaust
    the process's files, and another process may write there afterwards.  A folder the
    caller holds itself stays held."""
    from harness import api

    quiet = dict(notify=lambda *_: None)
    for k in range(3):
        api.run("kavz685", BRIEF_OVERRIDES, reference=False, plots=False, out=tmp_path / f"run{k}", **quiet)
    api.stability_map("kavz685", stiffnesses=[1e4], dampings=[0.0], h_omegas=[0.2], masters=["jacobi"],
                      min_steps=16, refine=False, jobs=1, out=tmp_path / "map")
    assert _open_files_under(tmp_path) == []
    assert not any(outputs.holds(tmp_path / name) for name in ("run0", "run1", "run2", "map"))
    assert _claimable_by_another_process(tmp_path / "run2") and _claimable_by_another_process(tmp_path / "map")
    mine = outputs.claim(tmp_path / "mine")
    try:
        api.run("kavz685", BRIEF_OVERRIDES, reference=False, plots=False, out=tmp_path / "mine", **quiet)
        assert outputs.holds(tmp_path / "mine") and not _claimable_by_another_process(tmp_path / "mine")
    finally:
        outputs.release(mine)
