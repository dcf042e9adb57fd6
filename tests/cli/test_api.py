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
    again = api.run(run.scene, reference=False, master="jacobi", out=tmp_path / "o", notify=lambda *_: None,
                    plots=False)
    assert np.array_equal(again.traces["coupling.tau2"], run.traces["coupling.tau2"])
    assert (tmp_path / "o" / "summary.json").is_file()


def test_bad_input_raises_input_error_naming_the_parameter(fmu_dir):
    with pytest.raises(api.InputError, match="did you mean 'stiffness'"):
        api.run("kavz685", ["coupling.stifness=900"], stop=0.1)
    with pytest.raises(api.InputError, match="no scene 'nope'"):
        api.load("nope")
    with pytest.raises(api.InputError, match="master 'nonsense' is unknown"):
        api.run("kavz685", stop=0.1, master="nonsense")
    with pytest.raises(api.InputError, match=r"^window='5.0:2.0': must lie in the reference's span"):
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
        # and where the api's own functions find it (validate_each calls validate)
        monkeypatch.setattr(importlib.import_module(real.__module__), name, wrapper)

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


# -- what a notebook user holds, and what the command line refuses, refused here too ----------------------

QUIET = {"reference": False, "notify": lambda kind, message: None}


@pytest.fixture(scope="module")
def short_run(fmu_dir):
    return api.run("kavz685", stop=0.2, **QUIET)


def test_validate_takes_a_run_an_array_a_pair_and_a_csv_alike(short_run, tmp_path):
    csv = tmp_path / "run.csv"
    a = short_run.array()
    np.savetxt(csv, np.column_stack([a[n] for n in a.dtype.names]), delimiter=",", header=",".join(a.dtype.names),
               comments="")
    verdicts = [api.validate("kavz685", result=given, window=(0, 0.2))
                for given in (short_run, a, (short_run.times, short_run.traces), str(csv), csv)]
    assert all(v.passed for v in verdicts)
    signals = [[(s.name, s.rms_error) for s in v.findings.signals] for v in verdicts]
    assert all(s == signals[0] for s in signals[:3])          # the same numbers, whatever the container
    with pytest.raises(api.InputError, match=r"^result=42: expected a Run, a numpy structured array"):
        api.validate("kavz685", result=42)
    with pytest.raises(api.InputError, match="without a 'time' field"):
        api.validate("kavz685", result=a[["coupling.tau2"]])
    with pytest.raises(api.InputError, match="signal 'x' has 2 values for 201 times"):
        api.validate("kavz685", result=(short_run.times, {"x": [1.0, 2.0]}))


def test_times_take_units_as_overrides_do(fmu_dir):
    plain = api.run("kavz685", step=0.002, stop=0.1, **QUIET)
    with_units = api.run("kavz685", step="2 ms", stop="100 ms", **QUIET)
    assert np.array_equal(plain.traces["coupling.tau2"], with_units.traces["coupling.tau2"])
    assert np.array_equal(plain.times, with_units.times)
    with pytest.raises(api.InputError, match=r"^step='2 kg': a value in kg .* cannot be a value in s"):
        api.run("kavz685", step="2 kg", stop=0.1, **QUIET)
    with pytest.raises(api.InputError, match=r"^stop=inf: expected a finite time"):
        api.load("kavz685", stop=float("inf"))
    assert api.parse_window("0:500 ms") == (0.0, 0.5) and api.parse_window(":2 s") == (None, 2.0)
    with pytest.raises(api.InputError, match=r"^window='0:2 kg': expected START:STOP in seconds"):
        api.parse_window("0:2 kg")
    with pytest.raises(api.InputError, match=r"^window stop='x'"):
        api.validate("kavz685", result=(np.arange(3.0), {}), window=(0, "x"))


def test_one_naming_of_signals_and_short_names_where_unambiguous(short_run):
    assert list(short_run.array(["tau2", "engine.w"]).dtype.names) == ["time", "coupling.tau2", "engine.w"]
    assert list(short_run.array("engine_torque").dtype.names) == ["time", "engine.engine_torque"]   # no alias
    stats = short_run.summary["statistics"]
    assert "coupling.tau2" in stats and "tau2" not in dict(stats)          # full names, as the traces have
    assert stats["tau2"] is stats["coupling.tau2"] and stats["w1"] is stats["engine.w"]   # short and alias taken
    assert set(short_run.summary["statistics"]) <= set(short_run.traces)
    with pytest.raises(api.UnknownSignal, match="signal 'w' is ambiguous: engine.w, load.w"):
        short_run.array(["w"])
    with pytest.raises(KeyError, match="did you mean"):
        short_run.traces["tua2"]
    assert "tau2" in short_run.traces and short_run.traces.get("nope") is None


def test_the_summary_file_names_signals_as_the_traces_do(fmu_dir, tmp_path):
    import json

    done = api.run("kavz685", stop=0.2, master="jacobi", out=tmp_path / "o", plots=False,
                   notify=lambda kind, message: None)
    written = json.loads((tmp_path / "o" / "summary.json").read_text())
    header = (tmp_path / "o" / "traces.csv").read_text().splitlines()[0].split(",")
    assert set(written["statistics"]) | set(written["error_vs_reference"]) <= set(header)
    assert done.summary["error_vs_reference"]["tau2"] == written["error_vs_reference"]["coupling.tau2"]


def test_reprs_fit_on_a_screen_and_say_pass_or_fail(short_run):
    shown = repr(short_run)
    assert shown.startswith("Run(kavz685: ok, master jacobi-quadratic") and len(shown.splitlines()) <= 12
    assert "coupling.tau2" in shown and max(map(len, shown.splitlines())) < 160
    failed = api.validate("kavz685", result=short_run)          # 0.2 s against a 10 s reference
    shown = repr(failed)
    assert shown.startswith("Validation(kavz685: FAIL") and "problem: the result ends at t = 0.2 s" in shown
    assert len(shown) < 2000 and len(shown.splitlines()) <= 16
    assert repr(api.validate("kavz685", result=short_run, window=(0, 0.2))).startswith("Validation(kavz685: PASS")
    bench = api.BenchResult(scene="kavz685", cases=[], summary=["  best master: x"], written=["/r/bench.md"])
    assert repr(bench).splitlines() == ["BenchResult(kavz685: 0 of 0 cases ran, none failed", "  best master: x",
                                        "  written: /r/ (bench.md))"]


@pytest.mark.parametrize("call, words", [
    (lambda: api.bench("kavz685", repeats=0), "repeats=0: must be in [1, 20]"),
    (lambda: api.bench("kavz685", repeats="3"), "repeats='3': expected a whole number in [1, 20]"),
    (lambda: api.bench("kavz685", out=123), "out=123: expected a folder"),
    (lambda: api.run(None), "scene=None: expected a scene's name"),
    (lambda: api.run("kavz685", out=123), "out=123: expected a folder"),
    (lambda: api.run("kavz685", master=5), "master: 5 is not a name"),
    (lambda: api.run("kavz685", master="me-cvode", tolerance="1e-4"), "tolerance='1e-4': expected a number"),
    (lambda: api.validate(None), "name=None: expected a reference's name"),
    (lambda: api.validate("kavz685", tolerance=0.1), "tolerance=0.1: one of lever, cross-check"),
    (lambda: api.sweep(scene=None), "scene=None"),
    (lambda: api.sweep(thin=0), "thin=0: must be in [1, 100]"),
    (lambda: api.stability_map(jobs=0), "jobs=0: must be in [1, 64]"),
    (lambda: list(api.fingerprints(stop="1 kg")), "stop='1 kg'"),
    (lambda: api.export(to="fmu"), "to='fmu': ssp or container"),
    (lambda: api.fmu_path("EngineShat"), "did you mean 'EngineShaft'"),
])
def test_wrong_types_and_values_raise_input_error_naming_the_argument(call, words):
    with pytest.raises(api.InputError) as raised:
        call()
    assert words in str(raised.value)


def test_numpy_scalars_are_numbers(fmu_dir):
    run = api.run("kavz685", master="me-cvode", tolerance=np.float32(1e-4), step=np.float64(0.002),
                  stop=np.float32(0.05), **QUIET)
    assert run.ok and run.summary["stop_s"] == pytest.approx(0.05)
    assert api.run("kavz685", {"coupling.stiffness": np.float64(900.0)}, stop=0.02, **QUIET).ok


def test_warnings_point_at_the_callers_line(fmu_dir):
    import warnings

    with warnings.catch_warnings(record=True) as heard:
        warnings.simplefilter("always")
        api.run("kavz685", stop=0.02, reference=False)        # the transient note
    assert heard and {Path(w.filename) for w in heard} == {Path(__file__)}


def test_every_public_name_is_listed_and_documented():
    assert sorted(dir(api)) == sorted(api.__all__) and "np" not in dir(api)
    undocumented = [n for n in api.__all__ if not (getattr(api, n).__doc__ or "").strip()]
    assert undocumented == []
    for cls in (api.Run, api.Validation):
        members = [m for m in vars(cls) if not m.startswith("_")]
        assert [m for m in members if not (getattr(cls, m).__doc__ or "").strip() and isinstance(
            getattr(cls, m), property)] == []
    assert api.scenes()["kavz685"].startswith("KAVZ-685") and api.scenes_list is api.scenes


def test_an_fmus_path_for_a_host_comes_from_the_api(fmu_dir):
    from fmpy import read_model_description

    assert read_model_description(str(api.fmu_path("EngineShaft"))).modelName == "EngineShaft"
    assert read_model_description(str(api.fmu_path("EngineShaft", fmi=3))).fmiVersion.startswith("3.")
