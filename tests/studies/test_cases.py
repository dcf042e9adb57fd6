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


def _square_or_fail(x):
    if x == 3:
        raise ValueError("three is refused")
    if x == 4:
        import os
        os._exit(1)             # a worker the OS kills: the pool breaks
    return {"status": "ok", "value": x * x}


def _pool_run(tmp_path, xs, passes=()):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from harness.studies.cases import collect
    log, recorded = CaseLog(tmp_path, {"study": "pool"}), {}
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        futures = {pool.submit(_square_or_fail, x): x for x in xs}
        collect(pool, futures, log, str, lambda error: {"status": FAILED, "error": str(error)},
                lambda x, result: recorded.__setitem__(x, result), passes)
    return recorded


def test_a_pool_collects_every_case_and_a_failure_does_not_cost_the_others(tmp_path):
    recorded = _pool_run(tmp_path, [1, 2, 3, 5])
    assert {x: r.get("value") for x, r in recorded.items()} == {1: 1, 2: 4, 3: None, 5: 25}
    assert recorded[3] == {"status": FAILED, "error": "three is refused"}


def test_a_broken_pool_ends_the_collection_only_for_a_caller_that_resubmits(tmp_path):
    import pytest
    from concurrent.futures.process import BrokenProcessPool

    # recorded as failed for a caller that does not resubmit (the sweep) ...
    recorded = _pool_run(tmp_path / "a", [1, 4])
    assert recorded[1]["value"] == 1 and recorded[4]["status"] == FAILED
    # ... passed on to one that does (the stability map)
    with pytest.raises(BrokenProcessPool):
        _pool_run(tmp_path / "b", [1, 4], passes=(BrokenProcessPool,))


def test_a_fingerprint_with_a_set_is_the_same_in_every_process(tmp_path):
    """A scene's features are a set, whose order follows the interpreter's string hashing,
    which changes from process to process: a log written by one `lever bench` must be
    resumed by the next, not set aside."""
    import subprocess
    import sys

    program = ("import sys; from pathlib import Path; from harness.studies.cases import CaseLog; "
               "log = CaseLog(Path(sys.argv[1]), {'features': {'plots', 'reference', 'energy_balance', 'stream'}}); "
               "print(log.set_aside)")
    seen = [subprocess.run([sys.executable, "-c", program, str(tmp_path)], capture_output=True, text=True, check=True,
                           env={"PYTHONHASHSEED": str(seed), "PATH": "/usr/bin:/bin"}).stdout.strip()
            for seed in range(1, 7)]
    assert seen == ["None"] * 6, seen


def _mark_and_sleep(folder, x):
    import os
    import time
    from pathlib import Path
    (Path(folder) / f"started-{x}").write_text(str(os.getpid()))
    time.sleep(600)             # a long case: only a terminated worker ends before it
    return {"status": "ok", "value": x}


def _gone(pid: int) -> bool:
    from pathlib import Path
    status = Path(f"/proc/{pid}/status")
    try:
        return "zombie" in status.read_text().lower()
    except FileNotFoundError:
        return True


def test_stopping_a_pool_ends_its_workers_under_way_and_logs_their_cases(tmp_path):
    """Ctrl-C in a study: the workers are terminated at once, not waited for to finish the
    case they run (a study whose cases take minutes would otherwise ignore Ctrl-C for
    minutes); the cases under way are logged as interrupted, the queued ones not at all.
    The pool's ``with`` block is left only after the check: its exit waits for the workers,
    which would hide a ``stop_pool`` that no longer ends them."""
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    from harness.studies.cases import INTERRUPTED, stop_pool

    log = CaseLog(tmp_path / "log", {"study": "stop"})
    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork"))
    workers = []
    try:
        futures = {pool.submit(_mark_and_sleep, str(tmp_path), x): x for x in range(5)}
        deadline = time.monotonic() + 120.0
        while len(list(tmp_path.glob("started-*"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        started = sorted(int(p.name.split("-")[1]) for p in tmp_path.glob("started-*"))
        assert started == [0, 1]
        workers = [int(p.read_text()) for p in tmp_path.glob("started-*")]
        stop_pool(pool, futures, log, str)
        deadline = time.monotonic() + 60.0         # a terminated worker ends in milliseconds
        while not all(_gone(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert all(_gone(pid) for pid in workers), "the workers were left running their cases"
        entries = [json.loads(line) for line in log.path.read_text().splitlines()[1:]]
        assert sorted(e["key"] for e in entries) == ["0", "1"]
        assert all(e["result"]["status"] == INTERRUPTED for e in entries)
    finally:
        import os
        import signal
        for pid in workers:         # a failed check must not leave sleepers behind
            if not _gone(pid):
                os.kill(pid, signal.SIGKILL)
        pool.shutdown(wait=True, cancel_futures=True)
