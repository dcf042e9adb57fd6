"""What the benchmark claims, computed from the cases (never asserted): each curve's time at
the target error, the headline ratios (best master over the baseline and over the
monolithic solution, a baseline step over the do-nothing floor) from the side-by-side
rounds, the harness's overhead above the FMU-call floor, the largest stable baseline
step; and what is no result, with the machine's noise (``harness.studies.trust``): too few
runs, a floor above the step it bounds, a time split that cannot be."""
from __future__ import annotations

import math
import statistics as stats

from harness.description import scene_kinds
from harness.description import scene as scenes
from harness.engine import masters as master_family
from harness.judges import metrics
from harness.studies import trust
from harness.studies.bench import floors, master_time
from harness.studies.bench.schedule import Case

#: the monolithic engines (``timing.run_monolithic``): scipy's DOP853 and CVODE
MONOLITHIC = ("monolithic", "monolithic-cvode")


def case_noise(case: Case, problems: list[str] | None = None) -> str:
    """The machine's noise around a case, in words (its load and the spread of its runs);
    for ``problems`` that are only fewer runs than asked, the load alone (a long case stops
    repeating on an idle machine too)."""
    loads = [x for x in case.load if x is not None]
    load = {"cpus": trust.cpus(), "load_min": min(loads), "load_max": max(loads)} if loads else None
    if problems and all(p.startswith("from ") for p in problems):
        said = trust.noise(load, None)
        return "the machine" + (said[said.index(" ("):] if " (" in said else "")
    return trust.noise(load, trust.spread(case.wall_times))


def split_case(case: Case):
    """A master's time split: the master's share measured directly (``case.timed``, every
    call of its own runs timed), the time in the calls split into crossing and slave by
    the do-nothing twins' prices; a figure that cannot be quoted (runs that disagree, too
    many interrupted steps) is kept aside with the reason.  A case without that
    measurement (a case log written before it) is split from the prices measured around
    its runs, an impossible split (a share below zero, priced calls above the run time)
    kept aside with the reason."""
    if not (case.prices and case.kind == "master" and case.calls_by_kind and case.wall_times):
        return
    if case.timed is not None:
        twin_prices = floors.median_prices(case.prices["hollow"])
        case.split, problem = master_time.split(case.timed, twin_prices, case.wall)
        case.split_unreliable = f"{problem}: {case_noise(case)}" if problem else None
        return
    ours, twin_prices = floors.median_prices(case.prices["ours"]), floors.median_prices(case.prices["hollow"])
    case.split = floors.time_split(case.wall, case.calls_by_kind, ours, twin_prices)
    problems = trust.split_problems(case.split, case.wall)
    case.split_unreliable = ("; ".join(problems) + f": {case_noise(case)}") if problems else None


def headline_cases(scene: scenes.Scene, cases: list[Case], p: dict) -> list[Case]:
    """The cases the headline ratios divide: each master's and the monolithic solution's
    two runs either side of the target error (the interpolation's), the largest stable
    baseline step and the baseline at the scene's step (against the do-nothing floor).
    The fastest master's runs come first, then the monolithic solutions': the rounds run
    the cases of the headline ratio next to each other (``timing.measure_rounds``)."""
    target, baseline = p["target_error"], p["baseline"]
    by_engine = _by_engine(cases)
    reached = sorted((t, name) for name, group in by_engine.items() if name in master_family.MASTERS
                     and (t := time_at_error(group, target)) is not None)
    first = [reached[0][1]] if reached else []
    chosen: dict[str, Case] = {}
    for name in dict.fromkeys([*first, *MONOLITHIC, *by_engine]):
        if name in by_engine and (name in master_family.MASTERS or name in MONOLITHIC):
            for c in bracket(by_engine[name], target):
                chosen[c.key] = c
    stable_base = [c for c in cases if c.engine == baseline and c.kind == "master" and c.stable
                   and c.tolerance is None]
    if stable_base and eigenfrequency(scene):
        largest = max(stable_base, key=lambda c: c.step)
        chosen[largest.key] = largest
    at_step = [c for c in stable_base if c.step == scene.experiment.step and c.steps]
    if at_step:
        chosen[at_step[0].key] = at_step[0]
    return list(chosen.values())


def eigenfrequency(scene: scenes.Scene) -> float | None:
    """The coupling mode's eigenfrequency estimate [rad/s]; None for a scene of another kind."""
    try:
        built = scene_kinds.physics(scene)
    except scene_kinds.NotADriveline:
        return None
    i1, i2 = metrics.inertias(scene)
    return built.coupling.eigen_estimate(i1, i2)[0]


def bracket(cases: list[Case], target: float, key: str = "tau_rms") -> list[Case]:
    """The runs a curve's time at ``target`` is read from: the cheapest run at or below
    the target and the dearest cheaper run above it (if any); [] when no run reaches it."""
    points = sorted((c.wall, c.errors[key], k) for k, c in enumerate(cases) if c.stable and key in c.errors)
    good = [p for p in points if p[1] <= target]
    if not good:
        return []
    w1, e1, k1 = min(good)
    worse = [p for p in points if p[1] > target and p[0] < w1]
    if not worse:
        return [cases[k1]]
    w0, e0, k0 = max(worse)
    return [cases[k1]] if e0 <= e1 else [cases[k1], cases[k0]]


def interpolate(target: float, good: tuple[float, float], worse: tuple[float, float] | None = None) -> float:
    """Run time at ``target`` between (time, error) points either side: log-log."""
    w1, e1 = good
    if worse is None or worse[1] <= e1:
        return w1
    w0, e0 = worse
    x = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return math.exp(math.log(w0) + x * (math.log(w1) - math.log(w0)))


def time_at_error(cases: list[Case], target: float, key: str = "tau_rms") -> float | None:
    """Run time at which a master's curve reaches ``target``: log-log interpolation
    between the cheapest run at or below it and the dearest run above it (None when no
    run reaches it)."""
    pair = bracket(cases, target, key)
    if not pair:
        return None
    return interpolate(target, *((c.wall, c.errors[key]) for c in pair))


def _by_engine(cases: list[Case]) -> dict[str, list[Case]]:
    by_engine: dict[str, list[Case]] = {}
    for case in cases:
        by_engine.setdefault(case.engine, []).append(case)
    return by_engine


def _round_times(group: list[Case], target: float, walls: dict[str, list[float]]) -> list[float] | None:
    """A curve's time at the target in each round (its bracket's runs of that round)."""
    pair = bracket(group, target)
    if not pair or any(c.key not in walls for c in pair):
        return None
    series = [walls[c.key] for c in pair]
    return [interpolate(target, *((w[k], c.errors["tau_rms"]) for w, c in zip(series, pair)))
            for k in range(min(len(w) for w in series))]


def _unpaired(a: float | None, b: float | None) -> dict | None:
    """A ratio of two medians measured apart (no rounds): said so, never as a spread."""
    if not a or not b:
        return None
    return {"median": a / b, "min": None, "max": None, "n": 0, "ratios": [], "single_run": False,
            "interleaved": False}


def claims(scene: scenes.Scene, cases: list[Case], p: dict, hollow_per_step: float | None = None,
           rounds: dict | None = None, machine: dict | None = None) -> dict:
    """What the benchmark shows, computed from the cases (not asserted).  Each headline
    ratio is the median of the ratios of ``rounds`` (the cases it divides, run side by side
    round after round: ``measure_rounds``) with their range; without rounds, the ratio of
    the two medians, marked as not measured side by side."""
    target = p["target_error"]
    by_engine = _by_engine(cases)
    at_target = {name: time_at_error(group, target) for name, group in by_engine.items()}
    walls = (rounds or {}).get("walls") or {}
    per_round = {name: _round_times(group, target, walls) for name, group in by_engine.items()}

    def ratio(a: str | Case, b: str | Case, a_value=None, b_value=None) -> dict | None:
        sa = per_round.get(a) if isinstance(a, str) else walls.get(a.key)
        sb = per_round.get(b) if isinstance(b, str) else walls.get(b.key)
        if sa and sb and len(sa) == len(sb):
            return {**trust.paired_ratio(sa, sb), "interleaved": True}
        return _unpaired(a_value, b_value)

    baseline = p["baseline"]
    base_time = at_target.get(baseline)
    ranked = sorted(((t, n) for n, t in at_target.items() if t is not None and n in master_family.MASTERS))
    out = {"target_error": target, "time_at_target_s": at_target, "baseline": baseline, "ratios": {},
           "machine": machine,
           "time_at_target_side_by_side": {n: trust.spread(t) for n, t in per_round.items() if t}}
    if ranked:
        best_time, best = ranked[0]
        out["best_master"] = best
        r = ratio(baseline, best, base_time, best_time) if base_time else None
        out["speedup_over_baseline"] = r["median"] if r else None
        out["ratios"]["speedup_over_baseline"] = r
        out["peers_at_target_s"] = {n: t for n, t in at_target.items() if n not in master_family.MASTERS}
        if at_target.get("monolithic"):
            r = ratio(best, "monolithic", best_time, at_target["monolithic"])
            out["best_master_over_monolithic"] = r["median"]
            out["ratios"]["best_master_over_monolithic"] = r
        if at_target.get("monolithic-cvode"):
            r = ratio(best, "monolithic-cvode", best_time, at_target["monolithic-cvode"])
            out["best_master_over_monolithic_cvode"] = r["median"]
            out["ratios"]["best_master_over_monolithic_cvode"] = r
    # One baseline step at the scene's step against the same calls into do-nothing FMUs,
    # taken round by round (the floor is timed in each round beside the step).
    hollow_rounds = (rounds or {}).get("hollow_floor") or []
    if hollow_per_step or hollow_rounds:
        at_step = [c for c in cases if c.engine == baseline and c.kind == "master" and c.tolerance is None
                   and c.stable and c.steps and c.step == scene.experiment.step]
        if at_step:
            case = at_step[0]
            steps_walls = walls.get(case.key)
            if steps_walls and hollow_rounds and len(steps_walls) == len(hollow_rounds):
                per_step_runs = [w / case.steps for w in steps_walls]
                r = {**trust.paired_ratio(per_step_runs, hollow_rounds), "interleaved": True}
                per_step, floor = stats.median(per_step_runs), stats.median(hollow_rounds)
            else:
                per_step, floor = case.wall / case.steps, hollow_per_step
                r = _unpaired(per_step, floor)
            b = {"step": scene.experiment.step, "per_step_s": per_step, "hollow_floor_per_step_s": floor,
                 "over_hollow_floor": r["median"], "ratio": r}
            problems = [trust.floor_problem(floor, per_step)]
            if r.get("min") is not None and r["min"] < 1.0:
                problems.append(f"in {sum(x < 1.0 for x in r['ratios'])} of {r['n']} rounds the do-nothing "
                                "floor was above the step it bounds")
            if case.split and not case.split_unreliable and not case_problems(case):
                # What our slaves do behind the calls bounds the ratio from below: a master
                # that cost nothing would still pay the crossings and the slaves' own work.
                # Both from the call prices, ours and the twins' timed back to back around
                # the case's runs (not the rounds' floor, timed at other moments).
                slave = case.split["slave"] / case.steps
                b.update({"slave_per_step_s": slave,
                          "bound_without_master": (case.split["crossing"] + case.split["slave"])
                          / case.split["crossing"]})
                problems.append(trust.bound_problem(b["bound_without_master"], r))
            elif case.split_unreliable or case.split:
                b["bound_unreliable"] = case.split_unreliable or "; ".join(case_problems(case))
            verdict = trust.judged(r["median"], problems, trust.noise(machine, trust.spread(steps_walls or [])))
            if not verdict["reliable"]:
                b["unreliable"] = verdict["reason"]
            out["baseline_step"] = b
            out["ratios"]["baseline_step_over_hollow_floor"] = r
    # Harness overhead of the fixed-step masters: each run over the replay of its own calls
    # timed just before it (the figure), and over the one-step FMU-call floor; the cases
    # whose run time is no result (``case_problems``) left out, as the table leaves them.
    overhead, own = {}, {}
    for case in cases:
        if case.kind == "master" and case.stable and case.tolerance is None and not case_problems(case):
            if case.floor_time and (o := overhead_above_floor(case)) is not None:
                overhead.setdefault(case.engine, []).append(o)
            if (r := overhead_above_own_calls(case)) is not None:
                own.setdefault(case.engine, []).append(r)
    out["overhead_above_call_floor"] = {n: stats.median(v) for n, v in overhead.items()}
    out["overhead_above_own_calls"] = {n: {"median": stats.median(r["median"] for r in v),
                                           "min": min(r["min"] for r in v), "max": max(r["max"] for r in v),
                                           "runs": sum(r["n"] for r in v), "cases": len(v)}
                                       for n, v in own.items()}
    # Stability: the largest stable step of the baseline, and which masters stay stable
    # at h * omega_n >= 5 with a bounded energy residual.
    omega = eigenfrequency(scene)
    if omega:
        stable_base = [c for c in by_engine.get(baseline, []) if c.stable and c.tolerance is None]
        if stable_base:
            largest = max(stable_base, key=lambda c: c.step)
            # the bar for the stiff case: the target reached in a tenth of this
            fractions, faster = {}, {}
            for n, t in at_target.items():
                if t is not None and n in master_family.MASTERS and n != baseline:
                    r = ratio(n, largest, t, largest.wall)
                    fractions[n] = r["median"]
                    faster[n] = ratio(largest, n, largest.wall, t)
            out["largest_stable_baseline_step"] = {"step": largest.step, "h_omega": largest.step * omega,
                                                   "wall_s": largest.wall, "runs": len(largest.wall_times),
                                                   "asked": largest.asked, "time_fraction_at_target": fractions,
                                                   "faster": faster}
            if walls.get(largest.key):
                out["largest_stable_baseline_step"]["wall_spread_side_by_side"] = trust.spread(walls[largest.key])
        large = {}
        for c in cases:
            if c.kind != "master":
                continue
            # a fixed-step run at its step; an adaptive one by the longest step it took
            step = c.step if c.tolerance is None else c.largest_step
            if step is not None and step * omega >= 5.0:
                large.setdefault(c.engine, []).append(
                    {"step": step, "h_omega": step * omega, "stable": c.stable, "tolerance": c.tolerance,
                     "energy_residual": c.energy_residual, "tau_rms": c.errors.get("tau_rms")})
        out["at_h_omega_5_or_more"] = large
    return out


def overhead_above_floor(case: Case) -> float | None:
    """A master's run time above the FMU-call floor (one step of zero-order-hold calls,
    ``floors.call_floor``, times the run's steps): the median over its runs of each run
    over the floor timed just before it (over the median floor for a case without)."""
    if not (case.steps and case.wall_times):
        return None
    if case.floor_times and len(case.floor_times) == len(case.wall_times):
        return trust.paired_ratio(case.wall_times, [f * case.steps for f in case.floor_times])["median"] - 1.0
    return case.wall / case.floor_time - 1.0 if case.floor_time else None


def overhead_above_own_calls(case: Case) -> dict | None:
    """A master's run time above the floor of its own FMI calls (``replay``), from the runs
    side by side with the replay (``replay.SideBySide``): each such run over its replay,
    less 1 - ``median``, ``min``, ``max`` over them and their number ``n``; None where not
    every run had its pair (not a fixed-step co-simulation master, a replay that failed or
    differed from the run)."""
    pairs = case.own_calls_pairs
    if not (case.wall_times and pairs and len(pairs) == len(case.wall_times)):
        return None
    r = trust.paired_ratio([run for run, _ in pairs], [replayed for _, replayed in pairs])
    return {"median": r["median"] - 1.0, "min": r["min"] - 1.0, "max": r["max"] - 1.0, "n": r["n"]}


def case_problems(case: Case) -> list[str]:
    """What makes a case's run time no result: fewer runs than asked (a failed case made
    its one run), a call floor above the step it bounds, runs faster than the replay of
    their own calls side by side (which makes the same calls and nothing else: the machine
    changed between the turns, or the replay is not the run's)."""
    problems = []
    if not case.failure and case.asked:
        problems.append(trust.runs_problem(len(case.wall_times), case.asked, max(case.wall_times, default=None)))
    if case.kind == "master" and case.floor_times and case.steps and case.wall_times:
        problems.append(trust.floor_problem(stats.median(case.floor_times), case.wall / case.steps))
    own = overhead_above_own_calls(case)
    if own is not None and own["median"] <= -0.005:         # below 0 % as the figure is quoted
        problems.append(f"the runs took {-100 * own['median']:.0f} % less than the replay of their own calls "
                        "timed side by side (the same calls and nothing else)")
    return [p for p in problems if p]
