"""Peers for the benchmark: fmpy's plain stepping reproduces the harness's Jacobi
exactly, libcosim runs our FMUs (fixed step and ECCO) and lands near the reference."""
from __future__ import annotations

import re

import numpy as np
import pytest

from harness.judges import metrics
from harness import peers
from harness.judges import monolithic
from harness.engine import run
from harness.description import scene
from harness.description import plan

SHORT = ["experiment.stop=0.3", "experiment.transient=0.1"]


def test_all_peers_are_available():
    assert {name: peers.available(name) for name in peers.PEERS} == {name: None for name in peers.PEERS}


def test_fmpy_jacobi_is_the_harness_jacobi(fmu_dir):
    spec = scene.load("kavz685").with_overrides(SHORT)
    ours = run.simulate(spec, "jacobi", 1e-3, fmu_dir)
    theirs = peers.simulate_peer("fmpy-jacobi", spec, 1e-3, fmu_dir)
    assert theirs.ok, theirs.failure
    assert np.array_equal(ours.times, theirs.times)
    for name in ("engine.w", "load.w", "coupling.tau1", "coupling.tau2"):
        assert np.array_equal(ours.traces[name], theirs.traces[name]), name


@pytest.mark.parametrize("name, tolerance", [("libcosim-fixed", None), ("libcosim-ecco", 1e-2)])
def test_libcosim_runs_our_fmus(name, tolerance, fmu_dir):
    spec = scene.load("kavz685").with_overrides(SHORT)
    result = peers.simulate_peer(name, spec, 5e-4, fmu_dir, tolerance=tolerance)
    assert result.ok, result.failure
    assert result.times[0] == 0.0 and result.times[-1] >= 0.3 - 1e-9
    ref = monolithic.solve(spec, result.times)
    e = metrics.errors(result.times, result.traces, ref.times, ref.traces, ["engine.w", "coupling.tau2"],
                       metrics.error_scales(spec, ref.traces))
    assert e["engine.w"]["rms_relative"] < 1e-2 and e["coupling.tau2"]["rms_relative"] < 5e-2, e


def test_ecos_runs_the_scene_as_a_peer(fmu_dir):
    spec = scene.load("kavz685").with_overrides(SHORT)
    result = peers.simulate_peer("ecos", spec, 1e-3, fmu_dir)
    assert result.ok, result.failure
    # every communication point to the stop time (ecos, told the stop time itself, dropped the
    # last one: it adds the step to its time and 0.001 added 299 times passes 0.299)
    assert len(result.times) == 301 and result.times[0] == 0.0 and result.times[-1] == pytest.approx(0.3, abs=1e-9)
    assert result.wall_time > 0.0
    assert set(result.traces) == set(plan.recorded_names(spec))
    ref = monolithic.solve(spec, result.times)
    e = metrics.errors(result.times, result.traces, ref.times, ref.traces, ["engine.w", "coupling.tau2"],
                       metrics.error_scales(spec, ref.traces))
    assert e["engine.w"]["rms_relative"] < 1e-2 and e["coupling.tau2"]["rms_relative"] < 5e-2, e


def test_libcosim_reports_a_refused_parameter_instead_of_crashing(fmu_dir):
    spec = scene.load("kavz685").with_overrides(SHORT + ["coupling.transfer_mode=bogus"])
    result = peers.simulate_peer("libcosim-fixed", spec, 1e-3, fmu_dir)
    assert not result.ok and result.failure_stage == "initialisation"
    assert "transfer_mode" in result.failure


def test_every_peer_keeps_the_contract(fmu_dir):
    """Each registered peer runs a short scene under its own name, reports the counters it
    declares, and ran the scene's experiment (a peer that did not is refused)."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.02", "experiment.transient=0.01"])
    for name, peer in peers.PEERS.items():
        assert peer.name == name and peer.summary and peer.timed, name
        result = peers.simulate_peer(name, spec, 1e-3, fmu_dir, tolerance=1e-2)
        assert result.ok, (name, result.failure)
        assert result.master == name or name.startswith("lever"), (name, result.master)
        assert set(peer.counters) <= set(result.counters), (name, result.counters)
        assert set(result.traces) == set(plan.recorded_names(spec)) and result.wall_time > 0, name


def test_a_new_peer_needs_only_its_class_and_its_name_in_the_registry(monkeypatch, fmu_dir):
    """The registry is the one place a peer is named: a peer added there is run, checked and
    refused like the others."""
    from harness.peers.base import Peer

    class Hold(Peer):
        name, summary = "hold", "every recorded variable held at 1 (no FMU stepped)"

        def scene_problem(self, setup):
            return "hold: no start but 0" if setup.scene.experiment.start else None

        def run(self, setup, step, tolerance, environment):
            grid = setup.time_grid(step)[::2]          # every other point: another experiment
            return run.RunResult(setup.scene, self.name, step, grid, {n: np.ones(len(grid)) for n in setup.record},
                                 1e-3, {"steps": len(grid) - 1})

    monkeypatch.setitem(peers.PEERS, "hold", Hold())
    spec = scene.load("kavz685").with_overrides(SHORT)
    assert peers.available("hold") is None
    refused = peers.simulate_peer("hold", spec, 1e-3, fmu_dir)
    assert refused.failure.startswith("refused: peer hold made 150 steps of 0.001 s, not the 300"), refused.failure
    with pytest.raises(ValueError, match="hold: no start but 0"):
        peers.simulate_peer("hold", spec.with_overrides(["experiment.start=0.1"]), 1e-3, fmu_dir)


def test_the_benchmark_runs_a_peer_by_its_name(fmu_dir):
    from harness.studies import bench

    spec = scene.load("kavz685").with_overrides(SHORT)
    case = bench.run_peer(spec, "fmpy-jacobi", 1e-3, 1, fmu_dir, 5.0)
    assert case.failure is None and case.steps == 300 and case.errors["tau_rms"] < 1e-2, case
    assert bench.run_peer(spec, "simulink", 1e-3, 1, fmu_dir, 5.0).failure.startswith("not run: unknown peer")


def test_a_peer_refuses_fmus_of_an_fmi_version_it_does_not_run_and_says_why(fmu_dir):
    """A peer whose engine runs no FMI 3.0 FMU refuses the scene before anything runs, and
    says what in the engine stops it; the peers whose engines do run FMI 3.0 are told so."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.05", "experiment.transient=0", "experiment.fmi=3"])
    for name, peer in peers.PEERS.items():
        if "3" not in peer.fmi_versions:
            assert peer.fmi_limit, name
            with pytest.raises(ValueError, match=rf"peer '{name}' runs FMI 2.0 FMUs; scene 'kavz685' has .*FMI 3.0.*: "
                                                 rf"{re.escape(peer.fmi_limit)}$"):
                peers.simulate_peer(name, spec, 1e-3, fmu_dir)
    runs_fmi3 = {name for name, peer in peers.PEERS.items() if "3" in peer.fmi_versions}
    assert runs_fmi3 == {"lever", "lever-jacobi", "fmpy-jacobi", "ecos", "ecos-serial", "ecos-log-all"}
    assert peers.simulate_peer("lever-jacobi", spec, 1e-3, fmu_dir).ok


def test_libcosim_refuses_an_fmi3_fmu_itself_as_its_peers_say(fmu_dir):
    """What the libcosim peers' refusal says, from libcosim: told to load an FMI 3.0 FMU
    anyway, it refuses it by its version."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.01", "experiment.transient=0", "experiment.fmi=3"])
    setup = peers.SceneSetup(spec, fmu_dir, plan.recorded_names(spec))
    # past the peer's own refusal (simulate_peer asks fmi_problem first)
    with pytest.raises(peers.LibcosimError, match=r"loading EngineShaft.fmu as 'engine': .*Unsupported FMI version"):
        peers.PEERS["libcosim-fixed"].run(setup, 1e-3, None, None)


def _same_runs(fmi2, fmi3):
    assert fmi2.ok and fmi3.ok, (fmi2.failure, fmi3.failure)
    assert np.array_equal(fmi2.times, fmi3.times) and fmi2.traces.keys() == fmi3.traces.keys()
    for name in fmi2.traces:
        assert np.array_equal(fmi2.traces[name], fmi3.traces[name]), name


def test_fmpy_jacobi_runs_the_fmi3_editions_as_the_fmi2_ones(fmu_dir):
    """fmpy's FMU3Slave loop on the FMI 3.0 editions gives the FMI 2.0 run's traces bit for
    bit: the same loop, and the editions are the same model code behind the same calls
    (the FMI 3.0 entry passes the doubles through to the FMI 2.0 entry), so any
    difference is a difference between the editions."""
    spec = scene.load("kavz685").with_overrides(SHORT)
    _same_runs(peers.simulate_peer("fmpy-jacobi", spec, 1e-3, fmu_dir),
               peers.simulate_peer("fmpy-jacobi", spec.with_overrides(["experiment.fmi=3"]), 1e-3, fmu_dir))


def test_fmpy_jacobi_says_what_an_fmi3_fmu_refused(fmu_dir):
    spec = scene.load("kavz685").with_overrides(SHORT + ["experiment.fmi=3", "coupling.transfer_mode=bogus"])
    result = peers.simulate_peer("fmpy-jacobi", spec, 1e-3, fmu_dir)
    assert not result.ok and result.failure_stage == "initialisation"
    assert "fmi3SetString" in result.failure and "FMU said: [error] parameter 'transfer_mode'" in result.failure


def test_ecos_runs_the_fmi3_editions_as_the_fmi2_ones(fmu_dir):
    """ecos on the SSP export of the FMI 3.0 scene logs what it logs of the FMI 2.0 one, to
    the last of its six decimals: the same algorithm stepping the same model code."""
    spec = scene.load("kavz685").with_overrides(SHORT)
    fmi3 = peers.simulate_peer("ecos-serial", spec.with_overrides(["experiment.fmi=3"]), 1e-3, fmu_dir)
    _same_runs(peers.simulate_peer("ecos-serial", spec, 1e-3, fmu_dir), fmi3)


def test_ecos_logging_everything_never_gives_zeros_for_an_fmi3_scene(fmu_dir):
    """ecos's default log reads every Float64 of an FMU in one call and ignores a refusal:
    ``ecos-log-all`` refuses an FMI 3.0 scene whose FMUs refuse that read in Co-Simulation,
    saying which and why, and runs one whose FMUs give it - then logging what ``ecos`` logs."""
    from harness.description.plan import fmu_path
    from harness.peers import ecos

    spec = scene.load("kavz685").with_overrides(SHORT + ["experiment.fmi=3"])
    # our FMI 3.0 editions give every Float64 (the event indicators too) in Co-Simulation
    refusing = {name: said for name, spec_ in spec.components.items()
                if (said := ecos.refused_read(fmu_path(spec_.fmu, fmu_dir, 3)))}
    assert refusing == {}
    _same_runs(peers.simulate_peer("ecos", spec, 1e-3, fmu_dir),
               peers.simulate_peer("ecos-log-all", spec, 1e-3, fmu_dir))
    # an FMU without event indicators gives every value in one call: the question is the FMU's
    assert ecos.refused_read(fmu_path("LeverCoupling", fmu_dir, 3)) is None


def test_what_stops_a_peer_is_said_before_anything_runs(lever, fmu_dir, tmp_path):
    """``peers.problem``: an unknown peer, an FMI version or a scene it cannot run; `lever
    engines` refuses such engines by it before running any."""
    spec3 = scene.load("kavz685").with_overrides(["experiment.fmi=3"])
    assert peers.problem("lever", spec3, fmu_dir) is None and peers.problem("ecos", spec3, fmu_dir) is None
    assert peers.problem("simulink", spec3, fmu_dir).startswith("peer 'simulink' is not available: unknown peer")
    assert peers.problem("fmpy-ssp", spec3, fmu_dir).startswith("peer 'fmpy-ssp' runs FMI 2.0 FMUs")
    assert "simulates from t = 0 only" in peers.problem("ecos", spec3.with_overrides(["experiment.start=0.1"]), fmu_dir)
    refused = lever("engines", "--set", "experiment.fmi=3", "--out", tmp_path / "e")
    assert refused.exit_code == 2 and not (tmp_path / "e").exists(), refused.output
    assert all(f"peer '{name}' runs FMI 2.0 FMUs" in refused.output
               for name in ("container", "fmpy-ssp", "libcosim-ssp", "libcosim-ecco"))
