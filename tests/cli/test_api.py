"""The Python API (harness.api): a run's traces as arrays and its summary, validation with
a window, bad input as InputError, nothing written without an output folder; the command
line goes through it; the example script runs."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from harness import api

REPO = Path(__file__).resolve().parents[2]


def test_a_run_gives_its_traces_as_an_array_and_its_summary_and_writes_nothing(fmu_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    heard = []
    run = api.run("kavz685", {"coupling.misalignment": "20 deg"}, stop=0.4, master="jacobi",
                  notify=lambda kind, message: heard.append((kind, message)))
    assert run.ok and run.failure is None and run.out is None
    a = run.array()
    assert a.dtype.names[0] == "time" and "coupling.tau2" in a.dtype.names
    assert a["time"][0] == 0.0 and a["time"][-1] == pytest.approx(0.4) and len(a) == len(run.times) == 401
    assert np.array_equal(a["coupling.tau2"], run.traces["coupling.tau2"])
    assert run.summary["master"] == "jacobi" and run.summary["stop_s"] == 0.4
    assert run.summary["error_vs_reference"]["tau2"]["rms_relative"] < 0.02      # jacobi at 1 ms: measured 0.0057
    assert heard[0][0] == "note" and "does not fit a run of 0.4 s" in heard[0][1]
    assert run.notes[0] == f"note: {heard[0][1]}"
    assert list(tmp_path.iterdir()) == []                   # no output folder, no files
    # the same run through the command line: the same traces
    again = api.run(run.scene, reference=False, master="jacobi", out=tmp_path / "o", notify=lambda *_: None)
    assert np.array_equal(again.traces["coupling.tau2"], run.traces["coupling.tau2"])
    assert (tmp_path / "o" / "summary.json").is_file()


def test_bad_input_raises_input_error_naming_the_parameter(fmu_dir):
    with pytest.raises(api.InputError, match="did you mean 'stiffness'"):
        api.run("kavz685", ["coupling.stifness=900"], stop=0.1)
    with pytest.raises(api.InputError, match="no scene 'nope'"):
        api.load("nope")
    with pytest.raises(api.InputError, match="master 'nonsense' is unknown"):
        api.run("kavz685", stop=0.1, master="nonsense")
    with pytest.raises(api.InputError, match="--window"):
        api.validate("kavz685", result=(np.arange(3.0), {}), window=(5.0, 2.0))


def test_validate_judges_given_traces_over_a_window(fmu_dir):
    run = api.run("kavz685", stop=0.5, reference=False, notify=lambda *_: None)
    whole = api.validate("kavz685", result=(run.times, run.traces))
    assert not whole.passed and any("before the stop time" in p for p in whole.findings.problems)
    part = api.validate("kavz685", result=(run.times, run.traces), window=(0.0, 0.5))
    assert part.passed and part.findings.span == (0.0, 0.5)
    assert part.findings.describe_span() == "t = 0 ... 0.5 s of the reference's 0 ... 10 s"


def test_the_command_line_goes_through_the_api(lever, fmu_dir, tmp_path, monkeypatch):
    calls = []

    def spy(name):
        real = getattr(api, name)

        def wrapper(*args, **kwargs):
            calls.append(name)
            return real(*args, **kwargs)
        monkeypatch.setattr(api, name, wrapper)

    for name in ("run", "validate"):
        spy(name)
    refused = lever("bench", "kavz685", "--only", "nonsense", "--out", tmp_path / "n")
    assert refused.exit_code == 2 and "nonsense" in refused.output     # refused before anything runs
    assert not (tmp_path / "n").exists()

    def bench_stops_at_once(*args, **kwargs):          # the routing is the point, not a benchmark
        calls.append("bench")
        calls.append(kwargs.get("fmi_editions"))
        raise api.InputError("stopped by the test")
    monkeypatch.setattr(api, "bench", bench_stops_at_once)
    assert lever("run", "kavz685", "--stop", "0.2", "--no-reference", "--no-plots", "--out", tmp_path / "r").exit_code == 0
    assert lever("validate", "--result", tmp_path / "r" / "traces.csv", "kavz685", "--window", "0:0.2",
                 "--out", tmp_path / "v").exit_code == 0
    assert calls == ["run", "validate"]
    benched = lever("bench", "kavz685", "--only", "jacobi", "--out", str(tmp_path / "b"))
    assert calls[-2:] == ["bench", True] and "stopped by the test" in benched.output, benched.output
    lever("bench", "kavz685", "--no-fmi-editions", "--out", str(tmp_path / "b"))
    assert calls[-2:] == ["bench", False]


def test_a_run_says_how_it_ended(fmu_dir):
    """What ``lever run``'s exit status is made of: ok (0), refused by the FMUs before the
    first step (bad input, 2), failed part-way (1); interrupted (130) is tests/test_interrupts.py's."""
    quiet = {"reference": False, "notify": lambda kind, message: None}
    assert api.run("kavz685", stop=0.05, **quiet).outcome == "ok"
    failed = api.run("kavz685", {"coupling.stiffness": 1e9, "experiment.transient": 0}, step=0.01, stop=1, **quiet)
    assert failed.outcome == "failed" and not failed.ok and " t = " in failed.failure
    refused = api.run("kavz685_misalignment_edge", {"coupling.misalignment": "44 deg"}, stop=0.05, **quiet)
    assert refused.outcome == "refused" and "misalignment" in refused.failure


def test_the_example_script_runs(fmu_dir, tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("api_tour", REPO / "examples" / "api_tour.py")
    tour = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tour)
    assert tour.main(tmp_path) == 0
    said = capsys.readouterr().out
    assert "as written      against kavz685, t = 0 ... 1 s of the reference's 0 ... 10 s: PASS" in said
    assert "stiffness 1500  against kavz685, t = 0 ... 1 s of the reference's 0 ... 10 s: FAIL (" in said
    assert (tmp_path / "tau2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
