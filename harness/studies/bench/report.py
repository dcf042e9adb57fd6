"""The benchmark's report: a row per case (bench.csv and the tables), bench.json, bench.md
in words, the work-precision plot, and the few lines ``lever bench`` prints at the end."""
from __future__ import annotations

import csv
import json
import math
import statistics as stats
from dataclasses import asdict
from pathlib import Path

import numpy as np

from harness.description import scene as scenes
from harness.paths import RESULTS
from harness.studies import trust
from harness.studies.bench import editions
from harness.studies.bench.headlines import case_noise, case_problems, overhead_above_floor, overhead_above_own_calls
from harness.studies.bench.replay import CHUNK_STEPS
from harness.studies.bench.schedule import Case


def progress_line(case: Case) -> str:
    """A finished case in one line of ``lever bench``'s progress."""
    if case.failure:
        return f"  {case.label:34s} FAILED: {case.failure[:150]}"
    return (f"  {case.label:34s} {case.wall:8.3f} s  torque rms {100 * case.errors.get('tau_rms', math.nan):9.4f} %"
            f"  ({case.steps} steps)")


#: what the two floors a master's run is measured against are, in the report's words
OWN_CALLS_WORDS = ("a run over a replay of the very FMI calls that run made, with the same arguments, on fresh "
                   "instances of the FMUs and with nothing else - the FMUs' own cost of that run, an extrapolating "
                   "master's extra work in the shafts and extra calls included - the two timed side by side in "
                   f"turns of {CHUNK_STEPS} steps, just before each run")
CALL_FLOOR_WORDS = ("each run over one communication step of zero-order-hold calls - each FMU stepped once, one "
                    "propagation - timed just before it, times the run's steps: a master that sends more or "
                    "makes more calls shows the FMUs' extra work there too")

COLUMNS = ["engine", "kind", "step", "tolerance", "wall_median_s", "wall_min_s", "wall_max_s", "repeats", "asked",
           "load_min", "load_max", "unreliable", "steps", "rhs", "method", "fmu_calls", "rollbacks",
           "own_calls_run_s", "own_calls_floor_s", "overhead_above_own_calls", "overhead_above_own_calls_min",
           "overhead_above_own_calls_max", "own_calls_note", "floor_s", "overhead_above_call_floor",
           "tau_rms", "tau_max", "w_rms", "w_max", "tau_rms_after_transient", "w_rms_after_transient",
           "energy_residual", "calls_per_step", "crossing_s", "slave_s", "master_s", "master_per_step_s", "split_unreliable", "failure"]


def own_calls_note(case: Case) -> str | None:
    """What the floor of a case's own calls is not, in words: not measured and why, or the
    replay of a span of the run scaled to the whole (None: the whole run, replayed)."""
    o = case.own_calls
    if not o:
        return None
    if o.get("problem"):
        return f"own calls not replayed: {o['problem']}"
    if o["span_steps"] < o["steps"]:
        return (f"own calls replayed for the first {o['span_steps']} of {o['steps']} steps (the recording's "
                "bound), scaled to the run's steps")
    return None


def _own_calls_seconds(case: Case) -> dict:
    """The medians of the runs side by side with the replay of their own calls and of the
    replays (the floor), each over the whole run [s]: what the overhead divides."""
    pairs = case.own_calls_pairs
    return {"own_calls_run_s": stats.median(run for run, _ in pairs) if pairs else None,
            "own_calls_floor_s": stats.median(replayed for _, replayed in pairs) if pairs else None}


def table_row(case: Case) -> dict:
    """A case as a row of the benchmark's tables (CSV and report).  A case whose run time
    is no result (``case_problems``) says why in ``unreliable``; a split that cannot be
    (``split_case``) is left out, the reason in ``split_unreliable``."""
    problems = case_problems(case)
    overhead = overhead_above_floor(case) if case.floor_time and case.stable and not problems else None
    own = overhead_above_own_calls(case) if case.stable and not problems else None
    spread = trust.spread(case.wall_times)
    loads = [x for x in case.load if x is not None]
    split = None if case.split_unreliable or problems else case.split      # a split of no result is none
    return {"engine": case.engine, "kind": case.kind, "step": case.step, "tolerance": case.tolerance,
            "wall_median_s": case.wall, "wall_min_s": spread["min"], "wall_max_s": spread["max"],
            "repeats": len(case.wall_times), "asked": case.asked or None,
            "load_min": min(loads) if loads else None, "load_max": max(loads) if loads else None,
            "unreliable": ("; ".join(problems) + f": {case_noise(case, problems)}") if problems else None,
            "steps": case.steps, "rhs": case.rhs, "method": case.method, "fmu_calls": case.fmu_calls, "rollbacks": case.rollbacks, **_own_calls_seconds(case),
            **{f"overhead_above_own_calls{suffix}": own[key] if own else None
               for suffix, key in (("", "median"), ("_min", "min"), ("_max", "max"))},
            "own_calls_note": own_calls_note(case),
            "floor_s": case.floor_time, "overhead_above_call_floor": overhead, **{k: case.errors.get(k) for k in
                                                 ("tau_rms", "tau_max", "w_rms", "w_max", "tau_rms_after_transient",
                                                  "w_rms_after_transient")},
            "energy_residual": case.energy_residual,
            "calls_per_step": (sum(sum(k.values()) for k in case.calls_by_kind.values()) / case.steps
                               if case.calls_by_kind and case.steps else None),
            **{f"{part}_s": (split or {}).get(part) for part in ("crossing", "slave", "master")},
            "master_per_step_s": (case.timed or {}).get("master_per_step_s") if split else None,
            "split_unreliable": case.split_unreliable, "failure": case.failure}


def write(out: Path, result: dict) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    rows = [table_row(c) for c in result["cases"]]
    with open(out / "bench.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    payload = {k: v for k, v in result.items() if k != "cases"}
    payload["cases"] = rows
    (out / "bench.json").write_text(json.dumps(payload, indent=2, default=_json))
    (out / "bench.md").write_text(markdown(result, rows))
    paths = [out / "bench.csv", out / "bench.json", out / "bench.md"]
    paths.append(plot(out / "work_precision.png", result))
    return paths


def _json(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, Case):
        return asdict(x)
    raise TypeError(type(x))


def _pct(x):
    return "" if x is None or not math.isfinite(x) else f"{100 * x:.4g} %"


def machine_text(machine: dict | None) -> str:
    """The machine's load during a study, in words."""
    if not machine or machine.get("load_max") is None:
        return "Machine load not known (no load average on this system)."
    return (f"Machine: {machine['cpus']} CPUs, one-minute load average {machine['load_min']:.2f}-"
            f"{machine['load_max']:.2f} during the run (median {machine['load_median']:.2f}, "
            f"{machine['samples']} samples).")


def faster_text(r: dict | None) -> str:
    """``2.1x faster [1.9-2.3x, 3 pairs]`` or ``0.6x`` said as ``1.7x slower``."""
    if not r or r.get("median") is None:
        return "not measured"
    if r["median"] >= 1.0:
        return f"{trust.ratio_text(r, 1)} faster"
    inverse = {**r, "median": 1 / r["median"],
               "min": 1 / r["max"] if r.get("max") else None, "max": 1 / r["min"] if r.get("min") else None}
    return f"{trust.ratio_text(inverse, 1)} slower"


def _ratio(r: dict | None, digits: int = 2) -> str:
    return trust.ratio_text(r, digits)


def _judged_text(judged: dict | None) -> str:
    """Which signals the torque and speed errors are the larger of (``judged``: bench's
    ``tau``/``w`` -> the two signals' names), in words; nothing where not known."""
    if not judged:
        return ""
    return (f"; torque: the larger of {' and '.join(judged['tau'])}, speed: the larger of "
            f"{' and '.join(judged['w'])} (columns tau_* and w_* of bench.csv)")


def markdown(result: dict, rows: list[dict]) -> str:
    c = result["claims"]
    floor = result.get("floor_spread") or trust.spread([result["floor_per_step_s"]])
    hollow_floor = result.get("hollow_floor_spread")
    lines = [f"# Work-precision benchmark: {result['scene']}", "",
             f"Median [min-max] of up to {result['repeats']} repeats of the stepping loop; errors against "
             f"{result.get('reference') or 'the monolithic reference (DOP853, rtol 1e-10)'}, relative to the mean "
             "torque / speed, time-averaged RMS" + _judged_text(result.get("judged")) + ".  "
             f"FMU-call floor: {trust.spread_text(floor)} per communication step"
             + (f"; the same calls into do-nothing FMUs: {trust.spread_text(hollow_floor)}"
                if hollow_floor and hollow_floor.get("n") else "") + ".", "",
             machine_text(result.get("machine") or c.get("machine")), ""]
    if result.get("eigenfrequency_rad_s"):
        lines += [f"Coupling eigenfrequency omega_n = {result['eigenfrequency_rad_s']:.1f} rad/s.", ""]
    lines += ["| engine | step / tol | run time [min-max] | runs | steps | above own calls [least to most] | "
              "above call floor | torque RMS | torque max | speed RMS | torque RMS after transient | "
              "energy residual | note |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        setting = f"tol {r['tolerance']:g}" if r["tolerance"] is not None else f"h {r['step']:g} s"
        if r.get("unreliable"):
            wall = "unreliable"
        elif r.get("wall_min_s") is not None and r["repeats"] > 1:
            wall = f"{r['wall_median_s']:.3f} s [{r['wall_min_s']:.3f}-{r['wall_max_s']:.3f}]"
        else:
            wall = f"{r['wall_median_s']:.3f} s"
        note = "; ".join(x for x in ((r["failure"] or "")[:90], r.get("unreliable") or "",
                                     r.get("own_calls_note") or "") if x)
        own = _pct(r["overhead_above_own_calls"])
        if own and r["repeats"] > 1:
            own += f" [{_pct(r['overhead_above_own_calls_min'])} to {_pct(r['overhead_above_own_calls_max'])}]"
        runs = f"{r['repeats']}" + (f" of {r['asked']}" if r.get("asked") and r["asked"] != r["repeats"] else "")
        steps = f"{r['steps']}" + (f" ({r['rhs']} RHS)" if r.get("rhs") is not None and r["kind"] == "master" else "")
        lines.append(f"| {r['engine']} | {setting} | {wall} | {runs} | {steps} | "
                     f"{own} | {_pct(r['overhead_above_call_floor'])} | {_pct(r['tau_rms'])} | {_pct(r['tau_max'])} | "
                     f"{_pct(r['w_rms'])} | {_pct(r['tau_rms_after_transient'])} | "
                     f"{'' if r['energy_residual'] is None else format(r['energy_residual'], '.2e')} | {note} |")
    lines += ["", f"## At an RMS torque error of {_pct(c['target_error'])}", "",
              "| engine | run time (interpolated) | in the rounds side by side: median [min-max] |", "|---|---|---|"]
    side = c.get("time_at_target_side_by_side", {})
    for name, t in sorted(c["time_at_target_s"].items(), key=lambda kv: (kv[1] is None, kv[1] or 0)):
        lines.append(f"| {name} | {'not reached' if t is None else f'{t:.3f} s'} | "
                     f"{trust.spread_text(side[name]) if name in side else ''} |")
    ratios = c.get("ratios", {})
    if c.get("best_master"):
        speedup = ratios.get("speedup_over_baseline")
        lines += ["", f"Best master: **{c['best_master']}**, "
                  + (f"{faster_text(speedup)} than {c['baseline']}." if speedup else
                     f"({c['baseline']} does not reach the target).")]
        if ratios.get("best_master_over_monolithic"):
            lines[-1] += (f"  It takes {_ratio(ratios['best_master_over_monolithic'])} the time of the monolithic "
                          "solution (scipy DOP853 on the unsplit equations) at this error.")
        if ratios.get("best_master_over_monolithic_cvode"):
            lines[-1] += (f"  It takes {_ratio(ratios['best_master_over_monolithic_cvode'])} the time of CVODE on "
                          "the unsplit equations at this error.")
    methods = sorted({(r["engine"], r["method"]) for r in rows if r.get("method")})
    if methods:
        lines += ["", "Integrators: " + "; ".join(f"{engine}: {method}" for engine, method in methods) + "."]
        if c.get("ratios") is not None:
            lines += ["", "Each ratio is the median of the ratios of runs made side by side (the cases it divides "
                      "run in turn, round after round), with their range; the run times above are the cases' own "
                      "repeats, made one case after another."]
    split_rows = [r for r in rows if r.get("crossing_s") is not None or r.get("split_unreliable")
                  or (r["kind"] == "master" and r.get("unreliable") and r.get("calls_per_step"))]
    if split_rows:
        lines += ["", "## Where the time goes", "",
                  "Each master's run time split by where it went, measured in runs of the case with every FMI "
                  "call timed (the timing's own cost calibrated and taken off; steps interrupted by other "
                  "processes set aside; the least of the runs): *master* the time outside the calls (the "
                  "master's arithmetic and Python, recording, the divergence guard), its microseconds a step "
                  "beside it; the time in the calls split into *crossing*, the calls priced at the do-nothing "
                  "twins of the FMUs (their variables behind the FMU's own native entry, an empty do_step: "
                  "a set or a read our entry answers costs a twin what it costs ours; each price timed call by "
                  "call in the floor's loop at the case's step - the scene's for adaptive masters - just before "
                  "and just after the case's runs), and *slave*, the rest (our FMUs' work: the FMI glue and the "
                  "physics).  A figure that cannot be quoted (timed runs that disagree by more than a quarter, "
                  "a fifth of the steps interrupted, a correction as large as the master's time) is not shown, "
                  "the reason beside it.", "",
                  "| engine | step / tol | run time | FMI calls per step | crossing | slave | master | master a step |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in split_rows:
            setting = f"tol {r['tolerance']:g}" if r["tolerance"] is not None else f"h {r['step']:g} s"
            wall = r["wall_median_s"]
            calls = "" if r["calls_per_step"] is None else f"{r['calls_per_step']:.1f}"
            if r.get("split_unreliable"):
                parts = f"unreliable: {r['split_unreliable']} | | | "
            elif r.get("unreliable"):
                parts = "unreliable: its run time is unreliable (above) | | | "
            else:
                parts = " | ".join(f"{r[f'{part}_s']:.3f} s ({100 * r[f'{part}_s'] / wall:.0f} %)"
                                   for part in ("crossing", "slave", "master"))
                parts += (f" | {1e6 * r['master_per_step_s']:.1f} us" if r.get("master_per_step_s") is not None
                          else " | ")
            shown = "unreliable" if r.get("unreliable") else f"{wall:.3f} s"
            lines.append(f"| {r['engine']} | {setting} | {shown} | {calls} | {parts} |")
    if c.get("baseline_step"):
        b = c["baseline_step"]
        if b.get("unreliable"):
            lines += ["", f"One {c['baseline']} step at h = {b['step']:g} s against the do-nothing FMUs' floor: "
                      f"unreliable ({b['unreliable']})."]
        else:
            lines += ["", f"One {c['baseline']} step at h = {b['step']:g} s: {b['per_step_s'] * 1e6:.1f} us, "
                      f"{_ratio(b['ratio'])} the do-nothing FMUs' floor for the same calls "
                      f"({b['hollow_floor_per_step_s'] * 1e6:.1f} us, timed in each round beside the step)."]
            if "bound_without_master" in b:
                lines[-1] += (f" Our slaves' own work behind those calls (the FMI glue and the physics) takes "
                              f"{b['slave_per_step_s'] * 1e6:.1f} us a step, so even a master that cost nothing "
                              f"would take {b['bound_without_master']:.2f}x the floor.")
            elif b.get("bound_unreliable"):
                lines[-1] += " The bound without a master is not shown: its split is unreliable."
    if c.get("overhead_above_own_calls"):
        lines += ["", "Harness overhead above the floor of each run's own FMI calls (" + OWN_CALLS_WORDS
                  + "; median over the master's steps whose run time is a result [least to most over "
                  "their runs]): "
                  + ", ".join(f"{n} {_pct(v['median'])} [{_pct(v['min'])} to {_pct(v['max'])}]"
                              for n, v in c["overhead_above_own_calls"].items()) + "."]
    if c.get("overhead_above_call_floor"):
        lines += ["", "Above the one-step FMU-call floor instead (" + CALL_FLOOR_WORDS + "; median over the same "
                  "steps): "
                  + ", ".join(f"{n} {_pct(v)}" for n, v in c["overhead_above_call_floor"].items()) + "."]
    if c.get("largest_stable_baseline_step"):
        s = c["largest_stable_baseline_step"]
        side = s.get("wall_spread_side_by_side")
        short = s.get("asked") and s["runs"] < s["asked"]
        lines += ["", f"Largest stable {c['baseline']} step: {s['step']:g} s (h*omega_n = {s['h_omega']:.3g}), "
                  + (f"run time unreliable (from {s['runs']} of {s['asked']} runs)" if short
                     else f"run time {s['wall_s']:.3f} s")
                  + (f"; side by side with the masters below: {trust.spread_text(side)}" if side else "") + "."]
        faster = s.get("faster", {})
        for name, fraction in sorted(s.get("time_fraction_at_target", {}).items(), key=lambda kv: kv[1]):
            lines.append(f"- {name} reaches {_pct(c['target_error'])} RMS torque error in {fraction:.3f} of that "
                         f"run time ({faster_text(faster.get(name)) if faster.get(name) else ''}).")
    if c.get("at_h_omega_5_or_more"):
        lines += ["", "At h*omega_n >= 5 (adaptive runs: their longest step):"]
        for name, runs in c["at_h_omega_5_or_more"].items():
            for r in runs:
                setting = f"h = {r['step']:g} s" if r.get("tolerance") is None else \
                    f"tol {r['tolerance']:g}, longest step {r['step']:.3g} s"
                lines.append(f"- {name} {setting} (h*omega_n = {r['h_omega']:.2f}): "
                             + (f"stable, energy residual {r['energy_residual']:.2e}, torque RMS {_pct(r['tau_rms'])}"
                                if r["stable"] else "failed"))
    lines += editions.markdown(result.get("fmi_editions"))
    return "\n".join(lines) + "\n"


def summary_lines(result: dict) -> list[str]:
    """The benchmark's outcome in a few lines (what ``lever bench`` prints at the end)."""
    claims = result["claims"]
    lines, target = [], claims["target_error"]
    for name, t in claims["time_at_target_s"].items():
        lines.append(f"  at {100 * target:g} % RMS torque error: {name:26s} "
                     + ("not reached" if t is None else f"{t:.3f} s"))
    ratios = claims.get("ratios", {})
    if claims.get("best_master"):
        speedup = ratios.get("speedup_over_baseline")
        over = ratios.get("best_master_over_monolithic")
        lines.append(f"  best master: {claims['best_master']}"
                     + (f", {faster_text(speedup)} than {claims['baseline']}" if speedup else "")
                     + (f"; {_ratio(over)} the monolithic solution's time" if over else ""))
    if claims.get("baseline_step"):
        b = claims["baseline_step"]
        if b.get("unreliable"):
            lines.append(f"  one {claims['baseline']} step against the do-nothing floor: unreliable ({b['unreliable']})")
        else:
            lines.append(f"  one {claims['baseline']} step: {b['per_step_s'] * 1e6:.1f} us, {_ratio(b['ratio'])} "
                         f"the do-nothing FMUs' floor ({b['hollow_floor_per_step_s'] * 1e6:.1f} us, same calls)")
            if "bound_without_master" in b:
                lines.append(f"    our slaves' own work in it: {b['slave_per_step_s'] * 1e6:.1f} us; a master that "
                             f"cost nothing would take {b['bound_without_master']:.2f}x the floor")
    for case in result["cases"]:
        if case.split and case_problems(case):
            lines.append(f"  {case.label:34s} split unreliable: its run time is unreliable ({'; '.join(case_problems(case))})")
        elif case.split_unreliable:
            lines.append(f"  {case.label:34s} split unreliable: {case.split_unreliable}")
        elif case.split:
            lines.append(f"  {case.label:34s} " + ", ".join(
                f"{part} {100 * case.split[part] / case.wall:.0f} %" for part in ("crossing", "slave", "master"))
                + (f" ({1e6 * case.timed['master_per_step_s']:.1f} us a step)" if case.timed else ""))
    if claims.get("overhead_above_own_calls"):
        lines.append(f"  above the floor of its own FMI calls (the run's calls replayed alone, in turns of "
                     f"{CHUNK_STEPS} steps with the run): " + ", ".join(
            f"{n} {100 * v['median']:.0f} % [{100 * v['min']:.0f} to {100 * v['max']:.0f} %]"
            for n, v in claims["overhead_above_own_calls"].items()))
    if claims.get("overhead_above_call_floor"):
        lines.append("  above the one-step FMU-call floor (zero-order-hold calls): " + ", ".join(
            f"{n} {100 * v:.0f} %" for n, v in claims["overhead_above_call_floor"].items()))
    lines += editions.summary_lines(result.get("fmi_editions"))
    lines.append("  " + machine_text(result.get("machine")))
    return lines


def plot(path: Path, result: dict) -> Path:
    from harness.formats import plotting

    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=(11, 6), layout="constrained")
    groups: dict[str, list[Case]] = {}
    for case in result["cases"]:
        key = ({"monolithic": "monolithic (scipy DOP853)", "monolithic-cvode": "monolithic (CVODE)"}
               .get(case.engine, case.engine))
        groups.setdefault(key, []).append(case)
    repeats = 1
    for name, group in groups.items():
        # joined in the order of their setting, loosest first: sorted by run time, two points
        # whose times differ by the machine's noise swapped places and the line zig-zagged
        ran = sorted((c for c in group if c.stable and "tau_rms" in c.errors),
                     key=lambda c: -(c.tolerance if c.tolerance is not None else c.step or 0.0))
        if not ran:
            continue
        repeats = max(repeats, *(len(c.wall_times) for c in ran))
        kind = group[0].kind
        style = {"master": "-o", "peer": "--s", "monolithic": ":^"}[kind]
        line, = ax.loglog([c.wall for c in ran], [100 * c.errors["tau_rms"] for c in ran], style, label=name,
                          markersize=4)
        if kind != "monolithic":       # each point's setting, as the report's tables list them
            for c in ran:
                setting = f"tol {c.tolerance:.0e}" if c.tolerance is not None else f"{1e3 * c.step:g}" if c.step else ""
                ax.annotate(setting, (c.wall, 100 * c.errors["tau_rms"]), textcoords="offset points",
                            xytext=(3, 3), fontsize=6, color=line.get_color())
    target = result["claims"]["target_error"]
    ax.axhline(100 * target, color="grey", lw=0.8, ls="--", label=f"target error {100 * target:g} %")
    # a median only where a case was timed more than once (`--repeats 1`: each point is one run)
    ax.set_xlabel("run time of the stepping loop [s] " +
                  (f"(median of up to {repeats} repeats)" if repeats > 1 else "(one run each)"))
    ax.set_ylabel("RMS torque error [% of mean torque]")
    ax.set_title(f"Work-precision, scene {result['scene']} (numbers: the communication step in ms)")
    ax.grid(True, which="both", alpha=0.3)
    plotting.log_ticks(ax.xaxis)
    plotting.legend_outside(ax)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "bench" / scene.name
