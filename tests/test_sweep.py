"""`lever sweep`: cases run on local processes or a Dask cluster, finished and failed
cases are kept and reused, a failing case is recorded with its diagnosis, and the trend
verdicts follow from the numbers."""
from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from harness.studies import sweep as sweeps
from harness.cli import main

# Short runs: 0.6 s simulated, amplitudes after 0.2 s.
SHORT = ["experiment.transient=0.2"]


def _axes():
    return [sweeps.Axis("stiffness", "3.17", "c", [450.0, 900.0], sweeps.FIG_317, "coupling.stiffness"),
            # a damping the coupling refuses: the case fails, the others complete
            sweeps.Axis("damping", "3.17", "b", [-1.0], sweeps.FIG_317, "coupling.damping")]


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
    assert any(c["result"].get("A_w1") == 123.0 for c in again["cases"])
    assert len(log.read_text().splitlines()) == 4
    # a changed set-up does not reuse them
    fresh = sweeps.sweep(_axes()[:1], tmp_path, stop=0.5, extra=SHORT, workers=1, progress=False)
    assert all(c["result"].get("A_w1") != 123.0 for c in fresh["cases"])


def test_sweep_on_a_dask_cluster(tmp_path, fmu_dir):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        report = sweeps.sweep(_axes()[:1], tmp_path, stop=0.6, extra=SHORT, dask=cluster.scheduler_address,
                              progress=False)
    local = sweeps.run_case(sweeps.plan(_axes()[:1], stop=0.6, extra=SHORT)[0])
    results = [c["result"] for c in report["cases"]]
    assert [r["status"] for r in results] == ["ok", "ok"]
    # the same numbers as in this process: runs are deterministic wherever they run
    assert results[0]["A_tau1"] == pytest.approx(local["A_tau1"], rel=1e-12)


def _row(axis, x, **values):
    return {"axis": axis, "x": x, "result": {"status": "ok", **values}}


def test_trend_verdicts_follow_the_numbers():
    amplitudes = lambda k: {q: v * k for q, v in (("A_w1", 1), ("A_w2", 2), ("A_a1", 1), ("A_a2", 2),  # noqa: E731
                                                   ("A_tau1", 1), ("A_tau2", 2))}
    results = [_row("load", x, **amplitudes(x ** 2), mean_w=40 - x, mean_tau=x) for x in (1.0, 2.0, 3.0)]
    results += [_row("stiffness", x, **amplitudes(1.0), dA_w=1 / x, dA_a=x, dA_tau=1 / x) for x in (1.0, 2.0)]
    axes = [a for a in sweeps.default_axes() if a.name in ("load", "stiffness")]
    verdicts = {t["trend"]: t for t in sweeps.trends(axes, results)}
    assert verdicts["the drive shaft's speed, acceleration and torque fluctuate less than the driven shaft's"][
        "reproduced"] == "yes"
    assert verdicts["fluctuation amplitudes grow non-linearly with load"]["reproduced"] == "yes"
    assert verdicts["mean speed falls with load"]["reproduced"] == "yes"
    stiff = verdicts["a stiffer elastic element shrinks the drive/driven amplitude difference (dA = A2 - A1)"]
    assert stiff["reproduced"] == "partly" and stiff["holds_for"] == ["dA_w", "dA_tau"]
    # linear growth is not the monograph's non-linear growth
    linear = [_row("load", x, **amplitudes(x), mean_w=1.0, mean_tau=x) for x in (1.0, 2.0, 3.0)]
    verdicts = {t["trend"]: t for t in sweeps.trends(axes[:1], linear)}
    assert verdicts["fluctuation amplitudes grow non-linearly with load"]["reproduced"] == "no"
    assert verdicts["mean speed falls with load"]["reproduced"] == "no"


def test_lever_sweep_refuses_an_unknown_axis():
    result = CliRunner().invoke(main, ["sweep", "--axis", "colour"])
    assert result.exit_code == 2 and "unknown sweep axis colour" in result.output
