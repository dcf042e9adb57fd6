"""A monolithic reference solution (``MonolithicSolution``: traces on the run's grid, how it
was computed) and its cache (``harness.cache``'s ``references``): solutions are stored by a
hash of everything they depend on - the scene's components, values and connections, the time
grid, the solver's settings, the code that plans and solves them and the package's version
(``harness.cache.code_digest``: every source file of the harness and of the physics) and
numpy's SIMD dispatch in use (its last bits differ between levels, which the dispatch pass
of the tests must see: docs/testing.md)."""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import cache
from harness.description import scene as scenes
from harness.engine.traces import replaced

#: the part of the cache (``harness.cache.PARTS``) the references are stored in
PART = "references"


class ReferenceUnavailable(ValueError):
    pass


@dataclass
class MonolithicSolution:
    times: np.ndarray
    traces: dict[str, np.ndarray]
    wall_time: float
    n_rhs: int
    method: str
    status: str = "ok"
    info: dict = field(default_factory=dict)


def cache_key(scene: scenes.Scene, times: np.ndarray, rtol: float, atol: float, method: str) -> str:
    payload = {
        "components": {n: {"fmu": c.fmu, "parameters": c.parameters} for n, c in sorted(scene.components.items())},
        "grid": hashlib.sha256(np.ascontiguousarray(times, dtype=float).tobytes()).hexdigest(),
        "connections": sorted(str(c) for c in scene.connections),
        "rtol": rtol, "atol": atol, "method": method,
        "code": cache.code_digest(), "simd": simd_in_use(),
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:16]


def simd_in_use() -> str:
    """numpy's dispatched SIMD levels this process runs (``NPY_DISABLE_CPU_FEATURES`` lowers them)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return " ".join(name for name in __cpu_dispatch__ if __cpu_features__.get(name))


def cache_path(scene: scenes.Scene, times, rtol, atol, method) -> Path:
    return cache.entries(PART) / f"reference-{scene.name}-{cache_key(scene, times, rtol, atol, method)}.npz"


def load_cached(path: Path) -> MonolithicSolution | None:
    """A stored reference (its ``info`` as stored, marked cached), or None."""
    if not path.exists():
        return None
    data = np.load(path, allow_pickle=False)
    meta = json.loads(str(data["meta"]))
    traces = {k: data[k] for k in data.files if k not in ("meta", "times")}
    return MonolithicSolution(data["times"], traces, meta["wall_time"], meta["n_rhs"], meta["method"],
                     info={**meta.get("info", {}), "cached": True})


def store(path: Path, reference: MonolithicSolution):
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = json.dumps({"wall_time": reference.wall_time, "n_rhs": reference.n_rhs, "method": reference.method,
                       "info": reference.info})
    # whole or not at all: a cache cut short by Ctrl-C would break every later run's reference
    with replaced(path) as temporary:
        np.savez_compressed(temporary, times=reference.times, meta=np.array(meta), **reference.traces)
