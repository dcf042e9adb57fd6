"""How far a timing taken on a shared machine can be trusted: spreads of repeated figures,
ratios taken pair by pair from interleaved runs, the machine's load, and the checks that keep
an impossible figure (a negative share, a floor above the step it bounds, a figure from
fewer runs than asked) out of a report (``lever bench``, ``lever hosts``).

A ratio of two run times measured minutes apart on a busy machine divides two different
machines; measured as pairs A B A B ..., each pair saw the same load, and the median of the
pairwise ratios with their range says how far the comparison holds.
"""
from __future__ import annotations

import math
import os
import statistics


def load_average() -> float | None:
    """The machine's one-minute load average (None where the OS has none)."""
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


def cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


class LoadLog:
    """The load averages seen while a study ran (sampled when asked: around each case)."""

    def __init__(self):
        self.samples: list[float] = []

    def sample(self) -> float | None:
        value = load_average()
        if value is not None:
            self.samples.append(value)
        return value

    def summary(self) -> dict:
        s = self.samples
        return {"cpus": cpus(), "load_min": min(s) if s else None, "load_max": max(s) if s else None,
                "load_median": statistics.median(s) if s else None, "samples": len(s)}


def spread(values) -> dict:
    """Median, min, max and count of repeated figures (NaNs left out)."""
    finite = [float(v) for v in values if v is not None and math.isfinite(v)]
    if not finite:
        return {"median": None, "min": None, "max": None, "n": 0}
    return {"median": statistics.median(finite), "min": min(finite), "max": max(finite), "n": len(finite)}


def paired_ratio(numerators, denominators) -> dict:
    """The ratio of two interleaved series, pair by pair (``numerators[k] / denominators[k]``,
    the two measured side by side): the median of the pairwise ratios, their min and max,
    how many pairs, and whether it rests on a single pair."""
    if len(numerators) != len(denominators):
        raise ValueError(f"paired_ratio: {len(numerators)} numerators against {len(denominators)} denominators")
    ratios = [a / b for a, b in zip(numerators, denominators)
              if a is not None and b is not None and math.isfinite(a) and math.isfinite(b) and b > 0]
    out = spread(ratios)
    out["ratios"] = ratios
    out["single_run"] = out["n"] == 1
    return out


def relative_spread(s: dict) -> float | None:
    """(max - min) / median of a ``spread``: 0 for steady figures."""
    if not s.get("n") or not s.get("median"):
        return None
    return (s["max"] - s["min"]) / s["median"]


#: repeats within this share of their median are steady (``noise``)
QUIET_SPREAD = 0.25


def noise(load: dict | None, figures: dict | None = None, unit: str = "s") -> str:
    """Why a figure is not to be trusted, in words: the machine's load and the spread of
    the repeated figures behind it."""
    parts = []
    if load and load.get("load_max") is not None:
        parts.append(f"load average {load['load_min']:.2f}-{load['load_max']:.2f} on {load['cpus']} CPUs")
    if figures and figures.get("n", 0) > 1:
        parts.append(f"repeats spread {_num(figures['min'], unit)}-{_num(figures['max'], unit)} "
                     f"over {figures['n']} runs")
    # an idle machine whose repeats agree is no cause: say what it was, not that it was noisy
    idle = bool(load and load.get("load_max") is not None and load["load_max"] < load.get("cpus", 1))
    steady = not (figures and figures.get("n", 0) > 1) or (relative_spread(figures) or 0.0) <= QUIET_SPREAD
    head = "not the machine's noise" if idle and steady else "machine too noisy"
    return head + (f" ({'; '.join(parts)})" if parts else "")


def _num(x: float, unit: str) -> str:
    if unit == "s" and abs(x) < 0.01:
        return f"{x * 1e6:.1f} us"
    if unit == "s":
        return f"{x:.3f} s"
    return f"{x:.3g}{unit}"


# -- the checks --------------------------------------------------------------------------------------------

def split_problems(split: dict | None, wall: float) -> list[str]:
    """What is impossible about a time split (``crossing``, ``slave``, ``master`` seconds of
    a run of ``wall`` seconds): a part below zero, parts that add up to more than the run."""
    if not split:
        return []
    problems = [f"{part} share below zero ({100 * split[part] / wall:.0f} %)"
                for part in ("crossing", "slave", "master") if split.get(part) is not None and split[part] < 0]
    priced = split.get("crossing", 0.0) + split.get("slave", 0.0)
    if priced > wall * (1 + 1e-9):
        problems.append(f"the priced calls ({priced:.3f} s) exceed the run time ({wall:.3f} s)")
    return problems


def floor_problem(floor_per_step: float | None, per_step: float | None) -> str | None:
    """A floor above the step it bounds: the calls alone cannot cost more than the step
    that makes them (and more)."""
    if floor_per_step is None or per_step is None or not (floor_per_step > 0 and per_step > 0):
        return None
    if floor_per_step > per_step:
        return (f"the call floor ({floor_per_step * 1e6:.1f} us) is above the step it bounds "
                f"({per_step * 1e6:.1f} us)")
    return None


def runs_problem(done: int, asked: int, longest: float | None = None) -> str | None:
    """A figure from fewer runs than asked (``longest``: the longest run's seconds, when a
    long run is why the repeats stopped)."""
    if done < asked:
        return f"from {done} of {asked} runs" + (f" (one took {longest:.3g} s: a long case is not repeated)"
                                                 if longest is not None else "")
    return None


def bound_problem(bound: float | None, measured: dict | None) -> str | None:
    """A lower bound above the figure it bounds: the ratio a master that cost nothing would
    reach, above the median of the whole master's measured ratios."""
    if bound is None or not measured or measured.get("median") is None:
        return None
    if bound > measured["median"]:
        return f"the bound without a master ({bound:.2f}x) is above the measured ratio ({measured['median']:.2f}x)"
    return None


def judged(value, problems: list[str], noise_text: str) -> dict:
    """A figure with its verdict: ``{"value": x, "reliable": True}`` or, with problems,
    ``{"value": None, "measured": x, "reliable": False, "reason": ...}`` - an unreliable
    figure keeps what was measured for the record, never as the value."""
    problems = [p for p in problems if p]
    if not problems:
        return {"value": value, "reliable": True}
    return {"value": None, "measured": value, "reliable": False,
            "reason": "; ".join(problems) + f": {noise_text}"}


def ratio_text(r: dict, digits: int = 2) -> str:
    """``1.31x [1.20-1.45x, 5 pairs]``; a ratio from one pair says so."""
    if not r or r.get("median") is None:
        return "not measured"
    if not r.get("n"):
        return f"{r['median']:.{digits}f}x (medians measured apart, not side by side)"
    if r["n"] == 1:
        return f"{r['median']:.{digits}f}x (a single run: no spread)"
    return f"{r['median']:.{digits}f}x [{r['min']:.{digits}f}-{r['max']:.{digits}f}x, {r['n']} pairs]"


def spread_text(s: dict, unit: str = "s") -> str:
    """``0.812 s [0.80-0.85 s]`` of a ``spread``; one run says so."""
    if not s or s.get("median") is None:
        return ""
    if s["n"] == 1:
        return f"{_num(s['median'], unit)} (1 run)"
    return f"{_num(s['median'], unit)} [{_num(s['min'], unit)}-{_num(s['max'], unit)}]"


def overlap(a: dict, b: dict) -> bool:
    """Whether two ratios' ranges overlap (the same comparison on two occasions)."""
    return a["min"] <= b["max"] and b["min"] <= a["max"]
