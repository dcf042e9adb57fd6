"""What one evaluation of a scene's Model Exchange FMUs costs `me-cvode`, for two folders of
FMUs side by side: ``python examples/me_point_cost.py OLD_FMU_DIR [NEW_FMU_DIR] [--scene S]
[--points N] [--rounds R]`` (NEW_FMU_DIR defaults to build/fmus, after ``make fmus``).

Build the old folder from an earlier commit (``git stash; make fmus; cp -r build/fmus
/tmp/fmus-old; git stash pop; make fmus``) to see what a change to the FMUs or their native
entry bought.  Both systems run in this process with the same master code: each round times
``--points`` right-hand sides (the time, the states, the propagation of the connected values,
the derivatives) and as many output points (the same, then the recorded outputs read) at new
points on each system in turn, so that a busy machine slows both alike; the table gives the
medians over the rounds in microseconds per point, and the ratio new/old with its spread (the
25th and 75th percentiles of the round-by-round ratios).
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine import masters
from harness.engine.system import MODEL_EXCHANGE, System
from harness.paths import FMUS


def _system(scene: str, fmu_dir: Path):
    checked = plans.check(scenes.load(scene), fmu_dir=fmu_dir)
    system = System(checked, record=list(checked.recorded), interface=MODEL_EXCHANGE)
    system.initialize()
    return system, masters.make("me-cvode", system, checked.scene.experiment.step)


def _time(system, master, points: int, offset: float) -> tuple[float, float]:
    """Seconds per right-hand side and per output point, at points no call has seen."""
    y0 = master._y.copy()
    yp = np.empty(master.nx)
    started = time.perf_counter()
    for k in range(points):
        master._rhs(offset + k * 1e-6, y0 * (1.0 + (offset + k) * 1e-12), yp)
    middle = time.perf_counter()
    for k in range(points):
        master._set_point(offset + k * 1e-6 + 5e-7, y0 * (1.0 - (offset + k) * 1e-12))
        system.propagate_with(master._recorded_reads)
    ended = time.perf_counter()
    return (middle - started) / points, (ended - middle) / points


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old", type=Path, help="a folder of FMUs to compare with")
    parser.add_argument("new", type=Path, nargs="?", default=FMUS, help="the FMUs measured (default build/fmus)")
    parser.add_argument("--scene", default="kavz685", help="the scene whose FMUs and connections are evaluated")
    parser.add_argument("--points", type=int, default=2000, help="points per round and kind (default 2000)")
    parser.add_argument("--rounds", type=int, default=15, help="rounds, interleaved (default 15)")
    args = parser.parse_args(argv)
    systems = {"old": _system(args.scene, args.old), "new": _system(args.scene, args.new)}
    times = {key: ([], []) for key in systems}
    try:
        for r in range(args.rounds):
            for key, (system, master) in systems.items():
                rhs, point = _time(system, master, args.points, float(r))
                times[key][0].append(rhs)
                times[key][1].append(point)
    finally:
        for system, _ in systems.values():
            system.free()
    print(f"scene {args.scene}: {args.rounds} rounds of {args.points} points, interleaved; us per point")
    print(f"{'':16s} {'old':>8s} {'new':>8s}   new/old [25th-75th percentile]")
    for k, label in enumerate(("right-hand side", "output point")):
        old, new = times["old"][k], times["new"][k]
        ratios = sorted(n / o for n, o in zip(new, old))
        q = statistics.quantiles(ratios, n=4)
        print(f"{label:16s} {statistics.median(old) * 1e6:8.1f} {statistics.median(new) * 1e6:8.1f}   "
              f"{statistics.median(ratios):.3f} [{q[0]:.3f}-{q[2]:.3f}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
