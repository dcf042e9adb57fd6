"""Real time, measured: the wall time of every step of a run (``lever run --latency``), for
users who step our FMUs in a real-time loop (hardware in the loop), where the slowest step
matters, not the mean.

The distribution (median, 99th and 99.9th percentile, maximum, the steps over the
communication step - the real-time budget), the start-up steps, and the slowest steps
explained from what was seen in them (``harness.engine.observers.StepTimer``):

* *start-up*: among the first ``STARTUP`` steps (caches, first calls, a master's history);
* *garbage collection*: a collection ran in the step (``gc.callbacks``), and took so long;
* *the host*: the process got less CPU than the step's wall time (the OS ran something
  else: involuntary context switches, CPU time well below the wall time);
* *the step's own work*: none of these - the CPU was ours all along.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.engine.observers import StepTimer
from harness.studies import trust

#: the steps counted as the start-up
STARTUP = 10
#: how many of the slowest steps are explained
SLOWEST = 10
#: a step whose CPU time is below this share of its wall time waited for the CPU
WAITED = 0.8


def analyse(timer: StepTimer, step: float, run_wall: float | None = None) -> dict:
    """The per-step wall time distribution of a run timed by ``timer`` at communication
    step ``step`` [s], its start-up steps and its slowest steps, each with why."""
    wall = np.frombuffer(timer.wall, dtype=float) if len(timer.wall) else np.empty(0)
    cpu = np.frombuffer(timer.cpu, dtype=float) if len(timer.cpu) else np.empty(0)
    switches = np.frombuffer(timer.switches, dtype=np.int_) if len(timer.switches) else np.empty(0, int)
    n = len(wall)
    if n == 0:
        return {"steps": 0}
    gc_by_step: dict[int, list[tuple[float, int]]] = {}
    for index, seconds, generation in timer.collections:
        gc_by_step.setdefault(min(index, n - 1), []).append((seconds, generation))
    steady = wall[STARTUP:] if n > STARTUP else wall
    out = {
        "steps": n, "step_s": step,
        "median_s": float(np.median(wall)), "p99_s": float(np.percentile(wall, 99)),
        "p999_s": float(np.percentile(wall, 99.9)), "max_s": float(wall.max()), "mean_s": float(wall.mean()),
        "after_startup": {"median_s": float(np.median(steady)), "p99_s": float(np.percentile(steady, 99)),
                          "p999_s": float(np.percentile(steady, 99.9)), "max_s": float(steady.max())},
        "over_step": int((wall > step).sum()),
        "over_step_after_startup": int((steady > step).sum()),
        "startup_s": [float(x) for x in wall[:STARTUP]],
        "startup": [{"wall_s": float(wall[k]), "cpu_s": float(cpu[k]), "switches": int(switches[k]),
                     "why": _why(k, wall[k], cpu[k], switches[k], gc_by_step.get(k, []))}
                    for k in range(min(STARTUP, n))],
        # the steps' CPU time: what each would take with a core of its own
        "cpu": {"median_s": float(np.median(cpu)), "p99_s": float(np.percentile(cpu, 99)),
                "p999_s": float(np.percentile(cpu, 99.9)), "max_s": float(cpu.max()), "over_step": int((cpu > step).sum())},
        "cpu_share": float(cpu.sum() / wall.sum()) if wall.sum() > 0 else None,
        "collections": len(timer.collections),
        "collection_s": float(sum(s for _, s, _ in timer.collections)),
        "involuntary_switches": int(switches.sum()),
        "load_average": trust.load_average(), "cpus": trust.cpus(),
        "timed_s": float(wall.sum()), "run_wall_s": run_wall,
    }
    order = np.argsort(wall)[::-1][:SLOWEST]
    out["slowest"] = [{"index": int(k), "t": float(timer.times[k]), "wall_s": float(wall[k]), "cpu_s": float(cpu[k]),
                       "switches": int(switches[k]), "why": _why(int(k), wall[k], cpu[k], switches[k],
                                                                gc_by_step.get(int(k), []))}
                      for k in order]
    out["why_counts"] = {}
    for row in out["slowest"]:
        for reason in row["why"].split("; "):
            key = reason.split(":")[0]
            out["why_counts"][key] = out["why_counts"].get(key, 0) + 1
    return out


def _why(index: int, wall: float, cpu: float, switches: int, collections: list[tuple[float, int]]) -> str:
    reasons = []
    if index < STARTUP:
        reasons.append(f"start-up: step {index + 1} of the run")
    if collections:
        seconds = sum(s for s, _ in collections)
        reasons.append(f"garbage collection: generation {max(g for _, g in collections)}, "
                       f"{seconds * 1e3:.2f} ms of the step")
    if cpu < WAITED * wall:
        reasons.append(f"the host: the process had the CPU {100 * cpu / wall:.0f} % of the step"
                       + (f" ({switches} involuntary context switch{'es' if switches != 1 else ''})"
                          if switches else ""))
    if not reasons:
        reasons.append("the step's own work: the CPU was the process's all along"
                       + (f" ({switches} involuntary context switch{'es' if switches != 1 else ''})"
                          if switches else ""))
    return "; ".join(reasons)


def _us(x: float) -> str:
    return f"{x * 1e6:.0f} us" if x < 1e-3 else f"{x * 1e3:.2f} ms"


def table(report: dict, title: str = "") -> str:
    """The latency report in Markdown."""
    if not report.get("steps"):
        return "No step was timed.\n"
    r, a = report, report["after_startup"]
    load = f"load average {r['load_average']:.2f} on {r['cpus']} CPUs" if r.get("load_average") is not None else ""
    lines = [f"# Step latency{': ' + title if title else ''}", "",
             f"{r['steps']} steps of {r['step_s'] * 1e3:g} ms; wall time of each step (the master, the FMU calls, "
             f"recording and checks), {load} at the end.  The process had the CPU "
             f"{100 * (r['cpu_share'] or 0):.0f} % of the steps' wall time; {r['collections']} garbage "
             f"collection(s) in the loop ({r['collection_s'] * 1e3:.1f} ms in all); {r['involuntary_switches']} "
             "involuntary context switches.", "",
             "| | median | p99 | p99.9 | max | steps over the step (real-time budget) |", "|---|---|---|---|---|---|",
             f"| all steps | {_us(r['median_s'])} | {_us(r['p99_s'])} | {_us(r['p999_s'])} | {_us(r['max_s'])} | "
             f"{r['over_step']} of {r['steps']} |",
             f"| after the first {len(r['startup_s'])} | {_us(a['median_s'])} | {_us(a['p99_s'])} | "
             f"{_us(a['p999_s'])} | {_us(a['max_s'])} | {r['over_step_after_startup']} |",
             f"| CPU time of each step (a core of its own) | {_us(r['cpu']['median_s'])} | {_us(r['cpu']['p99_s'])} | "
             f"{_us(r['cpu']['p999_s'])} | {_us(r['cpu']['max_s'])} | {r['cpu']['over_step']} |", "",
             "Start-up steps: " + ", ".join(_us(x) for x in r["startup_s"]) + ".", "",
             "| start-up step | wall | CPU | why |", "|---|---|---|---|",
             *(f"| {k + 1} | {_us(s['wall_s'])} | {_us(s['cpu_s'])} | {s['why']} |" for k, s in enumerate(r["startup"])),
             "",
             f"The {len(r['slowest'])} slowest steps:", "", "| step | t [s] | wall | CPU | why |", "|---|---|---|---|---|"]
    for s in r["slowest"]:
        lines.append(f"| {s['index'] + 1} | {s['t']:.4f} | {_us(s['wall_s'])} | {_us(s['cpu_s'])} | {s['why']} |")
    if r.get("run_wall_s"):
        lines += ["", f"Timed steps {r['timed_s']:.3f} s of a {r['run_wall_s']:.3f} s stepping loop "
                  "(the rest: the timer's own reads)."]
    return "\n".join(lines) + "\n"


def write(out: Path, report: dict, title: str = "") -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    (out / "latency.json").write_text(json.dumps(report, indent=1, default=_plain))
    (out / "latency.md").write_text(table(report, title))
    return [out / "latency.md", out / "latency.json"]


def _plain(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    raise TypeError(type(x))


def summary_lines(report: dict) -> list[str]:
    """What ``lever run --latency`` prints."""
    if not report.get("steps"):
        return ["  latency: no step was timed"]
    r = report
    return [f"  step latency: median {_us(r['median_s'])}, p99 {_us(r['p99_s'])}, p99.9 {_us(r['p999_s'])}, "
            f"max {_us(r['max_s'])}; {r['over_step']} of {r['steps']} steps over {r['step_s'] * 1e3:g} ms",
            "  start-up steps: " + ", ".join(_us(x) for x in r["startup_s"][:5])
            + ("" if math.isnan(r["max_s"]) else f"; slowest: {r['slowest'][0]['why']}")]


def report(out: Path, timer: StepTimer, result) -> list[str]:
    """A timed run (``simulate(observer=timer)``'s ``result``) analysed, written to ``out``
    (latency.md, latency.json), and what to print."""
    analysed = analyse(timer, result.step, result.wall_time)
    paths = write(out, analysed, f"{result.scene.name}, master {result.master}")
    return summary_lines(analysed) + [f"  latency table: {paths[0]}"]
