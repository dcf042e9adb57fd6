"""Fingerprints of runs: a SHA-256 of every committed scene's traces with every master,
so that a refactor can show that it changed no trace by a single bit (``lever fingerprint``,
run before and after, outputs compared with ``diff``).

The hash covers the recorded times and every recorded trace (float64 bytes, in the
scene's record order) and a failed run's message, so a run that now fails differently
also shows.  Hashes are of this machine's floating point: compare them on one machine.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from harness.engine import masters as master_family
from harness.description import scene as scenes
from harness.paths import FMUS, SCENES
from harness.engine.run import simulate


def trace_hash(times: np.ndarray, traces: dict[str, np.ndarray], failure: str | None) -> str:
    digest = hashlib.sha256(np.ascontiguousarray(times, dtype=np.float64).tobytes())
    for name, values in traces.items():
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    digest.update((failure or "").encode())
    return digest.hexdigest()


def shortened(scene: scenes.Scene, stop: float | None) -> scenes.Scene:
    """``scene`` ending at ``start + stop`` when that is sooner than its own stop (the
    start-up transient left out of statistics shortened with it: it must stay below the
    run's length); ``stop=None``: the scene's own length."""
    e = scene.experiment
    if stop is None or e.start + stop >= e.stop:
        return scene
    return scene.with_overrides([f"experiment.stop={e.start + stop!r}",
                                 f"experiment.transient={min(e.transient, stop / 2)!r}"])


def fingerprints(names: list[str] | None = None, masters: list[str] | None = None,
                 stop: float | None = None, fmu_dir: Path = FMUS):
    """Yield ``(scene, master, steps, hash)`` for every scene (default: every
    resources/scenes/*.toml) and master (default: all), run to ``stop`` seconds at most."""
    names = names or sorted(p.stem for p in SCENES.glob("*.toml"))
    masters = masters or list(master_family.MASTERS)
    for name in names:
        scene = shortened(scenes.load(name), stop)
        for master in masters:
            result = simulate(scene, master, fmu_dir=scene.fmu_dir or fmu_dir)
            yield name, master, len(result.times), trace_hash(result.times, result.traces, result.failure)
