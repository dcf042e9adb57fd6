"""Scenes of FMI 3.0 FMUs: ``experiment.fmi = 3`` runs our FMUs' FMI 3.0 editions
(build/fmus3) and every co-simulation master gives the FMI 2.0 editions' traces; a user's
FMI 3.0 FMU named by path runs beside FMI 2.0 ones; an FMU a master cannot use is refused
with a sentence saying what it lacks; an FMI 3.0 scene exports to SSP and runs from there.
"""
from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from harness.description import scene as scenes
from harness.engine.fmi3_component import Component3, UnsupportedFmu, open_component
from harness.engine.component import FmuCallError
from harness.engine.masters.registry import MASTERS
from harness.engine.me_component import NoModelExchange
from harness.engine.run import simulate
from harness.engine.system import CO_SIMULATION, System
from harness.formats import ssp
from harness.paths import FMUS, SCENES, fmi3_dir

STOP = 0.2

#: the stiff scene's span (1000 of its 50 us steps): every master's rollbacks, iterations,
#: rejected steps and Jacobians all happen in it, as in 0.2 s (the same rejected counts)
STIFF_STOP = 0.05


def _same_traces(fmi2, fmi3, names=None):
    """The two runs recorded the same rows (of ``names``, default all); their values differ
    by at most a few units in the last place (both editions run the same model code:
    expected bit-identical)."""
    assert fmi2.ok and fmi3.ok, (fmi2.failure, fmi3.failure)
    assert np.array_equal(fmi2.times, fmi3.times)
    if names is None:
        assert fmi2.traces.keys() == fmi3.traces.keys()
    for name in names or fmi2.traces:
        values = fmi2.traces[name]
        scale = max(1.0, float(np.max(np.abs(values))))
        assert float(np.max(np.abs(fmi3.traces[name] - values))) <= 1e-13 * scale, name


#: the co-simulation masters (the Model Exchange master integrates FMI 2.0 Model Exchange FMUs)
CO_SIMULATION_MASTERS = [name for name, cls in MASTERS.items() if cls.interface == CO_SIMULATION]


@pytest.mark.parametrize("master", CO_SIMULATION_MASTERS)
@pytest.mark.parametrize("scene_name", ["kavz685", "kavz685_stiff"])
def test_every_master_runs_the_fmi3_editions_as_the_fmi2_ones(scene_name, master):
    stop = STIFF_STOP if scene_name == "kavz685_stiff" else STOP
    scene = scenes.load(scene_name).with_overrides([f"experiment.stop={stop}"])
    fmi2 = simulate(scene, master=master)
    fmi3 = simulate(scene.with_overrides(["experiment.fmi=3"]), master=master)
    _same_traces(fmi2, fmi3)
    # the same calls, one for one: the FMI 3.0 edition is no other model
    timings = ("setup_time",)
    assert ({k: v for k, v in fmi2.counters.items() if k not in timings}
            == {k: v for k, v in fmi3.counters.items() if k not in timings})


def test_experiment_fmi_chooses_the_files_and_is_checked():
    scene = scenes.load("kavz685").with_overrides(["experiment.fmi=3"])
    system = System(scene)
    try:
        assert {type(c) for c in system.components.values()} == {Component3}
        assert {c.fmu_path.parent for c in system.components.values()} == {fmi3_dir(FMUS)}
        assert {c.description.fmiVersion for c in system.components.values()} == {"3.0"}
    finally:
        system.free()
    for bad in ("experiment.fmi=4", "experiment.fmi=true", "experiment.fmi=three"):
        with pytest.raises(scenes.SceneError, match="expected 2 or 3"):
            scenes.load("kavz685").with_overrides([bad])


def test_a_refused_fmi3_call_is_named_in_fmi3_terms_with_the_fmus_message():
    system = System(scenes.load("kavz685").with_overrides(["experiment.fmi=3"]))
    try:
        system.initialize()
        coupling = system.components["coupling"]
        with pytest.raises(FmuCallError, match=r"fmi3DoStep\(t = 0, h = -1\) returned error .*FMU said: .*step size"):
            coupling.do_step(0.0, -1.0)
        # the instance stays usable
        coupling.do_step(0.0, 1e-3)
        with pytest.raises(FmuCallError, match=r"fmi3SetFloat64\(stiffness = -1.0\)"):
            coupling.set_parameters({"stiffness": -1.0})
    finally:
        system.free()


def _copy(source: Path, out: Path, edit=None) -> Path:
    """``source`` copied to ``out``, its model description changed by ``edit`` (text -> text)."""
    if edit is None:
        shutil.copy(source, out)
        return out
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as new:
        for item in old.infolist():
            data = old.read(item.filename)
            if item.filename == "modelDescription.xml":
                changed = edit(data.decode("utf-8"))
                assert changed != data.decode("utf-8")
                data = changed.encode("utf-8")
            new.writestr(item, data)
    return out


def _scene_with_coupling(fmu: Path, tmp_path: Path) -> scenes.Scene:
    """KAVZ-685 for STOP s with its coupling the FMU file ``fmu`` (the shafts ours, FMI 2.0)."""
    text = (SCENES / "kavz685.toml").read_text()
    old = 'fmu = "LeverCoupling"'
    assert text.count(old) == 1
    path = tmp_path / "user.toml"
    path.write_text(text.replace(old, f'fmu = "{fmu.name}"'))
    return scenes.load(path).with_overrides([f"experiment.stop={STOP}"])


@pytest.mark.parametrize("master", ["gauss-seidel", "implicit-newton", "adaptive"])
def test_a_users_fmi3_fmu_by_path_runs_beside_fmi2_ones(tmp_path, master):
    user = _copy(fmi3_dir(FMUS) / "LeverCoupling.fmu", tmp_path / "UserCoupling.fmu")
    scene = _scene_with_coupling(user, tmp_path)
    system = System(scene)
    try:
        kinds = {n: (type(c).__name__, c.description.fmiVersion) for n, c in system.components.items()}
    finally:
        system.free()
    assert kinds == {"engine": ("Component", "2.0"), "coupling": ("Component3", "3.0"), "load": ("Component", "2.0")}
    # a coupling not ours (another name) is no driveline the harness knows: it records
    # the scene's list only, without the energy balance's variables
    user = simulate(scene, master=master)
    assert set(user.traces) == set(scene.record)
    _same_traces(simulate(scenes.load("kavz685").with_overrides([f"experiment.stop={STOP}"]), master=master),
                 user, scene.record)


def test_a_master_that_rolls_back_refuses_an_fmu_without_fmu_states(tmp_path):
    shafts = tmp_path / "shafts"
    shafts.mkdir()
    for name in ("EngineShaft", "LoadShaft"):
        _copy(fmi3_dir(FMUS) / f"{name}.fmu", shafts / f"{name}.fmu",
              lambda text: text.replace('canGetAndSetFMUState="true"', 'canGetAndSetFMUState="false"', 1)
              .replace('canSerializeFMUState="true"', 'canSerializeFMUState="false"', 1))
    text = (SCENES / "kavz685.toml").read_text()
    for name in ("EngineShaft", "LoadShaft"):
        text = text.replace(f'fmu = "{name}"', f'fmu = "shafts/{name}.fmu"')
    path = tmp_path / "stateless.toml"
    path.write_text(text)
    scene = scenes.load(path).with_overrides([f"experiment.stop={STOP}", "experiment.fmi=3"])
    for master in ("implicit-newton", "adaptive"):
        result = simulate(scene, master=master)
        assert not result.ok
        assert "canGetAndSetFMUstate = false" in result.failure and "engine (EngineShaft.fmu, FMI 3.0)" in \
            result.failure, result.failure
    # the explicit masters need no FMU states (jacobi-linear falls back to not rolling back)
    for master in ("jacobi", "jacobi-linear"):
        assert simulate(scene, master=master).ok


def test_an_fmu_without_co_simulation_is_refused_by_name(tmp_path):
    def model_exchange_only(text):
        start = text.index("<CoSimulation")
        return text[:start] + text[text.index("/>", start) + 2:]

    fmu = _copy(fmi3_dir(FMUS) / "LeverCoupling.fmu", tmp_path / "MeOnly.fmu", model_exchange_only)
    assert read_model_description(str(fmu)).coSimulation is None
    with pytest.raises(UnsupportedFmu, match=r"coupling: MeOnly.fmu \(FMI 3.0\) has no Co-Simulation interface"):
        open_component("coupling", fmu)


def test_an_fmi3_scene_exports_to_ssp_with_its_fmi3_fmus_and_runs_from_it(tmp_path):
    scene = scenes.load("kavz685").with_overrides([f"experiment.stop={STOP}", "experiment.fmi=3"])
    archive = ssp.export(scene, tmp_path / "k3.ssp")
    with zipfile.ZipFile(archive) as z:
        versions = {name: read_model_description(z.open(name)) for name in z.namelist() if name.endswith(".fmu")}
        ssd = z.read("SystemStructure.ssd").decode("utf-8")
    assert {n: md.fmiVersion for n, md in versions.items()} == {
        f"resources/{n}.fmu": "3.0" for n in ("EngineShaft", "LeverCoupling", "LoadShaft")}
    # SSP 1.0 connectors: an FMI 3.0 Float64 is declared as the Real it carries
    assert "<ssc:Real" in ssd and "Float64" not in ssd
    loaded = ssp.read_scene(archive)
    _same_traces(simulate(scene, master="jacobi"), simulate(loaded, master="jacobi"))


def test_the_model_exchange_master_refuses_fmi3_fmus_by_name():
    scene = scenes.load("kavz685").with_overrides([f"experiment.stop={STOP}", "experiment.fmi=3"])
    with pytest.raises(NoModelExchange, match=r"component 'engine' \(FMU EngineShaft\) is FMI 3\.0.*FMI 2\.0 Model Exchange"):
        simulate(scene, master="me-cvode")
