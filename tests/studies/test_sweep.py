"""`lever sweep`: cases run on local processes or a Dask cluster, finished and failed
cases are kept and reused, a failing case is recorded with its diagnosis, and the trend
verdicts follow from the numbers."""
from __future__ import annotations

import json

import pytest

from harness.studies import sweep as sweeps
from harness.studies import sweep_axes
from harness.studies.sweep_trends import NOT_JUDGED

# Short runs: 0.6 s simulated, amplitudes after 0.2 s.
SHORT = ["experiment.transient=0.2"]


def _axes():
    return [sweeps.Axis("stiffness", "3.17", "c", [450.0, 900.0], sweep_axes.FIG_317, "coupling.stiffness"),
            # a damping the coupling refuses: the case fails, the others complete
            sweeps.Axis("damping", "3.17", "b", [-1.0], sweep_axes.FIG_317, "coupling.damping")]


def test_local_sweep_keeps_failures_and_resumes(tmp_path, fmu_dir):
    report = sweeps.sweep(_axes(), tmp_path, stop=0.6, extra=SHORT, workers=2, progress=False)
    status = {(c["axis"], c["x"]): c["result"] for c in report["cases"]}
    assert status[("stiffness", 450.0)]["status"] == "ok" and status[("stiffness", 900.0)]["status"] == "ok"
    failed = status[("damping", -1.0)]
    assert failed["status"] == "failed" and "damping" in failed["error"] and "[0" in failed["error"]
    text = (tmp_path / "sweep.md").read_text()
    assert "## Failed cases" in text and "- damping = -1: " in text and failed["where"] in text
    assert (tmp_path / "sweep_stiffness.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # A re-run reuses the log: mark a finished case and see the mark come back.
    log = tmp_path / "cases.jsonl"
    lines = log.read_text().splitlines()
    assert len(lines) == 4                        # header + three cases
    entry = json.loads(lines[1])
    entry["result"]["A_w1"] = 123.0
    lines[1] = json.dumps(entry)
    log.write_text("\n".join(lines) + "\n")
    again = sweeps.sweep(_axes(), tmp_path, stop=0.6, extra=SHORT, workers=2, progress=False)
    assert any(c["result"].get("A_engine.w") == 123.0 for c in again["cases"])   # the log keeps A_w1
    assert len(log.read_text().splitlines()) == 4
    # a changed set-up does not reuse them
    fresh = sweeps.sweep(_axes()[:1], tmp_path, stop=0.5, extra=SHORT, workers=1, progress=False)
    assert all(c["result"].get("A_engine.w") != 123.0 for c in fresh["cases"])


def test_sweep_on_a_dask_cluster(tmp_path, fmu_dir):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        report = sweeps.sweep(_axes()[:1], tmp_path, stop=0.6, extra=SHORT, dask=cluster.scheduler_address,
                              progress=False)
    local = sweeps.run_case(sweeps.plan(_axes()[:1], stop=0.6, extra=SHORT)[0])
    results = [c["result"] for c in report["cases"]]
    assert [r["status"] for r in results] == ["ok", "ok"]
    # the same numbers as in this process: runs are deterministic wherever they run
    assert results[0]["A_coupling.tau1"] == pytest.approx(local["A_tau1"], rel=1e-12)


def _row(axis, x, **values):
    return {"axis": axis, "x": x, "result": {"status": "ok", **values}}


XS = (1.0, 2.0, 3.0, 4.0)
AMPLITUDES = ("A_w1", "A_w2", "A_a1", "A_a2", "A_tau1", "A_tau2")


def _case(axis, x, **values):
    """A case that ran, with every quantity a trend reads (drive below driven, flat means)."""
    base = {"A_w1": 1.0, "A_w2": 2.0, "A_a1": 1.0, "A_a2": 2.0, "A_tau1": 1.0, "A_tau2": 2.0,
            "mean_w": 30.0, "mean_tau": 100.0, "dA_w": 1.0, "dA_a": 1.0, "dA_tau": 1.0}
    return _row(axis, x, **{**base, **values})


def _grow(f):
    """Amplitudes f(x), the driven shaft's twice the drive shaft's."""
    return lambda x: {q: f(x) * (2.0 if q.endswith("2") else 1.0) for q in AMPLITUDES}


def _dA(f):
    return lambda x: {"dA_w": f(x), "dA_a": f(x), "dA_tau": f(x)}


#: each verdict of the trend report: (its axis, its title's start, values of a case at x
#: that make it true, values that make it false)
VERDICTS = {
    "drive below driven": ("load", "the drive shaft's speed",
                           lambda x: {}, lambda x: {"A_w1": 3.0, "A_a1": 3.0, "A_tau1": 3.0} if x == 3.0 else {}),
    "non-linear with load": ("load", "fluctuation amplitudes grow non-linearly with load",
                             _grow(lambda x: x ** 2), _grow(lambda x: x)),
    "non-linear with alpha": ("misalignment", "fluctuation amplitudes grow non-linearly with alpha",
                              _grow(lambda x: x ** 2), _grow(lambda x: 5 - x)),
    "mean speed falls": ("load", "mean speed falls with load",
                         lambda x: {"mean_w": 40 - x}, lambda x: {"mean_w": 40 + x}),
    "mean torque rises": ("load", "mean torque rises with load",
                          lambda x: {"mean_tau": 100 * x}, lambda x: {"mean_tau": 100 / x}),
    # the sweep's own numbers: dA_tau 0.0315 -> -0.865 over stiffness grows in size
    "stiffer shrinks |dA|": ("stiffness", "a stiffer elastic element shrinks",
                             _dA(lambda x: 1 / x), _dA(lambda x: 0.0315 - 0.2989 * (x - 1))),
    # ... and -0.899 -> -0.552 over damping shrinks
    "more damped shrinks |dA|": ("damping", "a more damped elastic element shrinks",
                                 _dA(lambda x: -0.899 + 0.1157 * (x - 1)), _dA(lambda x: x)),
    "heavier I2": ("inertia", "a heavier driven shaft (I2)",
                   lambda x: {"mean_w": 40 - x, "mean_tau": 100 + x},
                   lambda x: {"mean_w": 40 - 1e-6 * x, "mean_tau": 100 + 1e-6 * x}),
}


def _judge(axis, values):
    results = [_case(axis, x, **values(x)) for x in XS]
    return {t["trend"]: t for t in sweeps.trends(sweeps.select([axis]), results)}


def _one(verdicts, title):
    (found,) = [t for name, t in verdicts.items() if name.startswith(title)]
    return found


@pytest.mark.parametrize("verdict", list(VERDICTS))
def test_each_trend_verdict_is_yes_on_a_true_case_and_no_on_a_false_one(verdict):
    axis, title, true, false = VERDICTS[verdict]
    assert _one(_judge(axis, true), title)["reproduced"] == "yes"
    assert _one(_judge(axis, false), title)["reproduced"] == "no"


def test_a_difference_that_shrinks_in_part_is_partly_reproduced():
    values = lambda x: {"dA_w": 1 / x, "dA_a": x, "dA_tau": -1 / x}  # noqa: E731
    stiff = _one(_judge("stiffness", values), "a stiffer elastic element shrinks")
    assert stiff["reproduced"] == "partly" and stiff["holds_for"] == ["dA_w", "dA_tau"]


@pytest.mark.parametrize("verdict", list(VERDICTS))
def test_no_verdict_from_too_few_cases(verdict):
    axis, title, true, _ = VERDICTS[verdict]
    results = [_case(axis, x, **true(x)) for x in XS]
    for r in results[1:3]:
        r["result"] = {"status": "failed", "error": "SceneInvalid: not valid:\n  - a | b"}
    found = _one({t["trend"]: t for t in sweeps.trends(sweeps.select([axis]), results)}, title)
    assert found["reproduced"] == NOT_JUDGED
    assert found["numbers"].startswith(f"not judged: 2 of {len(XS)} cases ran")


def test_a_verdict_on_the_cases_that_ran_says_how_many_did():
    axis, title, true, _ = VERDICTS["mean speed falls"]
    results = [_case(axis, x, **true(x)) for x in XS]
    results[1]["result"] = {"status": "failed", "error": "boom"}
    found = _one({t["trend"]: t for t in sweeps.trends(sweeps.select([axis]), results)}, title)
    assert found["reproduced"] == "yes" and found["numbers"].endswith(f"(3 of {len(XS)} cases ran)")


def test_a_failed_cases_multi_line_error_stays_in_its_table_cell(tmp_path):
    axis = sweeps.select(["inertia"])
    results = [{"axis": "inertia", "x": x, "result": {"status": "failed", "where": "system.py:1 in f",
                                                      "error": "SceneInvalid: not valid:\n  - a | b\n  - c"}}
               for x in XS]
    sweeps.write(tmp_path, axis, {"scene": "kavz685", "cases": results, "trends": sweeps.trends(axis, results)})
    text = (tmp_path / "sweep.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| 1 |")]
    assert rows == ["| 1 | - | - | - | - | - | - | - | - | failed: SceneInvalid: not valid: - a \\| b - c "
                    "(system.py:1 in f) |"]
    assert "not judged: 0 of 4 cases ran" in text and "move by 0" not in text


def test_lever_sweep_refuses_a_stop_within_the_transient(lever, tmp_path):
    result = lever("sweep", "--axis", "inertia", "--stop", "0.5", "--out", str(tmp_path / "s"))
    assert result.exit_code == 2, result.output
    assert "--stop 0.5 s" in result.output and "experiment.transient = 2 s" in result.output
    assert "allowed: --stop > 2 s" in result.output
    assert not (tmp_path / "s").exists()         # refused before the output folder is claimed


def test_lever_sweep_refuses_an_unknown_axis(lever):
    result = lever("sweep", "--axis", "colour")
    assert result.exit_code == 2 and "unknown sweep axis colour" in result.output
