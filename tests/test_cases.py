"""The resumable case log behind studies: finished cases survive a kill, failures are
recorded and do not stop the others, a changed set-up starts afresh."""
from __future__ import annotations

import json

import numpy as np

from harness.studies.cases import FAILED, CaseLog, case_key


def test_cases_are_kept_and_reused(tmp_path):
    calls = []

    def compute(x):
        calls.append(x)
        return {"status": "ok", "value": np.float64(x) * 2, "series": np.arange(3)}

    log = CaseLog(tmp_path, {"scene": "s", "steps": [1e-3]})
    for x in (1.0, 2.0):
        log.run(case_key("jacobi", x), lambda x=x: compute(x))
    again = CaseLog(tmp_path, {"scene": "s", "steps": [1e-3]})
    result, reused = again.run(case_key("jacobi", 1.0), lambda: compute(1.0))
    assert reused and result["value"] == 2.0 and result["series"] == [0, 1, 2]
    assert calls == [1.0, 2.0] and len(again) == 2


def test_failure_is_recorded_and_the_study_goes_on(tmp_path):
    log = CaseLog(tmp_path, {})

    def broken():
        raise ZeroDivisionError("no")

    result, _ = log.run("a", broken)
    assert result["status"] == FAILED and "ZeroDivisionError: no" in result["error"]
    assert "test_cases.py" in result["where"]
    ok, _ = log.run("b", lambda: {"status": "ok"})
    assert ok["status"] == "ok" and len(CaseLog(tmp_path, {})) == 2


def test_torn_last_line_and_changed_fingerprint(tmp_path):
    log = CaseLog(tmp_path, {"v": 1})
    log.run("a", lambda: {"status": "ok"})
    with log.path.open("a") as f:
        f.write('{"key": "b", "resu')          # killed while writing
    resumed = CaseLog(tmp_path, {"v": 1})
    assert "a" in resumed and "b" not in resumed
    resumed.run("b", lambda: {"status": "ok"})
    assert [json.loads(line)["key"] for line in resumed.path.read_text().splitlines()[1:]] == ["a", "b"]
    fresh = CaseLog(tmp_path, {"v": 2})
    assert len(fresh) == 0 and fresh.set_aside is not None and fresh.set_aside.exists()
    assert len(CaseLog(tmp_path, {"v": 2}, resume=False)) == 0


def test_case_key_is_stable():
    assert case_key("jacobi", 1e-3, 2) == "jacobi|0.001|2"
