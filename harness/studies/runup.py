"""The no-load run-up next to the monograph's statement (Fig. 4.6a: the drive shaft reaches
its steady state in 0.42 s, n1 = 374.8 rpm, n2 = 372.6 rpm): which engine gets
there, from rest and from idle.  ``lever study runup`` (or ``python -m harness.studies.runup``) prints the table that
docs/models-and-fmus.md ("Run-up") quotes; ``--scan`` the lag scan behind the chosen Te.

Every row is the model's exact (monolithic) solution of a scene: kavz685_runup_rest /
kavz685_runup_idle as committed, or with the engine overridden.  Settling: the time after
which the speed stays within 2 % of its final value (the mean over the run's last five
whole revolutions of the driven shaft, what a revolution counter reads)."""
from __future__ import annotations

import argparse
import math

import numpy as np

from harness.description import scene as scenes
from harness.judges import monolithic, revolutions

MONOGRAPH = {"settle_s": 0.42, "n1_rpm": 374.8, "n2_rpm": 372.6}
RPM = 30.0 / math.pi
BAND = 0.02
STEP = 1e-3

#: today's engine: the line (3.23) answering at once
LINE = ["engine.characteristic=linear", "engine.torque_lag=0"]

#: (label, scene, overrides[, stop [s]])
ROWS = [
    ("line M1 - K1*w, no lag, from idle (today's engine)", "kavz685_runup_idle", LINE),
    ("line M1 - K1*w, no lag, from rest", "kavz685_runup_rest", LINE),
    ("Fig. 3.9 table, no lag, from rest", "kavz685_runup_rest", ["engine.torque_lag=0"]),
    ("line M1 - K1*w, lag Te, from rest", "kavz685_runup_rest", ["engine.characteristic=linear"], 4.0),
    ("Fig. 3.9 table, lag Te, from rest (kavz685_runup_rest)", "kavz685_runup_rest", []),
    ("Fig. 3.9 table, lag Te, from idle (kavz685_runup_idle)", "kavz685_runup_idle", []),
]


def runup(name: str, overrides: list[str] = (), stop: float | None = None) -> dict:
    """Settling times and final speeds of one run-up (the scene's monolithic solution)."""
    spec = scenes.load(name).with_overrides(list(overrides) + ([f"experiment.stop={stop}"] if stop else []))
    stop = spec.experiment.stop
    times = np.arange(0.0, stop + STEP / 2, STEP)
    ref = monolithic.solve(spec, times)
    w1, w2, phi2 = ref.traces["engine.w"], ref.traces["load.w"], ref.traces["load.phi"]
    phi1 = ref.traces["engine.phi"]
    n1, n2 = revolutions.mean_speed(times, phi1, 5), revolutions.mean_speed(times, phi2, 5)
    return {"settle1_s": revolutions.settling_time(times, w1, n1, BAND),
            "settle2_s": revolutions.settling_time(times, w2, n2, BAND),
            "n1_rpm": n1 * RPM, "n2_rpm": n2 * RPM, "peak1_rpm": float(np.max(w1)) * RPM,
            "lag_s": float(spec.components["engine"].parameters.get("torque_lag", 0.0))}


def table() -> list[tuple[str, dict]]:
    return [(label, runup(name, overrides, *stop)) for label, name, overrides, *stop in ROWS]


def markdown(rows) -> str:
    lines = ["| engine, start | Te [s] | engine.w settles [s] | load.w settles [s] | n1 [rpm] | n2 [rpm] | peak n1 [rpm] |",
             "|---|---|---|---|---|---|---|",
             f"| **monograph** (Fig. 4.6a) | - | {MONOGRAPH['settle_s']} | - | {MONOGRAPH['n1_rpm']} | "
             f"{MONOGRAPH['n2_rpm']} | - |"]
    for label, r in rows:
        lines.append(f"| {label} | {r['lag_s']:g} | {r['settle1_s']:.3f} | {r['settle2_s']:.3f} | {r['n1_rpm']:.1f} | "
                     f"{r['n2_rpm']:.1f} | {r['peak1_rpm']:.1f} |")
    return "\n".join(lines)


def scan(lags) -> str:
    lines = ["| Te [s] | engine.w settles [s] | load.w settles [s] | peak n1 [rpm] |", "|---|---|---|---|"]
    for lag in lags:
        r = runup("kavz685_runup_rest", [f"engine.torque_lag={lag}"])
        lines.append(f"| {lag:g} | {r['settle1_s']:.3f} | {r['settle2_s']:.3f} | {r['peak1_rpm']:.1f} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scan", nargs="*", type=float, help="settling times of kavz685_runup_rest at these lags [s]")
    args = parser.parse_args(argv)
    print(scan(args.scan) if args.scan is not None else markdown(table()))


if __name__ == "__main__":
    main()
