"""``lever engines``: the same scene in every engine that runs our FMUs - our harness,
fmpy's SSP stepper, OSP libcosim (from the SSP export, and with ECCO), our container FMU
in fmpy - each judged against the monolithic reference, with its run time.

``reference_errors`` is the one place a run is judged here; it handles runs whose rows
do not start at the scene's start (fmpy.ssp records no initial row).  When the project's
validator (``lever validate``) lands, this is the function to route through it.
"""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np

from harness import peers
from harness.judges import metrics
from harness.judges import monolithic
from harness.description import scene as scenes
from harness.paths import FMUS, RESULTS
from harness.engine.run import RunResult

#: the engines compared, peers of ``harness.peers``: name -> (what runs, how its master errs)
ENGINES = {
    "lever": ("our harness, the scene's master", "the scene's master (jacobi-quadratic: third order)"),
    "lever-jacobi": ("our harness, master jacobi", "zero-order hold of the torques: first order"),
    "container": ("our container FMU (fmpy container_fmu) stepped by fmpy.simulate_fmu",
                  "Jacobi inside the container, as lever-jacobi"),
    "fmpy-ssp": ("fmpy.ssp.simulate_ssp on the SSP export",
                 "coupling torques one step late; connected inputs start at 0 (first step without torque)"),
    "libcosim-ssp": ("OSP libcosim, fixed step, CosimExecution.from_ssp_file on the SSP export",
                     "coupling torques one step late (outputs read after the step, inputs set before the next)"),
    "libcosim-ecco": ("OSP libcosim ECCO (energy tolerance 1e-3 J), bonds from the OSP ports",
                      "as libcosim fixed step, with the step adapted to the power residual"),
}
ECCO_TOLERANCE = 1e-3


def run_engine(engine: str, scene: scenes.Scene, step: float, fmu_dir: Path = FMUS) -> RunResult:
    """One run of ``scene`` in ``engine`` (a peer of ``harness.peers``) at communication
    step ``step``; an adaptive engine (ECCO) at ``ECCO_TOLERANCE``."""
    if engine not in peers.PEERS:
        raise ValueError(f"unknown engine '{engine}' (known: {', '.join(ENGINES)})")
    return peers.simulate_peer(engine, scene, step, fmu_dir, tolerance=ECCO_TOLERANCE)


def reference_errors(scene: scenes.Scene, result: RunResult) -> dict:
    """Errors of ``result`` against the monolithic reference, by the traces' signal names
    (``engine.w``, ``coupling.tau2``, ...): RMS and max, absolute and relative (torques to the mean
    torque, speeds to the mean speed), over the whole run."""
    times = result.times
    prepended = len(times) and times[0] > scene.experiment.start + 1e-12
    grid = np.concatenate([[scene.experiment.start], times]) if prepended else times
    ref = monolithic.solve(scene, grid)
    keep = slice(1, None) if prepended else slice(None)
    ref_traces = {k: v[keep] for k, v in ref.traces.items()}
    return metrics.driveline_errors(scene, times, result.traces, ref.times[keep], ref_traces,
                                    scale_reference=ref.traces)


def compare(scene: scenes.Scene, engines: list[str], step: float | None = None, repeats: int = 3,
            fmu_dir: Path = FMUS, progress=None) -> list[dict]:
    """Run ``scene`` in each engine ``repeats`` times: one row per engine with the
    errors of its first run and the median run time."""
    step = float(step or scene.experiment.step)
    rows = []
    for engine in engines:
        if engine not in ENGINES:
            raise ValueError(f"unknown engine '{engine}' (known: {', '.join(ENGINES)})")
        times, first = [], None
        for _ in range(repeats):
            result = run_engine(engine, scene, step, fmu_dir)
            if not result.ok:
                first = first or result
                break
            times.append(result.wall_time)
            first = first or result
        row = {"engine": engine, "runs": ENGINES[engine][0], "master_error": ENGINES[engine][1], "step_s": step,
               "ok": first.ok, "failure": first.failure, "wall_time_s": statistics.median(times) if times else None,
               "steps": int(first.counters.get("steps", len(first.times) - 1))}
        if first.ok:
            row["errors"] = reference_errors(scene, first)
        rows.append(row)
        if progress:
            progress(_line(row, shown(scene)))
    return rows


def shown(scene: scenes.Scene) -> tuple[str, str]:
    """The speed and the torque the progress lines and the table show: the drive shaft's
    speed and the torque on the driven shaft, as the traces name them."""
    names = metrics.signals(scene)
    return names["w1"], names["tau2"]


def _line(row: dict, signals: tuple[str, str]) -> str:
    if not row["ok"]:
        return f"{row['engine']:14s} failed: {row['failure']}"
    e = row["errors"]
    return f"{row['engine']:14s} RMS error " + ", ".join(
        f"{name} {100 * e[name]['rms_relative']:.4f} %" for name in signals) + \
        f", run time {row['wall_time_s']:.3f} s"


def table(scene: scenes.Scene, rows: list[dict]) -> str:
    """The markdown table of ``rows``."""
    e = scene.experiment
    speed, torque = shown(scene)
    lines = [f"Scene `{scene.name}`, {e.stop - e.start:g} s simulated, communication step "
             f"{rows[0]['step_s'] * 1e3:g} ms. Errors are RMS (max) against the monolithic reference, relative "
             "to the mean speed and the mean torque; run time is the median of the runs, "
             "stepping only for our harness and libcosim, everything (unpacking, instantiation) for fmpy.ssp and "
             "the container (one call each).", "",
             f"| engine | what runs | {speed} error % | {torque} error % | run time [s] | the master's error |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        if not row["ok"]:
            lines.append(f"| `{row['engine']}` | {row['runs']} | failed | failed | - | {row['failure']} |")
            continue
        err = row["errors"]

        def cell(name):
            return f"{100 * err[name]['rms_relative']:.3g} ({100 * err[name]['max_relative']:.3g})"

        lines.append(f"| `{row['engine']}` | {row['runs']} | {cell(speed)} | {cell(torque)} | "
                     f"{row['wall_time_s']:.3f} | {row['master_error']} |")
    return "\n".join(lines) + "\n"


def write(out: Path, scene: scenes.Scene, rows: list[dict]) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / "engines.md", out / "engines.json"
    md.write_text(f"# The scene in other engines\n\nWritten by `lever engines {scene.name}`.\n\n" + table(scene, rows))
    js.write_text(json.dumps(rows, indent=1, default=float))
    return [md, js]


def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "engines" / scene.name
