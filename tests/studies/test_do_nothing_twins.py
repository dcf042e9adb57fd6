"""The do-nothing twins cross by the path of the FMU they stand for
(harness.studies.bench.do_nothing_twins): behind our native entry and its channel, a twin's
calls enter Python exactly where ours do; an FMU without our entry gets a plain pythonfmu twin.
Checked by counting the Python frames each FMI call runs inside the FMU (``sys.setprofile``:
pythonfmu calls the model on the host's thread), independent of any timing."""
from __future__ import annotations

import sys
import zipfile
from pathlib import Path

import fmpy
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from harness.studies.bench import do_nothing_twins

#: the Python a call runs before it reaches the FMU: fmpy's and this file's
HOST_SIDE = (str(Path(fmpy.__file__).parent), __file__)


class Instance:
    """An FMI 2.0 co-simulation instance of ``fmu``, initialised, whose calls report whether
    they ran Python code of the FMU (``entered``)."""

    def __init__(self, fmu: Path, folder: Path):
        description = read_model_description(str(fmu))
        self.unzipped = str(extract(str(fmu), unzipdir=str(folder)))
        self.vr = {v.name: v.valueReference for v in description.modelVariables}
        self.slave = FMU2Slave(guid=description.guid, unzipDirectory=self.unzipped,
                               modelIdentifier=description.coSimulation.modelIdentifier, instanceName="probe")
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        self.t = 0.0

    def entered(self, call) -> bool:
        inside = []

        def profile(frame, event, arg):
            # any Python below fmpy's own is the FMU's (its module may have been loaded from
            # another copy of the same FMU: one process shares its package by name)
            if event == "call" and not frame.f_code.co_filename.startswith(HOST_SIDE):
                inside.append(frame.f_code.co_name)
        sys.setprofile(profile)
        try:
            call()
        finally:
            sys.setprofile(None)
        return bool(inside)

    def set(self, values: dict) -> bool:
        return self.entered(lambda: self.slave.setReal([self.vr[n] for n in values], list(values.values())))

    def get(self, names) -> bool:
        return self.entered(lambda: self.slave.getReal([self.vr[n] for n in names]))

    def step(self, h=1e-3) -> bool:
        entered = self.entered(lambda: self.slave.doStep(self.t, h))
        self.t += h
        return entered

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


def _calls(instance: Instance, inputs: dict, outputs: list, judged: dict) -> list[bool]:
    """Whether each call of a master's step pattern entered Python: a step, a read of the
    outputs it left, a set of inputs in range, the read after it, another set, a step, a
    read, and a set of an input the model judges itself."""
    pattern = [instance.step(), instance.get(outputs), instance.set(inputs), instance.get(outputs),
               instance.set(inputs), instance.step(), instance.get(outputs)]
    if judged:
        pattern.append(instance.set(judged))
    return pattern


# A shaft (states: a step leaves its outputs in the entry) and the coupling (no states: its
# outputs follow the inputs; its misalignment is judged by the model, never kept in the entry)
CASES = {"LoadShaft": ({"tau": 12.0, "tau_rate": 0.5}, ["phi", "w", "a"], {},
                       [True, False, False, True, False, True, False]),
         "LeverCoupling": ({"phi1": 0.1, "w1": 1.0}, ["tau1", "tau2"], {"misalignment": 0.01},
                           [True, True, False, True, False, True, True, True])}


@pytest.mark.parametrize("model", CASES)
def test_the_twin_of_our_fmu_enters_python_where_ours_does(tmp_path, fmu_dir, model):
    inputs, outputs, judged, by_hand = CASES[model]
    twin = do_nothing_twins.build_twin(fmu_dir / f"{model}.fmu", tmp_path / f"{model}.fmu")
    with zipfile.ZipFile(twin) as archive:
        assert "channel=1" in archive.read(do_nothing_twins.ENTRY_CONFIG).decode().splitlines()
    patterns = {}
    for name, fmu in (("ours", fmu_dir / f"{model}.fmu"), ("twin", twin)):
        instance = Instance(fmu, tmp_path / name)
        try:
            patterns[name] = _calls(instance, inputs, outputs, judged)
        finally:
            instance.free()
    # by hand: a set of inputs in range waits in the entry; a read after a shaft's step is
    # answered there until another call; the step enters Python (and takes the inputs kept)
    assert patterns["ours"] == by_hand
    assert patterns["twin"] == patterns["ours"]


def _without_our_entry(fmu: Path, dest: Path) -> Path:
    """``fmu`` as the plain pythonfmu FMU it was before our native entry was put in front:
    pythonfmu's library under the model's name, no entry configuration."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w") as out:
        model = read_model_description(str(fmu)).coSimulation.modelIdentifier
        entry = f"{do_nothing_twins.PLATFORM_DIR}/{model}.so"
        inner = f"{do_nothing_twins.PLATFORM_DIR}/pythonfmu-export.so"
        for info in src.infolist():
            if info.filename in (entry, do_nothing_twins.ENTRY_CONFIG):
                continue
            out.writestr(entry if info.filename == inner else info.filename, src.read(info))
    return dest


def test_an_fmu_without_our_entry_gets_a_plain_pythonfmu_twin(tmp_path, fmu_dir):
    """A user's pythonfmu FMU (here: the load shaft without our entry) is priced by its own
    path: its twin has no entry of ours, and every call enters Python, as the FMU's do."""
    foreign = _without_our_entry(fmu_dir / "LoadShaft.fmu", tmp_path / "LoadShaft.fmu")
    assert do_nothing_twins.entry_of(foreign) is None and do_nothing_twins.entry_of(fmu_dir / "LoadShaft.fmu")
    twin = do_nothing_twins.build_twin(foreign, tmp_path / "twin" / "LoadShaft.fmu")
    with zipfile.ZipFile(twin) as archive:
        assert do_nothing_twins.ENTRY_CONFIG not in archive.namelist()
    inputs, outputs, judged, _ = CASES["LoadShaft"]
    for k, fmu in enumerate((foreign, twin)):
        instance = Instance(fmu, tmp_path / f"unzipped{k}")
        try:
            assert _calls(instance, inputs, outputs, judged) == [True] * 7
        finally:
            instance.free()


def test_the_twin_declares_to_the_entry_what_the_model_declares(fmu_dir):
    """What the survey reads from each model, by hand from the models' declarations: the
    shaft keeps its three torque inputs and publishes all five outputs (it has states); the
    coupling keeps the four motions and publishes nothing (no states), its misalignment
    judged by the model; the misalignment source keeps and publishes nothing."""
    shaft = do_nothing_twins.survey(fmu_dir / "LoadShaft.fmu")
    assert [name for name, *_ in shaft["deferred"]] == ["tau", "tau_rate", "tau_accel"]
    assert shaft["block_outputs"] == ["phi", "w", "a", "load_torque", "load_work"] and shaft["states"] == 3
    coupling = do_nothing_twins.survey(fmu_dir / "LeverCoupling.fmu")
    assert [name for name, *_ in coupling["deferred"]] == ["phi1", "w1", "phi2", "w2"]
    assert coupling["block_outputs"] == [] and coupling["states"] == 0
    source = do_nothing_twins.survey(fmu_dir / "MisalignmentSource.fmu")
    assert source["deferred"] == [] and source["block_outputs"] == []


def _edited(fmu: Path, dest: Path, member_ending: str, edit) -> Path:
    """A copy of ``fmu`` with the member whose name ends in ``member_ending`` edited."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w") as out:
        for info in src.infolist():
            data = src.read(info)
            out.writestr(info, edit(data) if info.filename.endswith(member_ending) else data)
    return dest


def test_the_twins_key_changes_with_the_entry_and_the_channels_code(tmp_path, fmu_dir):
    """A twin answers as the FMU's entry and channel code do: another entry library, other
    channel code or an entry that no longer speaks the channel is another twin."""
    ours = fmu_dir / "LoadShaft.fmu"
    keys = {do_nothing_twins.twin_key(ours),
            do_nothing_twins.twin_key(_edited(ours, tmp_path / "a.fmu", "/me_channel.py", lambda b: b + b"\n# x\n")),
            do_nothing_twins.twin_key(_edited(ours, tmp_path / "b.fmu", "linux64/LoadShaft.so", lambda b: b + b"\0")),
            do_nothing_twins.twin_key(_edited(ours, tmp_path / "c.fmu", "lever_shim.cfg",
                                              lambda b: b.replace(b"channel=1", b"channel=0")))}
    assert len(keys) == 4
    assert do_nothing_twins.twin_key(_edited(ours, tmp_path / "d.fmu", "documentation/_main.html",
                                             lambda b: b + b" ")) == do_nothing_twins.twin_key(ours)
