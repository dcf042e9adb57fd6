"""Resumable case logs for studies made of many independent runs (``lever bench``,
``lever stability``, ``lever sweep``).

Each finished case is appended to ``cases.jsonl`` in the study's output folder as one
JSON line, flushed and synced before the next case starts, so a study killed part-way
keeps every case it finished and a re-run skips them.  A case that fails is recorded
too, with its diagnosis, and the study goes on with the others.

The log starts with a header naming what the study depends on (its *fingerprint*: scene,
plan, versions); a log whose fingerprint differs is set aside (renamed, not deleted) and
the study starts afresh, so a resumed study never mixes results of different set-ups.
"""
from __future__ import annotations

import json
import os
import traceback
from pathlib import Path
from typing import Callable, Iterator

FAILED = "failed"


def case_key(*parts) -> str:
    """A stable text key of a case from its defining values (master, step, ...)."""
    return "|".join(f"{p:.12g}" if isinstance(p, float) else str(p) for p in parts)


class CaseLog:
    """Append-only log of a study's cases, keyed by :func:`case_key`."""

    def __init__(self, folder: Path, fingerprint: dict, resume: bool = True, name: str = "cases.jsonl"):
        self.path = Path(folder) / name
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fingerprint = json.loads(json.dumps(fingerprint, sort_keys=True, default=str))
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
        for line in lines[1:]:
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                break          # a line cut short by a kill: everything before it stands
            self._done[entry["key"]] = entry["result"]
        # Drop a torn last line so appends start on a fresh line.
        self.path.write_text("".join(line + "\n" for line in lines[:1 + len(self._done)]))
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

    def run(self, key: str, compute: Callable[[], dict]) -> tuple[dict, bool]:
        """The case's result, computed and recorded unless it is already in the log.

        Returns ``(result, reused)``.  An exception from ``compute`` is recorded as
        ``{"status": "failed", "error": ..., "where": ...}`` and does not propagate:
        one failed case must not cost the others.  KeyboardInterrupt does propagate.
        """
        if key in self._done:
            return self._done[key], True
        try:
            result = compute()
        except Exception as error:  # noqa: BLE001 - a study records every failure and goes on
            frame = traceback.extract_tb(error.__traceback__)[-1]
            result = {"status": FAILED, "error": f"{type(error).__name__}: {error}",
                      "where": f"{Path(frame.filename).name}:{frame.lineno} in {frame.name}"}
        return self.record(key, result), False


def _jsonable(value):
    """numpy scalars and arrays, paths: what case results commonly hold."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")
