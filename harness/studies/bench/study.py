"""The whole benchmark, in order: the FMU-call floors (ours, the do-nothing twins'), every
case of the plan through the case log, the time splits, the side-by-side rounds of the
headline cases, the FMI 2.0 and FMI 3.0 editions side by side, and the claims."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.description import scene as scenes
from harness.engine import interrupt
from harness.judges import fmu_reference, metrics
from harness.paths import FMUS
from harness.studies import trust
from harness.studies.bench import do_nothing_twins, editions, floors, headlines, report, schedule, timing
from harness.studies.bench.schedule import Case
from harness.studies.cases import CaseLog, case_key, duration_text


#: how to make the benchmark shorter, said with its estimate; and what the estimate leaves out
NARROW = ("--only, --no-peers, --no-monolithic or --repeats make it shorter; the monolithic solutions and the "
          "side-by-side rounds come on top")


def bench(scene: scenes.Scene, repeats: int = 3, fmu_dir: Path = FMUS, only: list[str] | None = None,
          peers: bool = True, monolithic: bool = True, progress=None, out: Path | None = None,
          resume: bool = True, fmi_editions: bool = True) -> dict:
    """Run the scene's plan.  With ``out``, every finished case goes to ``out/cases.jsonl``
    as it finishes (harness.studies.cases): a benchmark killed part-way and run again resumes
    with the cases not yet done (``resume=False`` starts afresh).  Ctrl-C stops it at the
    running case's next step (logged as interrupted) with ``Interrupted``.
    ``fmi_editions``: also the FMI 2.0 and FMI 3.0 editions side by side (``editions``)."""
    with interrupt.deferred():
        return _bench(scene, repeats, fmu_dir, only, peers, monolithic, progress, out, resume, fmi_editions)


def _compare_editions(scene, p, repeats, fmu_dir, log, say) -> dict:
    """The editions' comparison under the plan's baseline master at the scene's step,
    through the case log; what stops it is said in the result."""
    why = editions.missing(scene, fmu_dir)
    if why:
        say(f"FMI 2.0 and 3.0 editions not compared: {why}")
        return {"not_compared": why}
    master, step = p["baseline"], scene.experiment.step
    say(f"FMI 2.0 and 3.0 editions side by side: floor, call prices and {master} at h = {step:g} s, "
        f"{repeats} round(s)")
    key = case_key("editions", repeats, master, step)
    try:
        return schedule.rounds_logged(log, key, lambda: editions.compare(scene, master, step, repeats, fmu_dir))
    except Exception as error:  # noqa: BLE001 - without a case log: the benchmark keeps its other results
        return {"failure": f"{type(error).__name__}: {error}"}


def _bench(scene, repeats, fmu_dir, only, peers, monolithic, progress, out, resume, fmi_editions) -> dict:
    say = progress or (lambda text: None)
    p = schedule.plan(scene, only, fmu_dir, say)
    for name, why in p["dropped"].items():
        say(f"{name} not run: {why}")
    log = CaseLog(out, schedule.fingerprint(scene, repeats, fmu_dir), resume=resume) if out is not None else None
    if log is not None and len(log):
        say(f"resuming: {len(log)} case(s) already in {log.path}")
    # the load seen by the measurements themselves (kept in the case log: a resumed
    # benchmark reports the load its cases ran under, not the load when it resumed)
    machine = trust.LoadLog()
    cases: list[Case] = []

    def take(case: Case, measure):
        case, reused = schedule.logged(log, case, measure)
        cases.append(case)
        machine.samples += [x for x in case.load if x is not None]
        say(report.progress_line(case) + ("  (from the case log)" if reused else ""))

    def floor_case(fmus: Path, name: str) -> Case:
        case = Case(name, "floor", scene.experiment.step, asked=repeats, load=[trust.load_average()])
        case.wall_times = [floors.call_floor(scene, fmu_dir=fmus) for _ in range(repeats)]
        case.load.append(trust.load_average())
        return case

    ours_case, _ = schedule.logged(log, Case("floor", "floor", scene.experiment.step),
                                   lambda: floor_case(fmu_dir, "floor"))
    machine.samples += [x for x in ours_case.load if x is not None]
    floor_per_step = ours_case.wall
    say(f"FMU-call floor: {trust.spread_text(trust.spread(ours_case.wall_times))} per communication step")
    estimate = timing.estimated_seconds(scene, p, repeats, fmu_dir, floor_per_step)
    if estimate is not None and estimate > 60:
        say(f"{len(timing.planned_runs(scene, p, repeats))} cases of masters and peers; "
            f"{duration_text(estimate, NARROW)}")
    # The same calls into do-nothing twins of the FMUs (an empty do_step behind the FMU's own
    # entry): what the crossing costs, and the other half of each master's time split.
    try:
        twins = do_nothing_twins.twins(scene, fmu_dir)
    except Exception as error:  # noqa: BLE001 - the benchmark goes on without the split
        twins = None
        say(f"do-nothing FMUs not built ({type(error).__name__}: {error}): no split of the run times")
    hollow_case = None
    if twins is not None:
        hollow_case, _ = schedule.logged(log, Case("floor-hollow", "floor", scene.experiment.step),
                                         lambda: floor_case(twins, "floor-hollow"))
        machine.samples += [x for x in hollow_case.load if x is not None]
        if hollow_case.wall_times:
            say(f"do-nothing FMU floor: {trust.spread_text(trust.spread(hollow_case.wall_times))} per "
                "communication step (same calls)")
        else:
            say(f"do-nothing FMU floor not measured ({hollow_case.failure}): no split of the run times")
            twins = hollow_case = None
    e = scene.experiment
    against = fmu_reference.described(timing.monolithic.planned(scene),
                                      np.linspace(e.start, e.stop, int(round((e.stop - e.start) / e.step)) + 1))
    say(f"errors against {against}")
    limit = p["repeats_limit_s"]
    for name, steps in p["steps"].items():
        for h in steps:
            take(Case(name, "master", h),
                 lambda name=name, h=h: timing.run_master(scene, name, h, None, repeats, fmu_dir, limit, twins))
    for name, tolerances in p["tolerances"].items():
        at = p["output_steps"].get(name, scene.experiment.step)
        for tol in tolerances:
            take(Case(name, "master", at, tol),
                 lambda name=name, tol=tol, at=at: timing.run_master(scene, name, at, tol, repeats, fmu_dir, limit,
                                                                     twins))
    if peers:
        for name, steps in p["peers"].items():
            for h in steps:
                take(Case(name, "peer", h),
                     lambda name=name, h=h: timing.run_peer(scene, name, h, repeats, fmu_dir, limit))
        for name, tolerances in p["peer_tolerances"].items():
            for tol in tolerances:
                take(Case(name, "peer", scene.experiment.step, tol),
                     lambda name=name, tol=tol: timing.run_peer(scene, name, scene.experiment.step, repeats,
                                                                fmu_dir, limit, tol))
    plan = timing.monolithic.planned(scene)
    if monolithic and not fmu_reference.monolithic_knows(plan):
        monolithic = False
        say("monolithic cases not run: the monolithic solver has no equations for this scene")
    if monolithic:
        grid = p["monolithic_step"]
        for rtol in p["monolithic"]:
            take(Case("monolithic", "monolithic", grid, rtol),
                 lambda rtol=rtol: timing.run_monolithic(scene, rtol, grid, repeats))
        for rtol in p["monolithic_cvode"]:
            take(Case(timing.MONOLITHIC_CVODE, "monolithic", grid, rtol),
                 lambda rtol=rtol: timing.run_monolithic(scene, rtol, grid, repeats, timing.MONOLITHIC_CVODE))
    for case in cases:
        headlines.split_case(case)
    # The headline comparisons, measured side by side: the cases they divide run in turn,
    # round after round, with the do-nothing floor in each round.
    chosen = headlines.headline_cases(scene, cases, p)
    rounds = None
    if chosen:
        say(f"side by side: {len(chosen)} case(s) the headline ratios divide, {repeats} round(s)")
        key = case_key("rounds", repeats, *(c.key for c in chosen))
        rounds = schedule.rounds_logged(log, key,
                                        lambda: timing.measure_rounds(scene, chosen, repeats, fmu_dir, twins))
        machine.samples += [x for x in rounds.get("load", []) if x is not None]
    compared = _compare_editions(scene, p, repeats, fmu_dir, log, say) if fmi_editions else None
    if compared is not None:
        machine.samples += [x for x in compared.get("load", []) if x is not None]
    names = metrics.signals(scene)
    return {"scene": scene.name, "plan": p, "repeats": repeats, "reference": against,
            # the signals each error column is the larger of (tau_rms: the torques', w_rms: the speeds')
            "judged": {"tau": [names["tau1"], names["tau2"]], "w": [names["w1"], names["w2"]]},
            "floor_per_step_s": floor_per_step,
            "floor_spread": trust.spread(ours_case.wall_times),
            "hollow_floor_per_step_s": hollow_case.wall if hollow_case else None,
            "hollow_floor_spread": trust.spread(hollow_case.wall_times) if hollow_case else None,
            "machine": machine.summary(), "rounds": rounds, "fmi_editions": compared,
            "eigenfrequency_rad_s": headlines.eigenfrequency(scene), "cases": cases,
            "claims": headlines.claims(scene, cases, p, hollow_case.wall if hollow_case else None, rounds=rounds,
                                       machine=machine.summary())}
