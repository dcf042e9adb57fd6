"""The reference made from the FMUs (harness.judges.fmu_reference): where the monolithic
one exists, the errors measured against the made ones agree with it (the fast check of
``lever study reference-agreement``); the extrapolated reference is refused when the runs do
not show the master's order; a user's pythonfmu FMU without units, built here, connects and
is judged against the extrapolated reference."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from harness import api
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine.run import simulate
from harness.judges import fmu_reference, solution
from harness.judges.solution import ReferenceUnavailable
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "user_fmu"


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))


def _plan(name: str, stop: float) -> plans.Plan:
    return plans.check(scenes.load(name).with_overrides([f"experiment.stop={stop}"]))


def test_observed_orders_read_the_order_and_leave_round_off_out():
    t = np.linspace(0.0, 1.0, 11)
    exact = np.sin(t)
    levels = [{"y": exact + 1e-3 * h ** 2 * t, "flat": exact} for h in (4.0, 2.0, 1.0)]
    orders = fmu_reference.observed_orders(*levels)
    assert orders["y"] == pytest.approx(2.0) and orders["flat"] is None


def test_errors_against_the_made_references_agree_with_the_monolithic_ones(fmu_dir):
    plan = _plan("kavz685", 0.1)
    for master, step in (("jacobi", 2e-3), ("jacobi-quadratic", 1e-3)):
        run = simulate(plan, master, step)
        figures = {}
        for source in fmu_reference.SOURCES:
            ref = fmu_reference.reference(plan, run.times, source=source)
            assert ref.info["source"] == source
            judged = fmu_reference.judge(plan.scene, run.times, run.traces, ref)
            figures[source] = judged.figure
            if source != "monolithic":
                assert judged.reference_figure < figures["monolithic"] / 100, (master, source)
        for source in ("model-exchange", "extrapolated"):
            assert figures[source] / figures["monolithic"] == pytest.approx(1.0, abs=0.5), (master, source, figures)


def test_a_run_off_the_reference_grid_is_read_by_spline_with_its_error_added(fmu_dir):
    plan = _plan("kavz685", 0.2)
    run = simulate(plan, "adaptive", 1e-3)          # its own steps: off the made reference's grid
    ref = fmu_reference.reference(plan, run.times, source="model-exchange")
    assert ref.info["interpolated"] > 0 and np.array_equal(ref.times, run.times)
    monolithic = fmu_reference.reference(plan, run.times, source="monolithic")
    made = fmu_reference.judge(plan.scene, run.times, run.traces, ref).figure
    truth = fmu_reference.judge(plan.scene, run.times, run.traces, monolithic).figure
    assert made == pytest.approx(truth, rel=0.05)


def test_the_extrapolation_is_refused_when_the_runs_do_not_show_the_masters_order(fmu_dir):
    # the freewheel's own integrator, not the master, sets its error: the runs converge faster than order 2
    plan = _plan("freewheel_rectifier", 0.02)
    with pytest.raises(ReferenceUnavailable, match=r"does not show its order 2 \(observed: .*\d\.\d\d"):
        fmu_reference.reference(plan, np.linspace(0.0, 0.02, 101), source="extrapolated")


def test_the_made_reference_is_cached_by_the_scene(fmu_dir):
    plan = _plan("kavz685", 0.05)
    times = np.linspace(0.0, 0.05, 51)
    first = fmu_reference.reference(plan, times, source="extrapolated")
    again = fmu_reference.reference(plan, times, source="extrapolated")
    assert again.info.get("cached") and not first.info.get("cached")
    assert all(np.array_equal(first.traces[k], again.traces[k]) for k in first.traces)
    other = fmu_reference.reference(_plan("kavz685", 0.06), np.linspace(0.0, 0.05, 51), source="extrapolated")
    assert not other.info.get("cached")


@pytest.fixture(scope="module")
def user_scene(tmp_path_factory, user_example) -> Path:
    """The how-to's scene with its user's FMU (pythonfmu, no units) built here, 0.1 s long."""
    return user_example(tmp_path_factory.mktemp("user_fmu"), 0.1, 0.05)


def test_a_users_fmu_without_units_connects_and_is_judged_against_the_extrapolated_reference(
        user_scene, fmu_dir, tmp_path):
    heard = []
    done = api.run(user_scene, master="jacobi", step=1e-3, out=tmp_path / "run",
                   notify=lambda kind, message: heard.append(message))
    assert done.ok
    unchecked = [m for m in heard if "not checked for dimension" in m]
    assert len(unchecked) == 1 and "load.phi -> coupling.phi2 (load.phi declares no unit)" in unchecked[0]
    assert done.summary["unchecked_connections"]["connections"] == [
        "load.phi -> coupling.phi2 (load.phi declares no unit)", "load.w -> coupling.w2 (load.w declares no unit)",
        "coupling.tau2 -> load.tau (load.tau declares no unit)"]
    reference = done.summary["reference"]
    assert reference["source"] == "extrapolated co-simulation" and reference["own_error_relative"] < 1e-6
    assert set(done.summary["error_vs_reference"]) == {"engine.w", "load.w", "coupling.tau1", "coupling.tau2"}
    assert 1e-4 < done.summary["error_vs_reference"]["coupling.tau2"]["rms_relative"] < 0.1
    report = (tmp_path / "run" / "report.md").read_text()
    assert "**Units not checked:** 3 connections" in report
    assert "## Error against the extrapolated co-simulation reference" in report
    assert {"speeds.png", "torques.png", "vs_reference.png"} <= {p.name for p in (tmp_path / "run").iterdir()}


def test_a_run_with_no_reference_to_be_had_says_so_in_one_line(user_scene, fmu_dir, tmp_path, monkeypatch):
    monkeypatch.setattr(fmu_reference, "EXTRAPOLATED_MASTER", "jacobi-quadratic")   # order 3, shows 2 here
    heard = []
    done = api.run(user_scene, master="jacobi", step=1e-3, notify=lambda kind, message: heard.append(message))
    said = [m for m in heard if m.startswith("no reference for this scene")]
    assert len(said) == 1 and "does not show its order 3" in said[0]
    assert "error_vs_reference" not in done.summary
