"""What the studies write names each signal as the traces do (``component.variable``):
the engines' table and lines, the sweep's sweep.json and sweep.md, the benchmark's
progress line."""
from __future__ import annotations

import json
import re

from harness.description import scene
from harness.studies import engines
from harness.studies import sweep as sweeps
from harness.studies.bench import Case, report

KAVZ = {"w1": "engine.w", "w2": "load.w", "a1": "engine.a", "a2": "load.a", "tau1": "coupling.tau1",
        "tau2": "coupling.tau2", "U12": "coupling.U12"}


def _error(rms):
    return {"rms": rms, "max": 2 * rms, "rms_relative": rms, "max_relative": 2 * rms}


def test_the_engines_table_and_lines_name_the_signals_as_the_traces_do(tmp_path):
    spec = scene.load("kavz685")
    row = {"engine": "lever", "runs": "ours", "master_error": "third order", "step_s": 1e-3, "ok": True,
           "failure": None, "wall_time_s": 1.5, "steps": 10,
           "errors": {"engine.w": _error(1e-4), "load.w": _error(2e-4), "coupling.tau1": _error(3e-4),
                      "coupling.tau2": _error(4e-4)}}
    assert engines._line(row, engines.shown(spec)) == ("lever          RMS error engine.w 0.0100 %, coupling.tau2 "
                                                       "0.0400 %, run time 1.500 s")
    md, js = engines.write(tmp_path, spec, [row])
    assert "| engine | what runs | engine.w error % | coupling.tau2 error % |" in md.read_text()
    assert "| `lever` | ours | 0.01 (0.02) | 0.04 (0.08) |" in md.read_text()
    assert set(json.loads(js.read_text())[0]["errors"]) == {"engine.w", "load.w", "coupling.tau1", "coupling.tau2"}


def _case(x, **result):
    values = {f"A_{k}": 1.0 + x * (1.0 + i) for i, k in enumerate(("w1", "w2", "a1", "a2", "tau1", "tau2"))}
    values.update({f"mean_{k}": 30.0 for k in ("w1", "w2", "a1", "a2", "tau1", "tau2")},
                  mean_w=30.0, mean_tau=100.0 + x, dA_w=x, dA_a=x, dA_tau=x, unevenness_1=0.1, unevenness_2=0.2)
    return {"axis": "load", "x": x, "value": [x, 1.0], "result": {"status": "ok", **values, **result}}


def test_the_sweeps_files_name_the_signals_as_the_traces_do(tmp_path):
    axes = sweeps.select(["load"])
    cases = [_case(x) for x in (100.0, 150.0, 225.4, 350.0)]
    internal = {"scene": "kavz685", "stop": None, "cases": cases, "trends": sweeps.trends(axes, cases)}
    public = sweeps.write(tmp_path, axes, internal, KAVZ)
    written = json.loads((tmp_path / "sweep.json").read_text())
    assert written == json.loads(json.dumps(public))          # the file is what the caller gets
    result = written["cases"][0]["result"]
    assert {"A_engine.w", "A_load.w", "A_engine.a", "A_load.a", "A_coupling.tau1", "A_coupling.tau2",
            "mean_coupling.tau2", "unevenness_engine.w", "unevenness_load.w", "dA_tau", "mean_w"} <= set(result)
    assert not [k for k in result if re.search(r"_(w|a|tau)?[12]$", k)], result       # no monograph index left
    assert written["differences"]["dA_tau"] == "A_coupling.tau2 - A_coupling.tau1"
    text = json.dumps(written["trends"]) + (tmp_path / "sweep.md").read_text()
    assert "A_coupling.tau2" in text and "A_w1" not in text and "A_tau2" not in text and "unevenness_1" not in text
    assert "| value | A engine.w | A load.w | A engine.a | A load.a | A coupling.tau1 | A coupling.tau2 | mean speed |" \
        in text
    assert "Reported by the monograph: A_engine.w 100 -> 0.65" in text
    assert cases[0]["result"]["A_w1"] == 101.0                # the report computed on is left as it was


def test_another_scenes_names_are_its_own():
    names = dict(KAVZ, w1="diesel.w", tau2="joint.tau2")
    assert sweeps.signal_key("A_w1", names) == "A_diesel.w"
    assert sweeps.signal_key("smallest A_tau2 - A_tau1", names) == "smallest A_joint.tau2 - A_coupling.tau1"
    assert sweeps.signal_key("dA_tau", names) == "dA_tau" and sweeps.signal_key("A_w12", names) == "A_w12"


def test_the_bench_progress_line_says_torque_not_tau():
    case = Case("jacobi", "master", 1e-3, wall_times=[0.5], errors={"tau_rms": 1e-3}, steps=100)
    assert "torque rms    0.1000 %" in report.progress_line(case)


def test_the_run_plots_legends_name_the_signals_as_the_traces_do():
    from harness.formats import report as run_report

    legends = [legend for _, rows in run_report._angle_panels(KAVZ).values() for _, series in rows
               for _, legend in series]
    assert legends == ["coupling.U12", "-coupling.tau1 (drive)", "coupling.tau2 (driven)", "engine.w drive",
                       "load.w driven", "engine.a drive", "load.a driven",
                       "coupling.U12, the coupling's transfer function"]
