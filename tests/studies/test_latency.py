"""Real time, measured: the engine's step observer and the latency table of `lever run
--latency`.  No assertion here depends on how fast this machine is."""
from __future__ import annotations

import gc

import pytest

from harness.description import scene
from harness.engine.observers import StepTimer
from harness.engine.run import simulate
from harness.studies import latency


def _short():
    return scene.load("kavz685").with_overrides(["experiment.stop=0.05", "experiment.transient=0.01"])


def test_the_observer_sees_every_step_of_a_run_and_the_table_says_it(fmu_dir):
    timer = StepTimer()
    result = simulate(_short(), "jacobi-quadratic", 1e-3, fmu_dir, observer=timer)
    assert result.ok and len(timer.wall) == 50 and list(timer.times) == pytest.approx(result.times[1:])
    assert gc.callbacks.count(timer._on_gc) == 0          # the collection hook is taken away after the run
    report = latency.analyse(timer, 1e-3, result.wall_time)
    assert report["steps"] == 50 and len(report["startup_s"]) == latency.STARTUP
    assert report["median_s"] <= report["p99_s"] <= report["p999_s"] <= report["max_s"]
    assert report["timed_s"] <= result.wall_time
    assert len(report["slowest"]) == latency.SLOWEST
    assert report["slowest"][0]["wall_s"] == report["max_s"]
    known = ("start-up", "garbage collection", "the host", "the step's own work")
    assert all(reason.split(":")[0] in known for s in report["slowest"] for reason in s["why"].split("; "))
    text = latency.table(report, "kavz685")
    assert "| all steps |" in text and "| after the first 10 |" in text and "Start-up steps:" in text
    assert "| CPU time of each step" in text and text.count("| start-up: step ") >= latency.STARTUP
    assert text.count("\n| ") >= 3 + 1 + latency.STARTUP + 1 + latency.SLOWEST


def test_the_slowest_steps_are_explained_from_what_was_seen_in_them():
    timer = StepTimer()
    # synthetic steps of 1 ms: a slow first step, one with a collection, one that waited
    # for the CPU, one slow with the CPU all along
    for k in range(40):
        timer.wall.append(1e-4)
        timer.cpu.append(1e-4)
        timer.switches.append(0)
        timer.times.append((k + 1) * 1e-3)
    timer.wall[0], timer.cpu[0] = 2e-3, 2e-3
    timer.wall[20], timer.cpu[20] = 3e-3, 3e-3
    timer.collections.append((20, 2.5e-3, 2))
    timer.wall[25], timer.cpu[25], timer.switches[25] = 5e-3, 1e-4, 3
    timer.wall[30], timer.cpu[30] = 1.5e-3, 1.5e-3
    report = latency.analyse(timer, 1e-3)
    why = {s["index"]: s["why"] for s in report["slowest"]}
    assert why[0] == "start-up: step 1 of the run"
    assert why[20] == "garbage collection: generation 2, 2.50 ms of the step"
    assert why[25] == "the host: the process had the CPU 2 % of the step (3 involuntary context switches)"
    assert why[30] == "the step's own work: the CPU was the process's all along"
    assert report["over_step"] == 4 and report["over_step_after_startup"] == 3
    assert report["max_s"] == 5e-3 and report["median_s"] == 1e-4


def test_lever_run_latency_writes_the_table(lever, fmu_dir, tmp_path):
    outcome = lever("run", "kavz685", "--set", "experiment.stop=0.05", "--set",
                                       "experiment.transient=0.01", "--no-reference", "--no-plots", "--latency",
                                       "--out", str(tmp_path))
    assert outcome.exit_code == 0, outcome.output
    assert "step latency: median" in outcome.output and "start-up steps:" in outcome.output
    assert (tmp_path / "latency.md").read_text().startswith("# Step latency: kavz685, master jacobi-quadratic")
