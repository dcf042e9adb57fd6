"""Every committed scene through every public entry - the API with and without an output
folder, ``lever run`` with ``--no-plots`` and with ``--stream`` - over a few dozen steps:
each gives a summary of its own kind of scene (a rectifier is never summarised as a
driveline), and the API's summary without files is the one summary.json holds."""
from __future__ import annotations

import json

import numpy as np
import pytest

from harness import api
from harness.description import scene_kinds
from harness.formats import report
from harness.judges import monolithic

SCENES = sorted(api.scenes())
#: the run's length: a few dozen of the scene's steps (the stiff scene's 5e-5 s: 400)
STOP = 0.02
#: what says which kind of scene a summary is of (harness.formats.report.REPORTS)
KIND_KEY = {"driveline": "statistics", "rectifier": "freewheel"}
#: what a summary holds that changes from run to run of the same scene
VARYING = {"wall_time_s", "counters", "files", "reference"}


def _kind(name: str) -> str:
    return scene_kinds.kind_of(api.load(name))


def test_every_kind_of_scene_has_its_report_and_its_reference_solver():
    assert set(report.REPORTS) == set(scene_kinds.KINDS) == set(monolithic.SOLVERS)
    assert {_kind(name) for name in SCENES} == set(scene_kinds.KINDS)      # every kind is among the committed


def _summary_of_its_kind(summary: dict, name: str):
    kind = _kind(name)
    assert summary["scene"] == name and summary["ok"] is True, (name, summary.get("failure"))
    assert KIND_KEY[kind] in summary, (name, kind, sorted(summary))
    assert not (set(KIND_KEY.values()) - {KIND_KEY[kind]}) & set(summary), (name, kind, sorted(summary))


@pytest.mark.parametrize("name", SCENES)
def test_the_api_without_out_returns_the_run_with_its_kinds_summary(name, fmu_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run = api.run(name, stop=STOP, notify=lambda *_: None)
    assert isinstance(run, api.Run) and run.ok and run.out is None
    assert run.times[-1] == pytest.approx(STOP)
    _summary_of_its_kind(run.summary, name)
    if "reference" in api.load(name).features:          # judged against its reference
        assert run.reference is not None and run.summary["error_vs_reference"], name
    assert list(tmp_path.iterdir()) == []               # nothing written


@pytest.mark.parametrize("name", SCENES)
def test_the_api_with_out_writes_the_summary_the_api_returns(name, fmu_dir, tmp_path):
    bare = api.run(name, stop=STOP, notify=lambda *_: None)
    run = api.run(name, stop=STOP, out=tmp_path / "run", plots=False, notify=lambda *_: None)
    assert isinstance(run, api.Run) and run.ok and run.out == tmp_path / "run"
    written = json.loads((tmp_path / "run" / "summary.json").read_text())
    _summary_of_its_kind(written, name)
    assert set(written) - VARYING == set(bare.summary) - VARYING
    assert np.array_equal(run.traces[next(iter(run.traces))], bare.traces[next(iter(bare.traces))])


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("options", [("--no-plots",), ("--stream", "--no-plots")], ids=["plain", "stream"])
def test_lever_run_writes_every_scene(name, options, lever, fmu_dir, tmp_path):
    out = tmp_path / "run"
    result = lever("run", name, "--stop", STOP, *options, "--out", out, "--no-progress")
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    _summary_of_its_kind(summary, name)
    rows = (out / "traces.csv").read_text().splitlines()
    assert len(rows) > 10 and float(rows[-1].split(",")[0]) == pytest.approx(STOP)
    assert not list(out.glob("*.png"))
    if "--stream" in options:
        assert summary["stream"]["rows_written"] == len(rows) - 1
        assert f"Traces streamed while running: {len(rows) - 1} rows" in (out / "report.md").read_text()
    else:
        assert "stream" not in summary


@pytest.mark.parametrize("name", ["kavz685", "freewheel_rectifier"])
def test_a_streamed_run_of_each_kind_draws_its_kinds_plots(name, lever, fmu_dir, tmp_path):
    out = tmp_path / "run"
    result = lever("run", name, "--stop", STOP, "--stream", "--out", out, "--no-progress")
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    _summary_of_its_kind(summary, name)
    drawn = {p.name for p in out.glob("*.png")}
    assert drawn and drawn <= set(summary["files"]), (drawn, summary["files"])
    # each kind's own figures: the driveline's speeds of its two shafts, the rectifier's kinematics
    assert ("speeds.png" in drawn, "kinematics.png" in drawn) == ((True, False) if _kind(name) == "driveline"
                                                                   else (False, True)), drawn
