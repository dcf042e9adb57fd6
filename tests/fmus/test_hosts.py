"""Our FMUs in the C++ engine ecos (PyPI ecospy, its command-line program), in a bare
environment (PATH=/usr/bin:/bin; only ecos's own libtbb is pointed to): each FMU alone, and
the KAVZ-685 scene from our SSP export judged by `lever validate --result`; and the
`lever hosts` command that times the hosts."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from harness.description import scene
from harness.engine import run
from harness.formats import ssp
from harness.peers import ecos
from harness.studies import hosts

#: what each FMU alone records (its outputs), with its default parameters and inputs
ALONE = {"EngineShaft": ["w", "phi", "engine_torque"], "LoadShaft": ["w", "phi", "load_torque"],
         "LeverCoupling": ["tau1", "tau2", "U12"], "MisalignmentSource": ["misalignment"]}


@pytest.fixture(scope="module")
def ecos_bin(tmp_path_factory):
    path = tmp_path_factory.mktemp("ecos")
    ecos.ecos_program(path)     # EcosUnavailable fails the tests: ecospy and tbb are test dependencies
    return path


@pytest.mark.parametrize("fmu", list(ALONE))
def test_ecos_runs_each_fmu_alone_in_a_bare_environment(fmu, fmu_dir, ecos_bin, tmp_path):
    import shutil

    target = tmp_path / f"{fmu}.fmu"
    shutil.copy(fmu_dir / f"{fmu}.fmu", target)
    result = ecos.run_ecos(target, 0.2, 1e-3, ecos_bin)
    times, traces = ecos.ecos_traces(result.csv)
    name = fmu.lower()
    spec = scene.Scene(name=f"{name}_alone", description=f"{fmu} alone",
                       components={name: scene.ComponentSpec(fmu, {})}, connections=[],
                       experiment=scene.Experiment(stop=0.2, step=1e-3, master="jacobi", transient=0.0),
                       record=[f"{name}.{v}" for v in ALONE[fmu]], features=set())
    ours = run.simulate(spec, "jacobi", 1e-3, fmu_dir)
    assert ours.ok, ours.failure
    assert times[-1] == pytest.approx(0.2, abs=1e-9)
    for variable in ALONE[fmu]:
        theirs = traces[f"instance.{variable}"]          # ecos names a lone FMU's instance so
        expected = np.interp(times, ours.times, ours.traces[f"{name}.{variable}"])
        # ecos writes six decimals
        assert np.allclose(theirs, expected, rtol=1e-6, atol=1e-6), (fmu, variable)


#: the step at which ecos's result of KAVZ-685 passes the default verdict (docs/hosts.md): ecos
#: couples one step behind our masters, so its ripple's excess falls with the step (engine.a's
#: amplitude +10.6 % at 1 ms, +2.5 % at 0.25 ms, +1.05 % at 0.1 ms against 2 % allowed)
ECOS_STEP = 1e-4


@pytest.mark.parametrize("fmi", [2, 3])
def test_the_kavz685_scene_in_ecos_passes_lever_validate_at_its_stated_step(fmi, lever, fmu_dir, ecos_bin, tmp_path):
    """The scene from our SSP export, with the FMI 2.0 FMUs or the FMI 3.0 editions (the
    export of ``experiment.fmi = 3`` carries those), in a bare environment: over the whole 10 s
    at the scene's 1 ms the default verdict names the larger ripple (FMI 2.0 only: ecos's FMI
    3.0 run gives the same traces, tests/formats/test_peers.py); at ``ECOS_STEP`` it passes,
    judged over the start-up and 2 s of the steady window (11 revolutions: a tenth of the
    steps of the whole span at that step, whose cost is ecos's)."""
    for step, verdict in ((None, "FAIL"), (ECOS_STEP, "PASS"))[fmi - 2:]:
        stop = ["experiment.stop=4"] if step else []
        spec = scene.load("kavz685").with_overrides([f"experiment.fmi={fmi}"] + stop
                                                    + ([f"experiment.step={step}"] if step else []))
        archive = ssp.export(spec, tmp_path / "kavz685.ssp", fmu_dir)
        result = ecos.run_ecos(archive, spec.experiment.stop, spec.experiment.step, ecos_bin, record=list(spec.record))
        assert ("Loading FMI version 3" in result.log) == (fmi == 3)     # ecos says so of FMI 3.0 FMUs only
        times, traces = ecos.ecos_traces(result.csv)
        assert times[-1] == pytest.approx(spec.experiment.stop, abs=1e-9)
        assert len(times) == round(spec.experiment.stop / spec.experiment.step) + 1
        assert sorted(traces) == sorted(spec.record)          # ecos logged what its CSV configuration names
        names = list(spec.record)
        csv_path = hosts.write_result_csv(tmp_path / f"ecos-{verdict}.csv", times, traces, names)
        outcome = lever("validate", "--result", str(csv_path), "kavz685", "--out", str(tmp_path / verdict),
                        "--window", f"0:{spec.experiment.stop:g}", "--no-plots")
        assert f"kavz685: {verdict}" in outcome.output, outcome.output
        if verdict == "FAIL":
            assert "coupling.tau2: amplitude" in outcome.output and "engine.a: amplitude" in outcome.output, outcome.output
        assert outcome.exit_code == (verdict == "FAIL"), outcome.output


def test_ecos_applies_the_exported_parameter_values(fmu_dir, ecos_bin, tmp_path):
    """Values that differ from the FMUs' defaults reach the FMUs in ecos: every component's
    parameter set in the export has one name, which ecos is told to apply (it applied none
    while each set was named after its component: the KAVZ-685 run above passed only while
    every value it set was a default)."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.3", "experiment.transient=0.1",
                                                 "load.mean_torque=200", "load.random_amplitude=0"])
    archive = ssp.export(spec, tmp_path / "k.ssp", fmu_dir)
    result = ecos.run_ecos(archive, 0.3, 1e-3, ecos_bin, record=["load.load_torque"])
    _, traces = ecos.ecos_traces(result.csv)
    assert np.allclose(traces["load.load_torque"], 200.0, rtol=0, atol=1e-9), \
        "ecos ignored the SSP parameter set: the load torque is not the exported mean_torque = 200 N*m"


def test_ecos_makes_every_step_to_the_stop_time(fmu_dir, ecos_bin, tmp_path):
    """ecos adds the step to its time and stops when the next step would pass the stop
    time: 0.001 added 199 times is a hair above 0.199, so told to stop at 0.2 s it made 199
    steps.  It must make the scene's 200, ending at 0.2 s, as the benchmark's peer check
    demands."""
    import shutil

    target = tmp_path / "EngineShaft.fmu"
    shutil.copy(fmu_dir / "EngineShaft.fmu", target)
    times, _ = ecos.ecos_traces(ecos.run_ecos(target, 0.2, 1e-3, ecos_bin).csv)
    assert len(times) == 201 and times[-1] == pytest.approx(0.2, abs=1e-9), (len(times), times[-1])


def test_ecos_leaves_nothing_in_the_temporary_directory(fmu_dir, ecos_bin, tmp_path, monkeypatch):
    """ecos unpacks an SSP archive under TMPDIR and does not remove it: a run gets a
    directory of ours for that, gone when it ends."""
    import os

    temporary = tmp_path / "tmp"
    temporary.mkdir()
    monkeypatch.setenv("TMPDIR", str(temporary))
    monkeypatch.setattr("tempfile.tempdir", None)      # tempfile reads TMPDIR again
    spec = scene.load("kavz685")
    archive = ssp.export(spec, tmp_path / "kavz685.ssp", fmu_dir)
    env = {**ecos.BARE_ENVIRONMENT, "TMPDIR": str(temporary)}
    ecos.run_ecos(archive, 0.01, 1e-3, ecos_bin, env=env, record=["load.w"])
    assert os.listdir(temporary) == []


def test_ecos_says_what_failed(tmp_path, ecos_bin):
    with pytest.raises(RuntimeError, match="ecos failed"):
        ecos.run_ecos(tmp_path / "missing.ssp", 0.1, 1e-3, ecos_bin)


def test_lever_hosts_writes_the_table(lever, tmp_path, fmu_dir):
    result = lever("hosts", "--repeats", "1", "--set", "experiment.stop=0.05",
                                      "--set", "experiment.transient=0.01", "--out", str(tmp_path))
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "hosts.json").read_text())
    assert list(report["hosts"]) == list(hosts.HOSTS)
    assert report["hosts"]["harness-jacobi"]["ratio"] == 1.0
    assert all(row["median_s"] > 0 for row in report["hosts"].values())
    assert "| ecos |" in (tmp_path / "hosts.md").read_text()
    bad = lever("hosts", "--host", "simulink")
    assert bad.exit_code != 0 and "unknown host simulink" in bad.output


def test_lever_hosts_refuses_the_hosts_that_cannot_run_an_fmi3_scene_before_anything_runs(lever, fmu_dir, tmp_path):
    """libcosim runs no FMI 3.0 FMU and the C importer's timing loop is FMI 2.0's: each says
    so, before anything runs or is written; the others run the FMI 3.0 editions."""
    refused = lever("hosts", "--set", "experiment.fmi=3", "--out", str(tmp_path / "h"))
    assert refused.exit_code == 2 and not (tmp_path / "h").exists(), refused.output
    assert "peer 'libcosim-fixed' runs FMI 2.0 FMUs" in refused.output
    assert "host c-importer times the FMI 2.0 editions' stepping loop only" in refused.output
    assert hosts.problems(scene.load("kavz685").with_overrides(["experiment.fmi=3"]),
                          ("harness-jacobi", "ecos", "ecos-serial"), fmu_dir) == []
    assert hosts.problems(scene.load("kavz685"), hosts.HOSTS, fmu_dir) == []


def test_ecos_couples_as_libcosim_does_one_step_behind_our_jacobi(fmu_dir, ecos_bin, tmp_path):
    """What docs/hosts.md says of ecos's coupling, measured: its shafts move as libcosim's do
    (to ecos's six decimals), both giving the shafts the coupling torque of the states one
    step older than our jacobi does; ecos logs the torque of the new states, libcosim the
    torque the shafts were given (ecos's row k is libcosim's row k + 1)."""
    from harness import peers

    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.1", "experiment.transient=0.02"])
    archive = ssp.export(spec, tmp_path / "k.ssp", fmu_dir)
    times, traces = ecos.ecos_traces(ecos.run_ecos(archive, 0.1, 1e-3, ecos_bin, record=list(spec.record)).csv)
    libcosim = peers.simulate_peer("libcosim-fixed", spec, 1e-3, fmu_dir)
    ours = run.simulate(spec, "jacobi", 1e-3, fmu_dir)
    assert len(times) == len(libcosim.times) == len(ours.times) == 101
    for shaft in ("engine.w", "load.w"):
        assert np.allclose(traces[shaft], libcosim.traces[shaft], rtol=0, atol=2e-6)
        assert not np.allclose(traces[shaft], ours.traces[shaft], rtol=0, atol=1e-3)
    assert np.allclose(traces["coupling.tau1"][:-1], libcosim.traces["coupling.tau1"][1:], rtol=0, atol=2e-6)
    # the first step is the same in all three; from the second on, the lag shows
    assert traces["coupling.tau1"][1] == pytest.approx(ours.traces["coupling.tau1"][1], abs=1e-5)
    assert abs(traces["coupling.tau1"][2] - ours.traces["coupling.tau1"][2]) > 0.1


# -- the FMI 3.0 editions ---------------------------------------------------------------------------

#: what each FMI 3.0 edition alone records in ecos: ALONE, and the rectifier's speeds
ALONE_FMI3 = {**ALONE, "FreewheelRectifier": ["half_coupling_speed", "driven_speed", "driven_acceleration"]}


@pytest.mark.parametrize("fmu", list(ALONE_FMI3))
def test_ecos_runs_each_fmi3_edition_alone_as_the_fmi2_edition(fmu, fmu_dir, ecos_bin, tmp_path):
    """ecos's FMI 3.0 co-simulation (it loads the edition by its fmiVersion) in a bare
    environment: the same six decimals as the FMI 2.0 edition in ecos, which matches our
    harness (the test above).  ecos logs what it is told to (the outputs); logging every
    variable: the test below."""
    import shutil

    from harness.studies.me_hosts import fmi3_dir

    record = [f"instance.{v}" for v in ALONE_FMI3[fmu]]
    runs = {}
    for edition, folder in (("fmi2", fmu_dir), ("fmi3", fmi3_dir(fmu_dir))):
        (tmp_path / edition).mkdir()
        target = shutil.copy(folder / f"{fmu}.fmu", tmp_path / edition / f"{fmu}.fmu")
        run3 = ecos.run_ecos(Path(target), 0.2, 1e-3, ecos_bin, record=record)
        runs[edition] = ecos.ecos_traces(run3.csv)
    assert "Loading FMI version 3" in run3.log
    (t2, traces2), (t3, traces3) = runs["fmi2"], runs["fmi3"]
    assert len(t3) == 201 and np.array_equal(t2, t3)
    assert sorted(traces3) == sorted(record)
    for name in record:
        assert np.array_equal(traces3[name], traces2[name]), name


@pytest.mark.parametrize("fmu", ["EngineShaft", "LoadShaft", "FreewheelRectifier"])
def test_ecos_logging_every_variable_of_an_fmi3_edition_logs_its_event_indicators(fmu, fmu_dir, ecos_bin, tmp_path):
    """ecos's default log reads every Float64 in one call, the event indicators with them
    (a Co-Simulation importer may read any variable): every column the FMI 2.0 edition's log
    has is equal, and the indicators are the values fmpy reads from the FMI 3.0 edition at
    the same points (to the six decimals ecos prints)."""
    import shutil

    import fmpy
    from fmpy.fmi3 import FMU3Slave

    from harness.studies.me_hosts import fmi3_dir

    runs = {}
    for edition, folder in (("fmi2", fmu_dir), ("fmi3", fmi3_dir(fmu_dir))):
        (tmp_path / edition).mkdir()
        target = shutil.copy(folder / f"{fmu}.fmu", tmp_path / edition / f"{fmu}.fmu")
        runs[edition] = ecos.ecos_traces(ecos.run_ecos(Path(target), 0.2, 1e-3, ecos_bin).csv)
    (t2, traces2), (t3, traces3) = runs["fmi2"], runs["fmi3"]
    assert len(t3) == 201 and np.array_equal(t2, t3)
    assert set(traces2) < set(traces3)
    for name in traces2:
        assert np.array_equal(traces3[name], traces2[name]), name

    path = fmi3_dir(fmu_dir) / f"{fmu}.fmu"
    md = fmpy.read_model_description(str(path))
    indicators = [v for v in md.modelVariables if v.name.startswith("event_indicator_")]
    assert indicators and all(f"instance.{v.name}" in traces3 for v in indicators)
    slave = FMU3Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path), unzipdir=str(tmp_path / "x")),
                      modelIdentifier=fmu, instanceName="instance")
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    read = [slave.getFloat64([v.valueReference for v in indicators])]
    for k in range(200):
        slave.doStep(k * 1e-3, 1e-3)
        read.append(slave.getFloat64([v.valueReference for v in indicators]))
    slave.terminate()
    slave.freeInstance()
    for k, v in enumerate(indicators):
        assert np.allclose(traces3[f"instance.{v.name}"], [row[k] for row in read], rtol=0, atol=1e-6), v.name


def test_ecos_runs_the_fmi3_misalignment_source_to_its_reference(lever, fmu_dir, ecos_bin, tmp_path):
    """The one stand-alone reference without inputs (a lone FMU in ecos takes no inputs):
    the FMI 3.0 source over its reference's span, judged by ``lever validate --result``."""
    import shutil

    from harness.formats import reference_traces
    from harness.studies.me_hosts import fmi3_dir, write_result

    ref = reference_traces.read("MisalignmentSource")
    assert ref.inputs is None
    target = Path(shutil.copy(fmi3_dir(fmu_dir) / "MisalignmentSource.fmu", tmp_path / "MisalignmentSource.fmu"))
    signals = list(ref.outputs.signals)
    run3 = ecos.run_ecos(target, ref.opt.stop, ref.opt.step, ecos_bin, record=[f"instance.{s}" for s in signals])
    times, traces = ecos.ecos_traces(run3.csv)
    assert times[-1] == pytest.approx(ref.opt.stop, abs=1e-9)
    csv_path = write_result(tmp_path / "ecos3.csv", times, {s: traces[f"instance.{s}"] for s in signals})
    outcome = lever("validate", "--result", str(csv_path), "MisalignmentSource", "--out", str(tmp_path / "v"))
    assert outcome.exit_code == 0 and "MisalignmentSource: PASS" in outcome.output, outcome.output
