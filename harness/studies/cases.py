"""Resumable case logs for studies made of many independent runs (``lever bench``,
``lever stability``, ``lever sweep``).

Each finished case is appended to ``cases.jsonl`` in the study's output folder as one
JSON line, flushed and synced before the next case starts, so a study killed part-way
keeps every case it finished and a re-run skips them.  A case that fails is recorded
too, with its diagnosis, and the study goes on with the others.  A case stopped by
Ctrl-C is recorded as interrupted - neither done nor failed: a re-run does it again.

The log starts with a header naming what the study depends on (its *fingerprint*: scene,
plan, versions, and the code that computes the cases: ``harness.cache.code_digest``); a log whose fingerprint differs is set aside (renamed, not deleted) and
the study starts afresh, so a resumed study never mixes results of different set-ups.
"""
from __future__ import annotations

import json
import os
import traceback
from pathlib import Path
from typing import Callable, Iterator

from harness import cache
from harness.engine import interrupt

FAILED = "failed"
#: a case stopped by Ctrl-C: logged, not done (a resumed study runs it again)
INTERRUPTED = "interrupted"


def case_key(*parts) -> str:
    """A stable text key of a case from its defining values (master, step, ...)."""
    return "|".join(f"{p:.12g}" if isinstance(p, float) else str(p) for p in parts)


class CaseLog:
    """Append-only log of a study's cases, keyed by :func:`case_key`."""

    def __init__(self, folder: Path, fingerprint: dict, resume: bool = True, name: str = "cases.jsonl"):
        self.path = Path(folder) / name
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # the code that computes the cases is part of what they depend on, whatever the study says
        self.fingerprint = json.loads(json.dumps({**fingerprint, "code": cache.code_digest()}, sort_keys=True,
                                                 default=_canonical))
        self._done: dict[str, dict] = {}
        self.set_aside: Path | None = None
        if self.path.exists():
            if resume and self._read():
                return
            self._set_aside()
        with self.path.open("w") as f:
            f.write(json.dumps({"fingerprint": self.fingerprint}) + "\n")

    def _read(self) -> bool:
        """Load the finished cases; False when the log belongs to another set-up."""
        lines = self.path.read_text().splitlines()
        try:
            header = json.loads(lines[0]) if lines else {}
        except json.JSONDecodeError:
            return False
        if header.get("fingerprint") != self.fingerprint:
            return False
        whole = 1
        for line in lines[1:]:
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                break          # a line cut short by a kill: everything before it stands
            whole += 1
            if entry["result"].get("status") == INTERRUPTED:
                self._done.pop(entry["key"], None)      # to be run again
            else:
                self._done[entry["key"]] = entry["result"]
        # Drop a torn last line so appends start on a fresh line.
        self.path.write_text("".join(line + "\n" for line in lines[:whole]))
        return True

    def _set_aside(self):
        n = 1
        while (old := self.path.with_suffix(f".old{n}.jsonl")).exists():
            n += 1
        self.path.rename(old)
        self.set_aside = old

    def __contains__(self, key: str) -> bool:
        return key in self._done

    def __len__(self) -> int:
        return len(self._done)

    def get(self, key: str) -> dict | None:
        return self._done.get(key)

    def results(self) -> Iterator[tuple[str, dict]]:
        return iter(self._done.items())

    def record(self, key: str, result: dict) -> dict:
        line = json.dumps({"key": key, "result": result}, default=_jsonable)
        with self.path.open("a") as f:
            f.write(line + "\n")
            f.flush()
            os.fsync(f.fileno())
        self._done[key] = json.loads(line)["result"]
        return self._done[key]

    def interrupted(self, key: str, time: float | None = None):
        """Log that Ctrl-C stopped case ``key`` (at simulated ``time``): not done, not
        failed - a resumed study runs it again."""
        result = {"status": INTERRUPTED} | ({"time": time} if time is not None else {})
        self.record(key, result)
        del self._done[key]

    def run(self, key: str, compute: Callable[[], dict]) -> tuple[dict, bool]:
        """The case's result, computed and recorded unless it is already in the log.

        Returns ``(result, reused)``.  An exception from ``compute`` is recorded as
        ``{"status": "failed", "error": ..., "where": ...}`` and does not propagate:
        one failed case must not cost the others.  Ctrl-C (KeyboardInterrupt, e.g.
        ``harness.engine.interrupt.Interrupted``) is logged as interrupted and propagates.
        """
        if key in self._done:
            return self._done[key], True
        try:
            result = compute()
        except KeyboardInterrupt as error:
            self.interrupted(key, getattr(error, "time", None))
            raise
        except Exception as error:  # noqa: BLE001 - a study records every failure and goes on
            frame = traceback.extract_tb(error.__traceback__)[-1]
            result = {"status": FAILED, "error": f"{type(error).__name__}: {error}",
                      "where": f"{Path(frame.filename).name}:{frame.lineno} in {frame.name}"}
        return self.record(key, result), False


def completed(futures, poll_s: float = 0.2):
    """The futures (of a process pool) as they finish, like ``as_completed``, looking at
    the Ctrl-C flag between waits: ``Interrupted`` once the finished ones are handed on."""
    from concurrent.futures import FIRST_COMPLETED, wait

    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=poll_s, return_when=FIRST_COMPLETED)
        yield from done
        interrupt.check()


def collect(pool, futures: dict, log: CaseLog, key_of: Callable, failed: Callable, record: Callable,
            passes: tuple = ()):
    """Hand each case's result to ``record(case, result)`` as its worker finishes: a case
    whose worker raised gets ``failed(error)`` instead (one failed case must not cost the
    others), except for the exceptions in ``passes``, which end the collection (a broken
    pool, for a caller that resubmits).  Ctrl-C: a worker that took it at a step logs its
    case as interrupted; then, or on Ctrl-C here, the cases under way are logged as
    interrupted and the pool is stopped (``stop_pool``) before ``Interrupted`` goes on."""
    logged = 0
    try:
        for future in completed(futures):
            case = futures[future]
            try:
                result = future.result()
            except passes:
                raise
            except KeyboardInterrupt as error:     # the worker took Ctrl-C at a step
                log.interrupted(key_of(case), getattr(error, "time", None))
                logged = 1
                raise interrupt.Interrupted() from None
            except Exception as error:  # noqa: BLE001 - e.g. a worker killed by the OS
                result = failed(error)
            record(case, result)
    except KeyboardInterrupt:
        stop_pool(pool, futures, log, key_of, logged)
        raise


def stop_pool(pool, futures: dict, log: CaseLog, key_of: Callable, logged: int = 0):
    """Ctrl-C in a study run by a process pool: log the cases under way as interrupted
    (``logged`` of them are already: a worker that took the Ctrl-C said so), drop the
    queued ones and end the workers at once (not after the queue)."""
    # concurrent.futures has no public call for it before Python 3.14 (terminate_workers);
    # taken before shutdown, which forgets the processes
    workers = list((getattr(pool, "_processes", None) or {}).values())
    # The pool marks a case running when it enters its call queue, one more than the
    # workers; the workers take them in order: the first ones are the cases under way.
    running = [case for future, case in futures.items() if future.running() and key_of(case) not in log]
    for case in running[:max(0, len(workers) - logged)]:
        log.interrupted(key_of(case))
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        if process.is_alive():
            process.terminate()


def _canonical(value):
    """A fingerprint's value as the same JSON in every process: a set as its sorted items
    (its own order changes with the interpreter's string hashing from run to run)."""
    if isinstance(value, (set, frozenset)):
        return sorted(value, key=repr)
    return str(value)


def _jsonable(value):
    """numpy scalars and arrays, paths: what case results commonly hold."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


#: communication steps of the two runs that time a study's cases before it starts
CALIBRATION_STEPS = (50, 250)


def step_cost(timed) -> tuple[float, float]:
    """``(set-up, per step)`` [s] of a kind of run, from ``timed(steps)`` (the seconds a run
    of that many communication steps takes) at ``CALIBRATION_STEPS``: the difference of the
    two is the steps' cost, the rest of the shorter run its set-up."""
    few, many = CALIBRATION_STEPS
    short, long = timed(few), timed(many)
    per_step = max(0.0, (long - short) / (many - few))
    return max(0.0, short - few * per_step), per_step


def duration_text(seconds: float, narrow: str) -> str:
    """A study's estimated time in words ("about 40 s", "about 6 min"); when it is longer
    than a minute, with how to stop and resume it and ``narrow``, how to make it shorter."""
    said = f"about {seconds:.0f} s" if seconds < 90 else f"about {seconds / 60:.0f} min"
    if seconds <= 60:
        return f"{said} (estimated)"
    return (f"{said} (estimated from runs timed just now; Ctrl-C stops it and the same command resumes; "
            f"{narrow})")
