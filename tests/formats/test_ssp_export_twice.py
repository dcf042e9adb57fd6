"""An archive's configured FMU exported again (harness/formats/configured_fmu.py, ssp.export):
the values of the new export are the ones its FMUs carry.

A scene read from an archive runs the archive's configured FMUs; exported with a changed
value (``--set coupling.stiffness=900`` over the archive's 715.4), each FMU must start at
the new value - in its model description, in the resource it reads at instantiation, in
what the instantiated FMU reports - and its values the same as those of a fresh export of
the scene with that value, so that fmpy.ssp (a host we did not write, which applies no
parameter binding) runs the re-exported archive exactly as the fresh one."""
from __future__ import annotations

import json
import shutil
import tempfile
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest

from harness.description import scene as scenes
from harness.formats import ssp
from harness.formats.configured_fmu import configure, configured_guid

STIFFNESS = 900.0


def _coupling(archive: Path, where: Path) -> Path:
    with zipfile.ZipFile(archive) as z:
        return Path(z.extract("resources/LeverCoupling.fmu", where))


def _started_at(fmu: Path, where: Path, name: str) -> float:
    md = fmpy.read_model_description(str(fmu))
    vr = next(v.valueReference for v in md.modelVariables if v.name == name)
    instance = fmpy.instantiate_fmu(fmpy.extract(str(fmu), unzipdir=where), md)
    try:
        return instance.getReal([vr])[0]
    finally:
        instance.freeInstance()


@pytest.fixture(scope="module")
def archives(fmu_dir, tmp_path_factory):
    where = tmp_path_factory.mktemp("twice")
    first = ssp.export(scenes.load("kavz685"), where / "first.ssp", fmu_dir)
    read = ssp.read_scene(first)
    assert read.fmu_dir is not None
    again = ssp.export(read.with_overrides([f"coupling.stiffness={STIFFNESS}"]), where / "again.ssp", read.fmu_dir)
    fresh = ssp.export(scenes.load("kavz685").with_overrides([f"coupling.stiffness={STIFFNESS}"]),
                       where / "fresh.ssp", fmu_dir)
    return {"first": first, "again": again, "fresh": fresh}


def test_the_fmu_exported_again_carries_the_new_value_everywhere(archives, tmp_path):
    first = _coupling(archives["first"], tmp_path / "first")
    again = _coupling(archives["again"], tmp_path / "again")
    assert _started_at(first, tmp_path / "u1", "stiffness") == 715.4
    starts = {v.name: v.start for v in fmpy.read_model_description(str(again)).modelVariables}
    assert float(starts["stiffness"]) == STIFFNESS
    with zipfile.ZipFile(again) as z:
        carried = json.loads(z.read("resources/lever_start_values.json"))
    assert carried["stiffness"] == STIFFNESS
    assert _started_at(again, tmp_path / "u2", "stiffness") == STIFFNESS
    with zipfile.ZipFile(_coupling(archives["fresh"], tmp_path / "fresh")) as z:
        assert json.loads(z.read("resources/lever_start_values.json")) == carried


def test_configuring_twice_keeps_the_earlier_values_the_later_do_not_name(fmu_dir, tmp_path):
    once = configure(Path(fmu_dir) / "LeverCoupling.fmu", {"stiffness": 812.5, "damping": 3.0}, tmp_path / "1.fmu")
    twice = configure(once, {"stiffness": 640.0}, tmp_path / "a" / "folder" / "2.fmu")     # made where it is missing
    with zipfile.ZipFile(twice) as z:
        carried = json.loads(z.read("resources/lever_start_values.json"))
    assert carried == {"stiffness": 640.0, "damping": 3.0}
    assert _started_at(twice, tmp_path / "u", "stiffness") == 640.0
    assert _started_at(twice, tmp_path / "v", "damping") == 3.0
    # the shim's configuration is the original's but for the GUID line (where it finds Python stays)
    with zipfile.ZipFile(Path(fmu_dir) / "LeverCoupling.fmu") as z:
        original = z.read("resources/lever_shim.cfg").decode().splitlines()
    with zipfile.ZipFile(twice) as z:
        configured = z.read("resources/lever_shim.cfg").decode().splitlines()
        guid = fmpy.read_model_description(str(twice)).guid
    assert len(configured) == len(original) and sum(a != b for a, b in zip(original, configured)) == 1
    assert [line for line in configured if line.startswith("guid=")] == [f"guid={guid}"]


def test_fmpy_ssp_runs_the_archive_exported_again_as_the_fresh_one(archives):
    from fmpy.ssp.simulation import simulate_ssp

    runs = {name: simulate_ssp(str(path), stop_time=0.05, step_size=1e-3) for name, path in archives.items()}
    tau = "coupling.tau2" if "coupling.tau2" in runs["again"].dtype.names else next(
        n for n in runs["again"].dtype.names if n.endswith("tau2"))
    assert np.array_equal(runs["again"][tau], runs["fresh"][tau])
    assert not np.allclose(runs["again"][tau], runs["first"][tau], rtol=1e-3)


ORIGINAL = "{8c4e810f-3df3-4a00-8276-176fa3c9f000}"


def test_a_configured_guid_is_a_uuid_of_the_original_and_the_values_whatever_their_order():
    import uuid

    guid = configured_guid(ORIGINAL, {"stiffness": 900.0, "damping": 2.0})
    assert uuid.UUID(guid).version == 5
    assert guid == configured_guid(ORIGINAL, {"damping": 2.0, "stiffness": 900.0})      # the same configuration
    assert guid != configured_guid(ORIGINAL, {"stiffness": 900.5, "damping": 2.0})      # another value
    assert guid != configured_guid(ORIGINAL, {"stiffness": 900.0})                     # fewer values
    assert guid != configured_guid("{8c4e810f-3df3-4a00-8276-176fa3c9f001}", {"stiffness": 900.0, "damping": 2.0})
    assert guid not in (ORIGINAL, ORIGINAL.strip("{}"))
    # an FMI 3.0 instantiation token need not be a UUID: the configured one still is
    token = configured_guid("lever-coupling-token", {"stiffness": 900.0})
    assert uuid.UUID(token).version == 5
    assert token != configured_guid("another token", {"stiffness": 900.0})             # derived from the token too
    assert token == configured_guid("lever-coupling-token", {"stiffness": 900.0})


def test_configuring_refuses_an_fmu_that_cannot_carry_values_and_a_value_that_does_not_fit_by_name(fmu_dir,
                                                                                                   tmp_path):
    plain = tmp_path / "Plain.fmu"            # our FMU without the shim's configuration: it cannot take the GUID
    with zipfile.ZipFile(Path(fmu_dir) / "LeverCoupling.fmu") as src, zipfile.ZipFile(plain, "w") as out:
        for info in src.infolist():
            if info.filename != "resources/lever_shim.cfg":
                out.writestr(info, src.read(info))
    with pytest.raises(ValueError, match=r"^Plain\.fmu does not take configured start values"):
        configure(plain, {"stiffness": 900.0}, tmp_path / "out" / "a.fmu")
    with pytest.raises(ValueError, match="stiffness"):
        configure(Path(fmu_dir) / "LeverCoupling.fmu", {"stiffness": "stiff"}, tmp_path / "out" / "b.fmu")
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


def test_a_configured_fmu_is_written_where_the_temporary_folder_is_another_file_system(fmu_dir, tmp_path,
                                                                                       monkeypatch):
    """The copy is written beside its destination and renamed there (a rename cannot cross file
    systems): with the temporary folder on a RAM disk (/dev/shm, tmpfs) and the destination
    on disk, it is made all the same and nothing is left in either folder but the FMU."""
    shm = Path("/dev/shm")
    if not shm.is_dir() or shm.stat().st_dev == tmp_path.stat().st_dev:
        pytest.skip("no RAM disk on another file system than the tests' folder")
    elsewhere = Path(tempfile.mkdtemp(dir=shm))
    monkeypatch.setattr(tempfile, "tempdir", str(elsewhere))
    try:
        made = configure(Path(fmu_dir) / "LeverCoupling.fmu", {"stiffness": 812.5}, tmp_path / "c.fmu")
        assert list(elsewhere.iterdir()) == []
    finally:
        shutil.rmtree(elsewhere)
    assert list(tmp_path.iterdir()) == [made]
    with zipfile.ZipFile(made) as z:
        assert json.loads(z.read("resources/lever_start_values.json")) == {"stiffness": 812.5}
