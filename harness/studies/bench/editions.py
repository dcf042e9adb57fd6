"""The FMI 2.0 and FMI 3.0 editions of the scene's FMUs side by side: what a step of the FMI
calls alone costs with each (the FMU-call floor, ``floors.call_floor``: no master, no
recording), each call's price by component and kind (``floors.call_prices``), and the
scene's run with each edition under the same master at the same step.  Every measurement is
made for both editions in each round, the editions' order alternating from round to round,
so FMI 3.0 over FMI 2.0 is taken round by round (``trust.paired_ratio``): median [min-max]
of the rounds' ratios.  Within a round the two editions' floors, and their prices, take
turns every few hundred steps (``floors.floors_side_by_side``, ``prices_side_by_side``):
on a machine shared with other work, a pair of figures then saw the same moments.

Both editions are the same model code behind the same calls (the FMI 3.0 entry hands the
values through to the FMI 2.0 one): the difference is what the FMI 3.0 entry and the
harness's FMI 3.0 side add to each call - a run that computed other traces is said to have.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.description import scene as scenes
from harness.description.plan import fmu_path
from harness.engine import interrupt
from harness.engine.run import simulate
from harness.paths import FMUS
from harness.studies import trust
from harness.studies.bench import floors

EDITIONS = (2, 3)

#: steps of each edition's floor a round (about half a second of calls on KAVZ-685)
FLOOR_STEPS = 5000

#: steps of each edition's pricing of the calls a round
PRICE_STEPS = 2000

#: steps an edition makes before the other takes its turn (floor, prices): tens of milliseconds
CHUNK = 200


def missing(scene: scenes.Scene, fmu_dir: Path = FMUS) -> str | None:
    """Why the scene's editions cannot be compared (a component's FMU given by path has
    no other edition; an edition not built), None when they can."""
    problems = []
    for name, spec in scene.components.items():
        if scenes.is_fmu_path(spec.fmu):
            problems.append(f"{name}'s FMU is a file ({spec.fmu}), of one edition")
            continue
        for fmi in EDITIONS:
            path = fmu_path(spec.fmu, fmu_dir, fmi)
            if not path.exists():
                problems.append(f"no FMI {fmi}.0 edition of {spec.fmu} ({path})")
    return "; ".join(problems) or None


def compare(scene: scenes.Scene, master: str, step: float, repeats: int, fmu_dir: Path = FMUS) -> dict:
    """``repeats`` rounds of: the floor, the call prices and the scene's run under
    ``master`` at ``step``, each with the FMI 2.0 and the FMI 3.0 editions in turn.  What
    each edition measured (seconds) and FMI 3.0 over FMI 2.0 round by round; raises
    ``RuntimeError`` when a run fails."""
    versions = {fmi: scene.with_overrides([f"experiment.fmi={fmi}"]) for fmi in EDITIONS}
    floor_times = {fmi: [] for fmi in EDITIONS}
    prices = {fmi: [] for fmi in EDITIONS}
    runs = {fmi: [] for fmi in EDITIONS}
    steps, difference, loads = 0, 0.0, []
    for k in range(repeats):
        loads.append(trust.load_average())
        order = EDITIONS if k % 2 == 0 else EDITIONS[::-1]
        measured = floors.floors_side_by_side([versions[fmi] for fmi in order], FLOOR_STEPS, fmu_dir, step, CHUNK)
        for fmi, figure in zip(order, measured):
            floor_times[fmi].append(figure)
        measured = floors.prices_side_by_side([versions[fmi] for fmi in order], fmu_dir, PRICE_STEPS, step, CHUNK)
        interrupt.check()
        for fmi, figure in zip(order, measured):
            prices[fmi].append(figure)
        results = {}
        for fmi in order:
            results[fmi] = simulate(versions[fmi], master, step, fmu_dir)
            interrupt.check()
            if not results[fmi].ok:
                raise RuntimeError(f"{scene.name} with the FMI {fmi}.0 editions failed: {results[fmi].failure}")
            runs[fmi].append(results[fmi].wall_time)
        if k == 0:
            steps = int(results[2].counters.get("steps", 0))
            difference = _largest_difference(results[2], results[3])
    loads.append(trust.load_average())
    return {"master": master, "step": step, "repeats": repeats, "steps": steps,
            "floor_steps": FLOOR_STEPS, "price_steps": PRICE_STEPS, "chunk": CHUNK,
            "largest_trace_difference": difference, "load": loads,
            "floor": _side_by_side(floor_times),
            "prices": {name: {kind: _side_by_side({fmi: [p[name][kind] for p in prices[fmi]] for fmi in EDITIONS})
                              for kind in prices[2][0][name] if all(kind in p[name] for p in prices[3])}
                       for name in prices[2][0]},
            "run": _side_by_side(runs)}


def _side_by_side(times: dict[int, list[float]]) -> dict:
    """Each edition's figures, their spread, and FMI 3.0 over FMI 2.0 round by round."""
    return {"fmi2": trust.spread(times[2]), "fmi3": trust.spread(times[3]), "fmi2_s": times[2], "fmi3_s": times[3],
            "ratio": trust.paired_ratio(times[3], times[2])}


def _largest_difference(fmi2, fmi3) -> float:
    """The largest difference between the two runs' traces, relative to each trace's
    largest magnitude (at least 1): 0 when they are bit for bit the same."""
    if not np.array_equal(fmi2.times, fmi3.times) or fmi2.traces.keys() != fmi3.traces.keys():
        return float("inf")
    largest = 0.0
    for name, values in fmi2.traces.items():
        scale = max(1.0, float(np.max(np.abs(values))))
        largest = max(largest, float(np.max(np.abs(fmi3.traces[name] - values))) / scale)
    return largest


def markdown(editions: dict | None) -> list[str]:
    """The comparison's section of bench.md (nothing when it was not made)."""
    if not editions:
        return []
    lines = ["", "## FMI 2.0 and FMI 3.0 editions", ""]
    if editions.get("not_compared") or editions.get("failure"):
        return lines + [f"Not compared: {editions.get('not_compared') or editions['failure']}."]
    lines += [f"The same FMUs as FMI 2.0 and as FMI 3.0 (`experiment.fmi`), measured in turn in each of "
              f"{editions['repeats']} round(s), the order alternating: median [min-max] of each edition's figures, "
              "and FMI 3.0 over FMI 2.0 as the median [min-max] of the rounds' ratios.  The floor is one "
              f"communication step of the FMI calls alone ({editions['floor_steps']} steps a round, no master, no "
              f"recording); the prices are per call, each timed where it falls in the floor's step "
              f"({editions['price_steps']} steps a round; state: get, set and free an FMU state, a third of the "
              f"three); in a round the two editions' floors, and their prices, take turns every "
              f"{editions.get('chunk', '')} steps.  The run is {editions['master']} at h = {editions['step']:g} s "
              f"({editions['steps']} steps), one edition after the other.", "",
              "| what | FMI 2.0 | FMI 3.0 | FMI 3.0 / FMI 2.0 |", "|---|---|---|---|",
              _row("floor, a step", editions["floor"], "us")]
    for name, kinds in editions["prices"].items():
        for kind, figures in kinds.items():
            lines.append(_row(f"{name} {kind}, a call", figures, "us"))
    lines.append(_row(f"run ({editions['master']}, h = {editions['step']:g} s)", editions["run"], "s"))
    difference = editions["largest_trace_difference"]
    lines += ["", "The two runs' traces: " + ("bit for bit the same." if difference == 0 else
                                               f"differ by up to {difference:.3g} of a trace's largest magnitude.")]
    return lines


def _row(what: str, figures: dict, unit: str) -> str:
    """A table row: each edition's median [min-max] (``unit`` "us": seconds shown in
    microseconds) and the rounds' ratio."""
    if unit == "us":
        text = [_us(figures["fmi2"]), _us(figures["fmi3"])]
    else:
        text = [trust.spread_text(figures["fmi2"]), trust.spread_text(figures["fmi3"])]
    return f"| {what} | {text[0]} | {text[1]} | {trust.ratio_text(figures['ratio'])} |"


def _us(s: dict) -> str:
    """A spread of seconds in microseconds."""
    if s.get("median") is None:
        return "not measured"
    if s["n"] == 1:
        return f"{s['median'] * 1e6:.2f} us (1 round)"
    return f"{s['median'] * 1e6:.2f} us [{s['min'] * 1e6:.2f}-{s['max'] * 1e6:.2f}]"


def summary_lines(editions: dict | None) -> list[str]:
    """The comparison in the lines ``lever bench`` prints at the end."""
    if not editions:
        return []
    if editions.get("not_compared") or editions.get("failure"):
        return [f"  FMI 3.0 against FMI 2.0 editions not compared: {editions.get('not_compared') or editions['failure']}"]
    floor, run = editions["floor"], editions["run"]
    return [f"  FMI 3.0 / FMI 2.0 editions: floor {trust.ratio_text(floor['ratio'])} "
            f"({_us(floor['fmi3'])} against {_us(floor['fmi2'])} a step); "
            f"{editions['master']} h = {editions['step']:g} s run {trust.ratio_text(run['ratio'])} "
            f"({trust.spread_text(run['fmi3'])} against {trust.spread_text(run['fmi2'])})"]

