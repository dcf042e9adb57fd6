"""A reference made from the scene's FMUs themselves, for a scene the monolithic solver
(``harness.judges.monolithic``) has no equations for - a user's own FMU in the driveline,
say - so that a run's error can be measured for any scene.

``reference(plan, times)`` gives the best reference there is, and says which it is
(``info["source"]``, one of ``SOURCES``):

* ``monolithic``: the scene's equations solved unsplit (when the monolithic solver knows them);
* ``model-exchange``: every FMU offers Model Exchange - the ``me-cvode`` master at
  ``ME_TOLERANCE``, far below any error a co-simulation is run for; its own error estimated
  by the same run at ``ME_CHECK_TOLERANCE`` (100 times looser: the looser run's error, on the high side while CVODE converges);
* ``extrapolated``: a co-simulation master (``EXTRAPOLATED_MASTER``, or the one asked for) at
  three steps, each half the one before, and Richardson's extrapolation of the finest two with
  the master's order - taken only when the three show that order (the observed order of each
  signal within ``ORDER_SLACK`` of it); its own error estimated by the extrapolation from the
  coarser two (that extrapolation's error: on the high side in the asymptotic range).

Both kinds are computed once on a uniform grid (``grid_step``) and cached by the scene, the FMU
files, the grid, the harness's and the physics' code and the versions (as the monolithic
reference is, ``harness.judges.solution``; the cache's folder: ``harness.cache``); a run's
times are read from that grid, by a cubic spline between its points (its error estimated and
added to the reference's own).  Where none can be had, ``ReferenceUnavailable`` says why in a
sentence.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from harness import cache
from harness.description import plan as plans
from harness.description import scene_kinds
from harness.engine import masters as master_family
from harness.engine import observers
# simulate looked up at each call: a stand-in set on harness.engine.run for a while is not kept
from harness.engine import run as engine_run
from harness.judges import metrics, monolithic, rectifier
from harness.judges import solution as solutions
from harness.judges.solution import MonolithicSolution, ReferenceUnavailable, cache_key, load_cached, store

#: where a reference comes from -> how a report names it
SOURCES = {"monolithic": "monolithic", "model-exchange": "converged Model Exchange",
           "extrapolated": "extrapolated co-simulation"}
#: CVODE's relative tolerance for the Model Exchange reference, and the looser one its error is estimated by
ME_TOLERANCE = 1e-10
ME_CHECK_TOLERANCE = 1e-8
#: the co-simulation master extrapolated when a FMU offers co-simulation only (order 2, no
#: rollback: it runs FMUs that cannot restore their states)
EXTRAPOLATED_MASTER = "jacobi-linear"
#: how far (in orders) a signal's observed convergence order may lie from the master's
ORDER_SLACK = 0.5
#: a signal whose change between the two finest runs is below this share of its scale has
#: converged to round-off: it shows no order, and none is asked of it
ROUND_OFF = 1e-12
#: the reference grid: this share of the scene's step (finer than any run it judges, so that a
#: run's points are mostly on it); at most ``MAX_ROWS`` rows
GRID_SHARE = 0.25
MAX_ROWS = 400_001


def label(reference) -> str:
    """How a report names the reference ``reference`` came from ("monolithic", ...)."""
    return SOURCES[(getattr(reference, "info", None) or {}).get("source", "monolithic")]


def grid_step(plan: plans.Plan) -> float:
    """The step of the uniform grid a made reference is computed on: a whole fraction of the
    experiment, ``GRID_SHARE`` of the scene's step, at most ``MAX_ROWS`` rows."""
    e = plan.experiment
    span = e.stop - e.start
    rows = min(MAX_ROWS - 1, math.ceil(span / (GRID_SHARE * e.step) - 1e-9))
    return span / rows


def monolithic_knows(plan: plans.Plan) -> bool:
    """Whether the monolithic solver has the scene's equations (``monolithic.SOLVERS``)."""
    return plan.kind == "rectifier" or plan.driveline_problem is None


def described(plan: plans.Plan, times) -> str:
    """The reference ``plan``'s runs are judged against, in a sentence (its source, method and
    own error), or why there is none."""
    try:
        ref = reference(plan, np.asarray(times, dtype=float))
    except ReferenceUnavailable as error:
        return f"no reference, so no errors: {error}"
    return f"the {label(ref)} reference ({quality(ref, own_error(plan.scene, ref))})"


def offers_model_exchange(plan: plans.Plan) -> bool:
    return all(getattr(md, "modelExchange", None) is not None for md in plan.descriptions.values())


def reference(plan: plans.Plan, times: np.ndarray, use_cache: bool = True, source: str | None = None,
              master: str | None = None) -> MonolithicSolution:
    """The reference of ``plan`` at ``times`` (see the module's text), its source in
    ``info["source"]``, its own error estimate in ``info["check"]`` (a second solution at
    ``times``: the distance between the two is the estimate).  ``source``: one of ``SOURCES``
    (None: the best the scene has); ``master``: the extrapolated reference's master."""
    if source not in (None, *SOURCES):
        raise ValueError(f"source {source!r}: one of {', '.join(SOURCES)}")
    problems = []
    if source in (None, "monolithic"):
        try:
            solved = monolithic.solve(plan, times, use_cache=use_cache)
            solved.info.setdefault("source", "monolithic")
            return solved
        except ReferenceUnavailable as error:
            if source == "monolithic":
                raise
            problems.append(str(error))
    made = None
    if source in (None, "model-exchange") and offers_model_exchange(plan):
        try:
            made = _cached(plan, "model-exchange", None, use_cache, _model_exchange)
        except ReferenceUnavailable as error:
            if source == "model-exchange":
                raise
            problems.append(str(error))         # the extrapolated co-simulation may still be had
    elif source == "model-exchange":
        bare = [name for name, md in plan.descriptions.items() if getattr(md, "modelExchange", None) is None]
        raise ReferenceUnavailable(f"{', '.join(bare)} offer{'s' if len(bare) == 1 else ''} co-simulation only: "
                                   "no Model Exchange reference")
    if made is None:
        try:
            made = _cached(plan, "extrapolated", master or EXTRAPOLATED_MASTER, use_cache, _extrapolated)
        except ReferenceUnavailable as error:
            if problems and source is None:
                raise ReferenceUnavailable(f"{'; '.join(problems[1:] + [str(error)])}") from None
            raise
    made.info.setdefault("why_not_monolithic", problems[0] if problems else "")
    return _at(made, np.asarray(times, dtype=float))


# -- the two made references, on the grid --------------------------------------------------------

def _grid_run(plan, master, step, options=None):
    result = engine_run.simulate(plan, master, step, options=options or {})
    if not result.ok:
        raise ReferenceUnavailable(f"the reference's run ({master}, step {step:g} s) failed: {result.failure}")
    return result


def _model_exchange(plan: plans.Plan, _master) -> MonolithicSolution:
    h = grid_step(plan)
    fine = _grid_run(plan, "me-cvode", h, {"tolerance": ME_TOLERANCE})
    check = _grid_run(plan, "me-cvode", h, {"tolerance": ME_CHECK_TOLERANCE})
    return MonolithicSolution(fine.times, fine.traces, fine.wall_time + check.wall_time,
                              int(fine.counters.get("rhs") or 0), f"me-cvode rtol={ME_TOLERANCE:g}",
                              info={"source": "model-exchange", "check": check.traces,
                                    "estimate_by": f"the same run at rtol={ME_CHECK_TOLERANCE:g}"})


def _extrapolated(plan: plans.Plan, master: str) -> MonolithicSolution:
    cls = master_family.master_class(master)
    if cls.adaptive or not cls.order:
        raise ReferenceUnavailable(f"master '{master}' has no fixed convergence order to extrapolate with "
                                   "(an adaptive or Model Exchange master)")
    h = grid_step(plan)
    runs = [_grid_run(plan, master, h / 2 ** k) for k in range(3)]
    n = len(runs[0].times)
    levels = []
    for k, run in enumerate(runs):
        rows = run.traces
        levels.append({name: np.asarray(values, dtype=float)[::2 ** k][:n] for name, values in rows.items()})
    if any(len(v) != n for level in levels for v in level.values()):
        raise ReferenceUnavailable("the reference's runs at halved steps do not share the coarsest run's grid")
    p = cls.order
    gain = 2.0 ** p - 1.0
    coarse, middle, fine = levels
    extrapolated = {k: fine[k] + (fine[k] - middle[k]) / gain for k in fine}
    check = {k: middle[k] + (middle[k] - coarse[k]) / gain for k in fine}
    orders = observed_orders(coarse, middle, fine)
    off = {k: o for k, o in orders.items() if o is not None and abs(o - p) > ORDER_SLACK}
    steps = ", ".join(f"{h / 2 ** k:.4g}" for k in range(3))
    if off:
        said = ", ".join(f"{k} {o:.2f}" for k, o in sorted(off.items()))
        raise ReferenceUnavailable(f"no extrapolated reference: {master} at steps {steps} s does not show its "
                                   f"order {p} (observed: {said}); the runs are not in their asymptotic range")
    return MonolithicSolution(runs[0].times, extrapolated, sum(r.wall_time for r in runs),
                              sum(int(r.counters.get("steps", 0)) for r in runs),
                              f"{master} at steps {steps} s, Richardson-extrapolated with order {p}",
                              info={"source": "extrapolated", "check": check, "master": master, "order": p,
                                    "observed_orders": orders,
                                    "estimate_by": "the extrapolation from the coarser two runs"})


def observed_orders(coarse: dict, middle: dict, fine: dict) -> dict:
    """Each signal's convergence order seen in three runs at halved steps:
    log2(|coarse - middle| / |middle - fine|) in RMS; None where the change is at round-off."""
    out = {}
    for name in fine:
        scale = metrics.rms(fine[name]) or 1.0
        first = metrics.rms(coarse[name] - middle[name])
        second = metrics.rms(middle[name] - fine[name])
        if second <= ROUND_OFF * scale or first <= ROUND_OFF * scale:
            out[name] = None
        else:
            out[name] = math.log2(first / second)
    return out


# -- cache, and a run's times read from the grid -----------------------------------------------

CHECK = "check::"


def _fmu_hash(plan: plans.Plan) -> str:
    digest = hashlib.sha256()
    for name in sorted(plan.paths):
        digest.update(name.encode() + Path(plan.paths[name]).read_bytes())
    return digest.hexdigest()[:16]


def _cache_path(plan, source, master) -> Path:
    e = plan.experiment
    grid = np.array([e.start, e.stop, grid_step(plan)])
    # cache_key holds the code of every package that makes the reference (harness.cache.code_digest)
    key = hashlib.sha256(json.dumps([cache_key(plan.scene, grid, 0.0, 0.0, f"{source} {master}"), _fmu_hash(plan),
                                     list(plan.recorded)]).encode()).hexdigest()[:16]
    return cache.entries(solutions.PART) / f"fmu-reference-{plan.name}-{key}.npz"


def expected_wait(plan: plans.Plan, run) -> str | None:
    """Before ``reference(plan, ...)`` makes a reference: what it runs and about how long that
    takes, in words - from ``run``, a run of the scene just made (its wall time per
    communication point, the FMUs' pace here): the extrapolated reference runs
    ``EXTRAPOLATED_MASTER`` at 1, 1/2 and 1/4 of the grid step (``GRID_SHARE`` of the scene's
    step), 28 times the points of a run at the scene's step; the Model Exchange one runs CVODE
    twice on the grid, its own steps as its tolerance needs (the figure is the least it
    takes).  None where it is cached and nothing is run."""
    e = plan.experiment
    h = grid_step(plan)
    model_exchange = offers_model_exchange(plan)
    source, master = ("model-exchange", None) if model_exchange else ("extrapolated", EXTRAPOLATED_MASTER)
    if _cache_path(plan, source, master).exists():
        return None
    steps = (h,) * 2 if model_exchange else (h, h / 2, h / 4)      # the runs' steps (see the module's text)
    points = sum(round((e.stop - e.start) / step) for step in steps)
    pace = run.wall_time / max(1, len(run.times) - 1)
    figure = points * pace
    said = (f"about {observers.duration(figure)}" if not model_exchange else f"{observers.duration(figure)} or more")
    runs = (f"{EXTRAPOLATED_MASTER} at steps {h:.4g}, {h / 2:.4g} and {h / 4:.4g} s" if not model_exchange else
            f"me-cvode at rtol {ME_TOLERANCE:g} and {ME_CHECK_TOLERANCE:g} on a {h:.4g} s grid")
    return (f"{said} ({runs}: {points:,} communication points, {points / max(1, len(run.times) - 1):.3g} times this "
            f"run's, at its pace of {1e3 * pace:.3g} ms a point)")


def _cached(plan, source, master, use_cache, make) -> MonolithicSolution:
    path = _cache_path(plan, source, master)
    if use_cache and (cached := load_cached(path)) is not None:
        check = {k[len(CHECK):]: v for k, v in cached.traces.items() if k.startswith(CHECK)}
        traces = {k: v for k, v in cached.traces.items() if not k.startswith(CHECK)}
        return MonolithicSolution(cached.times, traces, cached.wall_time, cached.n_rhs, cached.method,
                                  info={**cached.info, "check": check})
    made = make(plan, master)
    if use_cache:
        stored = {**made.traces, **{CHECK + k: v for k, v in made.info["check"].items()}}
        info = {k: v for k, v in made.info.items() if k != "check"}
        store(path, MonolithicSolution(made.times, stored, made.wall_time, made.n_rhs, made.method, info=info))
    return made


def _at(made: MonolithicSolution, times: np.ndarray) -> MonolithicSolution:
    """``made`` read at ``times``: its own rows where ``times`` are on its grid, a cubic
    spline between them (its error, estimated from the spline of every other row, added to
    the check's distance)."""
    grid = made.times
    if len(times) and (times[0] < grid[0] - 1e-9 or times[-1] > grid[-1] + 1e-9):
        raise ReferenceUnavailable(f"the run's times {times[0]:g} ... {times[-1]:g} s leave the reference's "
                                   f"{grid[0]:g} ... {grid[-1]:g} s")
    index = np.clip(np.searchsorted(grid, times), 0, len(grid) - 1)
    left = np.clip(index - 1, 0, len(grid) - 1)
    nearest = np.where(np.abs(grid[left] - times) < np.abs(grid[index] - times), left, index)
    on_grid = np.abs(grid[nearest] - times) <= 1e-9 * max(1.0, abs(grid[-1]))

    def read(traces):
        out = {}
        for name, values in traces.items():
            values = np.asarray(values, dtype=float)
            if on_grid.all():
                out[name] = values[nearest]
            else:
                between = CubicSpline(grid, values)(times)
                out[name] = np.where(on_grid, values[nearest], between)
        return out

    traces, check = read(made.traces), read(made.info["check"])
    if not on_grid.all():
        # the spline's error: that of a spline through every other row, at the rows it skips, / 2**4
        for name, values in made.traces.items():
            values = np.asarray(values, dtype=float)
            coarse = CubicSpline(grid[::2], values[::2])(grid)
            spread = metrics.rms(coarse - values) / 16.0
            check[name] = check[name] + spread
    info = {**made.info, "check": check, "interpolated": int((~on_grid).sum())}
    return MonolithicSolution(times, traces, made.wall_time, made.n_rhs, made.method, info=info)


# -- what the reference says about a run --------------------------------------------------------

@dataclass
class Judged:
    """A run's errors against a reference (``errors``, by signal as the scene's kind judges
    them), its error figure (the largest relative RMS error) and the reference's own figure."""
    errors: dict
    figure: float
    reference_figure: float | None


def errors(scene, times, traces, ref: MonolithicSolution, after: float | None = None) -> dict:
    """The run's errors against ``ref`` as the scene's kind judges them: the driveline's
    speeds and torques, the rectifier's main signals, else every signal both record,
    relative to its RMS in the reference."""
    if scene_kinds.kind_of(scene) == "rectifier":
        return rectifier.errors(scene, times, traces, ref)
    judged = [metrics.signals(scene)[short] for short in metrics.JUDGED]
    if all(n in traces and n in ref.traces for n in judged):
        return metrics.driveline_errors(scene, times, traces, ref.times, ref.traces, after=after)
    names = [n for n in traces if n in ref.traces]
    scales = {n: metrics.rms(np.asarray(ref.traces[n], float)) or 1.0 for n in names}
    return metrics.errors(np.asarray(times, float), traces, ref.times, ref.traces, names, scales, after)


def judge(scene, times, traces, ref: MonolithicSolution) -> Judged:
    """``errors``, the run's error figure and the reference's own (None: not estimated)."""
    found = errors(scene, times, traces, ref)
    return Judged(found, figure(found), own_error(scene, ref))


def figure(found: dict) -> float:
    """The error figure of ``errors``: the largest relative RMS error of any signal."""
    return max((e["rms_relative"] for e in found.values()), default=float("nan"))


def own_error(scene, ref: MonolithicSolution) -> float | None:
    """The reference's own error figure (its check's distance from it); None when it has no check."""
    if "check" not in ref.info:
        return None
    return figure(errors(scene, ref.times, ref.info["check"], ref))


def summary(scene, times, traces, ref: MonolithicSolution) -> dict:
    """What a run's summary holds of its error against a made reference (``error_vs_reference``,
    ``reference``: its source, method and own error)."""
    own = own_error(scene, ref)
    return {"error_vs_reference": errors(scene, times, traces, ref),
            "reference": {"source": label(ref), "method": ref.method, "wall_time_s": ref.wall_time,
                          "rhs_evaluations": ref.n_rhs, "own_error_relative": own,
                          "estimated_by": ref.info.get("estimate_by"), "quality": quality(ref, own),
                          "observed_orders": ref.info.get("observed_orders"),
                          "why_not_monolithic": ref.info.get("why_not_monolithic")}}


def quality(ref: MonolithicSolution, own: float | None) -> str:
    """How good the reference is, in words: its method and its own error estimate."""
    if own is None:
        return f"{ref.method}"
    return f"{ref.method}; its own error about {100 * own:.2g} % (RMS, relative: {ref.info['estimate_by']})"
