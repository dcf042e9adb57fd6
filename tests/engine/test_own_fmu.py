"""Bring your own FMU: a scene mixes our FMUs with one that is not ours - TorqueMonitor,
a minimal FMI 2.0 co-simulation FMU in C (tests/engine/foreign_fmu), built here with the
machine's C compiler, with a Real input and Real, String and Enumeration outputs - named
by path.  It runs in `lever run`, exports to SSP (the FMU copied in, a source the archive
resolves, connectors only for what SSP readers take), and that archive runs in `lever
run`, in libcosim and in fmpy.ssp.  The default transient follows a short scene."""
from __future__ import annotations

import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from harness.description import scene as scenes
from harness.engine import traces as trace_files
from harness.engine.run import simulate
from harness.formats import ssp
from harness.paths import SCENES

sys.path.insert(0, str(Path(__file__).parent / "foreign_fmu"))
import build as foreign  # noqa: E402

DRIVELINE = ["engine.w", "load.w", "coupling.tau1", "coupling.tau2"]


@pytest.fixture(scope="module")
def monitor_fmu(tmp_path_factory) -> Path:
    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler")
    return foreign.build(tmp_path_factory.mktemp("foreign"))


def _monitored_scene_text(fmu: str) -> str:
    """KAVZ-685 for 1.5 s, no transient stated, with the monitor reading coupling.tau1."""
    text = (SCENES / "kavz685.toml").read_text()
    for old, new in (('name = "kavz685"', 'name = "kavz685_monitored"'), ("transient = 2.0\n", ""),
                     ("stop = 10.0", "stop = 1.5"),
                     ('"coupling.tau2 -> load.tau",\n]', '"coupling.tau2 -> load.tau",\n    "coupling.tau1 -> monitor.torque",\n]'),
                     ('"load.load_torque",\n]', '"load.load_torque", "monitor.peak",\n]')):
        assert old in text, old
        text = text.replace(old, new)
    return text + f'\n[components.monitor]\nfmu = "{fmu}"\n[components.monitor.parameters]\nlimit = 120.0\n'


@pytest.fixture(scope="module")
def monitored(monitor_fmu) -> Path:
    """The scene file beside the FMU, naming it relative to itself."""
    path = monitor_fmu.parent / "monitored.toml"
    path.write_text(_monitored_scene_text("TorqueMonitor.fmu"))
    return path


def test_an_fmu_by_path_relative_or_absolute(lever, monitored, monitor_fmu, tmp_path):
    spec = scenes.load(monitored)
    assert spec.components["monitor"].fmu == str(monitor_fmu.resolve())
    elsewhere = tmp_path / "elsewhere.toml"
    elsewhere.write_text(_monitored_scene_text(str(monitor_fmu.resolve())))
    assert scenes.load(elsewhere).components == spec.components
    # a variant in another folder inherits the path as its base resolved it
    variant = tmp_path / "variant.toml"
    variant.write_text(f'extends = "{monitored}"\nname = "v"\n')
    assert scenes.load(variant).components["monitor"].fmu == str(monitor_fmu.resolve())
    # a missing file is named as such, exit 2
    missing = tmp_path / "missing.toml"
    missing.write_text(_monitored_scene_text("NoSuch.fmu"))
    result = lever("run", str(missing), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2 and f"no FMU file {tmp_path / 'NoSuch.fmu'}" in result.output
    # the extension in any case names a file, as `lever validate` takes it
    missing.write_text(_monitored_scene_text("NoSuch.FMU"))
    result = lever("run", str(missing), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2 and f"no FMU file {tmp_path / 'NoSuch.FMU'}" in result.output


def test_the_default_transient_follows_the_length():
    assert scenes.Experiment(stop=1.5).transient == pytest.approx(0.3)
    assert scenes.Experiment(stop=10.0).transient == 2.0 and scenes.Experiment(stop=60.0).transient == 2.0
    spec = scenes.Scene("s", "", {}, [], scenes.Experiment(stop=1.0), [], set())
    assert spec.with_overrides(["experiment.stop=30"]).experiment.transient == 2.0
    assert spec.with_overrides(["experiment.stop=0.5"]).experiment.transient == pytest.approx(0.1)
    assert spec.with_overrides(["experiment.stop=0.5", "experiment.transient=0"]).experiment.transient == 0.0
    # a transient the scene states stays what it says
    assert scenes.load("kavz685").with_overrides(["experiment.stop=30"]).experiment.transient == 2.0


def test_the_mixed_scene_runs_and_the_driveline_is_untouched(lever, monitored, tmp_path, fmu_dir):
    out = tmp_path / "run"
    result = lever("run", str(monitored), "--no-plots", "--out", str(out))
    assert result.exit_code == 0, result.output
    import json
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] and summary["transient_s"] == pytest.approx(0.3)     # 1.5 s: not refused
    times, traces = trace_files.read(out / "traces.csv")
    # the monitor saw the coupling's torque: its peak is the largest |tau1| (119.34 N*m
    # against 119.35: jacobi-quadratic feeds inputs extrapolated over the step, 5e-5 apart)
    assert traces["monitor.peak"][-1] == pytest.approx(np.max(np.abs(traces["coupling.tau1"])), rel=2e-4)
    # the same driveline, bit for bit, as without the monitor
    plain = simulate(scenes.load("kavz685").with_overrides(["experiment.stop=1.5", "experiment.transient=0.3"]))
    for name in DRIVELINE:
        assert np.array_equal(traces[name], plain.traces[name]), name


def test_export_copies_the_fmu_and_writes_only_connectors_ssp_readers_take(lever, monitored, monitor_fmu, tmp_path):
    archive = tmp_path / "monitored.ssp"
    result = lever("export-ssp", str(monitored), "--out", str(archive))
    assert result.exit_code == 0, result.output
    with zipfile.ZipFile(archive) as z:
        assert z.read("resources/TorqueMonitor.fmu") == monitor_fmu.read_bytes()
        root = ET.fromstring(z.read("SystemStructure.ssd"))
        names = set(z.namelist())
    components = {c.get("name"): c for c in root.iter(f"{{{ssp.SSD}}}Component")}
    assert all(c.get("source") in names for c in components.values())          # every source resolves
    assert components["monitor"].get("source") == "resources/TorqueMonitor.fmu"
    connectors = {c.get("name"): (c.get("kind"), c[0].tag.rsplit("}", 1)[1])
                  for c in components["monitor"].iter(f"{{{ssp.SSD}}}Connector")}
    # no String (status) or Enumeration (level) connector
    assert connectors == {"torque": ("input", "Real"), "peak": ("output", "Real")}
    kinds = {c[0].tag.rsplit("}", 1)[1] for c in root.iter(f"{{{ssp.SSD}}}Connector")}
    assert kinds <= set(ssp.CONNECTOR_TYPES)


@pytest.fixture(scope="module")
def archive(monitored, tmp_path_factory, fmu_dir) -> Path:
    path = tmp_path_factory.mktemp("archive") / "monitored.ssp"
    return ssp.export(scenes.load(monitored), path, fmu_dir)


def test_the_archive_runs_in_lever_run(lever, archive, tmp_path, monitored):
    out = tmp_path / "from_ssp"
    result = lever("run", str(archive), "--out", str(out), "--no-reference", "--no-plots")
    assert result.exit_code == 0, result.output
    _, from_archive = trace_files.read(out / "traces.csv")
    direct = simulate(scenes.load(monitored))
    for name in DRIVELINE + ["monitor.peak"]:
        assert np.array_equal(from_archive[name], direct.traces[name]), name


LIBCOSIM = """
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
log_output_level(CosimLogLevel.ERROR)
execution = CosimExecution.from_ssp_file(sys.argv[1], 1_000_000)
observer = CosimObserver.create_last_value()
execution.add_observer(observer)
monitor = execution.slave_index_from_instance_name("monitor")
coupling = execution.slave_index_from_instance_name("coupling")
tau1_ref = int(sys.argv[2])
largest = 0.0
for _ in range(1500):
    largest = max(largest, abs(observer.last_real_values(coupling, [tau1_ref])[0]))
    assert execution.step()
print(execution.status().current_time, observer.last_real_values(monitor, [2])[0], largest)
"""


def _tau1_reference(archive) -> int:
    from fmpy import read_model_description
    back = ssp.read_scene(archive)
    md = read_model_description(str(back.fmu_dir / "LeverCoupling.fmu"))
    return next(v.valueReference for v in md.modelVariables if v.name == "tau1")


def _ours(archive) -> float:
    back = ssp.read_scene(archive)
    return simulate(back, fmu_dir=back.fmu_dir).traces["monitor.peak"][-1]


def test_the_archive_runs_in_libcosim(archive, tmp_path):
    # its own process, as harness.peers runs libcosim (an abort would end it)
    done = subprocess.run([sys.executable, "-c", LIBCOSIM, str(archive), str(_tau1_reference(archive))],
                          capture_output=True, text=True, timeout=300,
                          env={**__import__("os").environ, "TMPDIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr[-2000:]
    end_ns, peak, largest = done.stdout.split()
    assert int(end_ns) == 1_500_000_000
    # the monitor saw libcosim's coupling torque: its peak is the largest |tau1| it was fed
    assert float(peak) == pytest.approx(float(largest), rel=1e-12)
    # libcosim holds inputs over a step (our jacobi-quadratic ramps them): the start-up
    # peak differs, 121.92 against 119.36 N*m measured (2.1 %); bound 5 %
    assert float(peak) == pytest.approx(_ours(archive), rel=5e-2)


def test_the_archive_runs_in_fmpy_ssp(archive):
    """fmpy.ssp applies no binding of the SSD, only its ``parameter_set`` argument: the
    archive's qualified set, as `lever export-ssp` says."""
    from fmpy.ssp.ssd import read_ssv
    from fmpy.ssp.simulation import simulate_ssp

    table = simulate_ssp(str(archive), stop_time=1.5, step_size=1e-3,
                         parameter_set=read_ssv(str(archive), resource=ssp.QUALIFIED_SET))
    assert "monitor.status" not in table.dtype.names and "monitor.level" not in table.dtype.names
    tau1 = np.asarray(table["coupling.tau1"])
    assert table["monitor.peak"][-1] == pytest.approx(np.max(np.abs(tau1[:-1])), rel=1e-12)
    # a zero-order hold like libcosim's: 121.91 against our 119.36 N*m measured; bound 5 %
    assert table["monitor.peak"][-1] == pytest.approx(_ours(archive), rel=5e-2)


def test_a_shortened_run_fits_the_scenes_transient_and_says_so():
    """The scene states 2 s of 10: a 1 s run keeps the same share (0.2 s) and a note says it;
    a run the transient still fits keeps it; a transient the user sets stays strict."""
    kavz = scenes.load("kavz685")
    short = kavz.with_overrides(["experiment.stop=1"])
    assert short.experiment.transient == pytest.approx(0.2)
    assert "2 s does not fit a run of 1 s" in short.experiment.transient_note
    assert scenes.experiment_findings(short.experiment) == []
    assert short.with_overrides(["coupling.stiffness=900"]).experiment.transient_note == short.experiment.transient_note
    fits = kavz.with_overrides(["experiment.stop=3"])
    assert fits.experiment.transient == 2.0 and fits.experiment.transient_note is None
    chosen = kavz.with_overrides(["experiment.stop=1", "experiment.transient=2"])
    assert chosen.experiment.transient == 2.0 and chosen.experiment.transient_note is None
    assert scenes.experiment_findings(chosen.experiment) == ["experiment.transient = 2.0 s must be in [0, stop - start)"]


def test_lever_run_stop_shortens_the_run_and_the_report_says_what_it_judged(lever, fmu_dir, tmp_path):
    out = tmp_path / "short"
    result = lever("run", "kavz685", "--stop", "0.5", "--no-reference", "--no-plots", "--out", str(out))
    assert result.exit_code == 0, result.output
    import json
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_s"] == 0.5 and summary["transient_s"] == pytest.approx(0.1)
    assert "statistics after 0.1 s instead" in result.output
    assert "The run is shorter than its scene" in (out / "report.md").read_text()
    strict = lever("run", "kavz685", "--stop", "0.5", "--set", "experiment.transient=2",
                                      "--out", str(tmp_path / "strict"))
    assert strict.exit_code == 2 and "experiment.transient = 2.0 s must be in [0, stop - start)" in strict.output


def test_a_run_that_ends_before_its_transient_says_there_is_no_steady_window(fmu_dir, tmp_path):
    from harness import api
    from harness.formats import report

    done = api.run("kavz685", stop=0.3, reference=False, notify=lambda *_: None)
    summary = dict(done.summary, statistics={k: None for k in done.summary["statistics"]})   # nothing after it
    report.write_report(tmp_path / "report.md", summary)
    assert "No steady window: the run ended before the start-up transient did (t < 0.06 s)" in \
        (tmp_path / "report.md").read_text()


def test_a_c_fmu_with_units_is_checked_for_dimension(monitor_fmu, fmu_dir, tmp_path):
    """TorqueMonitor declares N.m: a torque into it connects, checked (not listed as
    unchecked); a speed into it is refused, both sides declaring their units."""
    from harness.description import plan as plans

    path = tmp_path / "monitored.toml"
    path.write_text(_monitored_scene_text(str(monitor_fmu)))
    checked = plans.check(scenes.load(path))
    assert checked.refusals == () and checked.unchecked == ()
    path.write_text(_monitored_scene_text(str(monitor_fmu)).replace('"coupling.tau1 -> monitor.torque"',
                                                                     '"engine.w -> monitor.torque"'))
    refused = plans.check(scenes.load(path))
    assert [f for f in refused.refusals if "engine.w -> monitor.torque" in f and "different quantity" in f
            and "(rad/s, [angle] / [time])" in f and "(N.m," in f]
