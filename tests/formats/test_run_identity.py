"""Results that say what they ran: summary.json, report.md and the plots' titles carry the
parameter values a run used and where each came from, and `lever validate` says when a
result was made with other values than its reference."""
from __future__ import annotations

import json

import pytest

from harness import api
from harness.formats.run_files import run_title


@pytest.fixture(scope="module")
def misaligned(fmu_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("misaligned")
    api.run("kavz685", {"coupling.misalignment": "20 deg"}, stop=0.3, reference=False, out=out, plots=False,
            notify=lambda *_: None)
    return out


def test_summary_names_every_parameter_and_where_its_value_came_from(misaligned):
    summary = json.loads((misaligned / "summary.json").read_text())
    parameters = summary["parameters"]
    assert parameters["coupling.misalignment"] == {"value": "20 deg", "source": "--set"}
    assert parameters["coupling.stiffness"] == {"value": "715.4 N.m/rad", "source": "scene file"}
    assert parameters["engine.torque_lag"]["source"] == "default"
    assert summary["overrides"] == {"coupling.misalignment": "20 deg", "experiment.stop": "0.3"}
    assert summary["master"] == "jacobi-quadratic" and summary["master_options"] == {"ramp": True}
    assert summary["fmi_edition"] == 2 and summary["lever_version"]
    assert "tolerance" in summary


def test_the_report_never_quotes_the_scene_files_value_of_an_overridden_parameter(misaligned):
    report = (misaligned / "report.md").read_text()
    assert "alpha = 15 deg" not in report         # the scene file's description quotes its own 15 deg
    assert report.startswith("# kavz685 with coupling.misalignment = 20 deg")
    assert "| coupling.misalignment | 20 deg | --set |" in report
    assert "Changed with --set: **coupling.misalignment = 20 deg**" in report
    title = run_title({"scene": "kavz685", "master": "jacobi", "step_s": 1e-3,
                       "overrides": {"coupling.misalignment": "20 deg"}})
    assert title == "kavz685 - jacobi, h = 0.001 s\n--set coupling.misalignment = 20 deg"


def test_validate_says_a_result_was_made_with_other_values_than_its_reference(lever, misaligned, tmp_path):
    outcome = lever("validate", "--result", str(misaligned / "traces.csv"), "kavz685", "--window", "0:0.3",
                    "--out", str(tmp_path))
    assert ("note: the result was made with other values than its reference" in outcome.output
            and "coupling.misalignment = 20 deg (--set; the reference: 15 deg)" in outcome.output), outcome.output
    # a CSV without a lever summary beside it: said to be of unknown making
    lone = tmp_path / "lone" / "traces.csv"
    lone.parent.mkdir()
    lone.write_text((misaligned / "traces.csv").read_text())
    outcome = lever("validate", "--result", str(lone), "kavz685", "--window", "0:0.3", "--out", str(tmp_path / "v"))
    assert "what the result was made with is not known" in outcome.output


def test_the_summary_never_quotes_the_scene_files_description_of_a_changed_run(misaligned):
    summary = json.loads((misaligned / "summary.json").read_text())
    assert "15 deg" not in json.dumps(summary)
    assert summary["description"].startswith("kavz685 with coupling.misalignment = 20 deg")
