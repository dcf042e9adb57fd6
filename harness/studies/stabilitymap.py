"""The stability map (``lever stability [SCENE]``): the scene run over coupling
stiffness, coupling damping, communication step and master, each case classified, next
to the edges the linear analysis (``harness.judges.stability``) predicts.

Each case is the scene with ``coupling.stiffness = c`` and ``coupling.damping = b``,
run at ``h = x / omega_n`` (``x`` the swept ``h * omega_n``) for ``max(min_steps,
periods * 2*pi / x)`` steps (at most ``max_steps``).  The start-up (both shafts at the
same speed, the coupling unloaded) rings the coupling mode; what a master makes of that
ringing is what is classified, from the driven-shaft coupling torque ``tau2`` and the
energy residual:

* ``divergent``: the run failed (a non-finite value, an FMU refusing a value out of its
  range, a coupling iteration that does not converge), or the torque's oscillation
  amplitude (half its range) grew more than ``GROWTH_DIVERGENT`` times from the first
  quarter of the run to the last;
* ``energy-drifting``: not divergent, but the amplitude grew more than ``GROWTH_DRIFT``
  times, or the energy residual exceeds ``ENERGY_DRIFT`` of the engine's work over the
  run (the master creates or destroys energy at a steady rate - Gauss-Seidel's
  ``c*w*h`` torque bias does);
* ``stable``: neither.

A run that cannot start (a master that rolls steps back with an FMU that keeps no state,
an FMU refusing a start value) shows nothing of stability: its case is recorded as failed.

For comparing with the linear prediction a case counts as *unstable* when it is
divergent or its amplitude grew more than ``GROWTH_DRIFT`` times (the energy residual
measures accuracy, not the growth the spectral radius predicts).  Finished and failed
cases are kept in a ``harness.studies.cases.CaseLog``; a re-run resumes.

Where the linear model cannot be made (a shaft FMU of one's own refuses its probe runs:
``port_probe.ProbeRefused``), the map is of observed runs only: no ``omega_n``, so no
``h * omega_n`` and no edges; the cases run at the scene's step times ``step_ratios``,
scaled by ``sqrt(c_scene / c)`` so that each stiffness's row covers the same range of
``h * omega_n`` whatever the unknown inertias are (``omega_n`` of the coupling mode goes
as ``sqrt(c)``), each as many steps as the scene's own run (so as many coupling periods),
and ``StabilityMap.no_prediction`` says why nothing was predicted.  With the default
ratios (0.1 ... 100) a scene whose own step is at h*omega_n of a few hundredths (as
kavz685's) is swept over the range the predicted map covers.
"""
from __future__ import annotations

import math
import multiprocessing
import time as clock
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from harness.description import scene_kinds
from harness.engine import masters as master_family
from harness.judges import metrics
from harness.description import scene as scenes
from harness.judges import coupling_scene, port_probe, stability
from harness.engine import interrupt
from harness.engine.system import CO_SIMULATION
from harness.studies.cases import CALIBRATION_STEPS, FAILED, CaseLog, case_key, collect, duration_text, step_cost
from harness.paths import FMUS, RESULTS

GROWTH_DIVERGENT = 10.0
GROWTH_DRIFT = 1.25
ENERGY_DRIFT = 1e-2
STATUSES = ("stable", "energy-drifting", "divergent")

#: Masters with a fixed communication step (the adaptive ones choose theirs; the Model
#: Exchange one splits no coupling into steps).
FIXED_STEP_MASTERS = [name for name, cls in master_family.MASTERS.items()
                      if not cls.adaptive and cls.interface == CO_SIMULATION]
#: The explicit masters: no iteration, a stability edge to compare.
EXPLICIT = [name for name in FIXED_STEP_MASTERS
            if not issubclass(master_family.MASTERS[name], master_family.IterativeMaster)]


@dataclass
class Plan:
    stiffnesses: list            # N*m/rad
    dampings: list               # N*m*s/rad
    h_omegas: list               # h * omega_n
    masters: list
    min_steps: int = 500
    periods: float = 4.0
    max_steps: int = 4000
    refine: bool = True          # also run at 0.9 and 1.1 (or more, see _above) times each predicted edge
    #: a refinement case above the edge runs long enough for the predicted growth to
    #: reach this factor (at most ``max_refine_steps``): near the edge growth is slow
    refine_growth: float = 10.0
    max_refine_steps: int = 6000
    #: a map without prediction: its steps as multiples of ``scene_step`` at ``scene_stiffness``
    #: (module docstring), and the scene's step count (its duration over its step)
    step_ratios: list = field(default_factory=lambda: [0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0])
    scene_step: float | None = None
    scene_stiffness: float | None = None
    scene_steps: int | None = None

    def steps_for(self, h_omega: float) -> int:
        return int(min(self.max_steps, max(self.min_steps, math.ceil(self.periods * 2.0 * math.pi / h_omega))))

    @property
    def predicted(self) -> bool:
        """False: the plan of a map without prediction (no linear model of the scene)."""
        return self.scene_step is None

    def observed_cases(self, master: str, stiffness: float, damping: float) -> list["Case"]:
        """A row of a map without prediction: the scene's step times each of ``step_ratios``,
        scaled by ``sqrt(scene_stiffness / stiffness)``; as many steps as the scene's own run at
        that ratio (at least ``min_steps``, at most ``max_steps``)."""
        scale = math.sqrt(self.scene_stiffness / stiffness)
        return [Case(master, stiffness, damping, None,
                     int(min(self.max_steps, max(self.min_steps, math.ceil(self.scene_steps / ratio)))),
                     step=float(f"{ratio * self.scene_step * scale:.4g}"))
                for ratio in self.step_ratios]

    def fingerprint(self, scene: scenes.Scene) -> dict:
        """What a case's result depends on besides its key (the grids are not in it: a
        denser plan reuses the cases it shares with a coarser one)."""
        return {"study": "stability", "criteria": 1, "scene": scene.name,
                "components": {n: {"fmu": c.fmu, "parameters": c.parameters} for n, c in scene.components.items()},
                "connections": [str(c) for c in scene.connections],
                "periods": self.periods, "refine_growth": self.refine_growth}


def linear_model(scene: scenes.Scene, fmu_dir: Path = FMUS, say=None) -> tuple[stability.TwoInertia | None, str]:
    """``(model, "")``: the scene's linear model (``stability.model_of``); ``(None, why)``
    where a shaft FMU refuses the probe runs it needs - the map then runs its cases
    unpredicted, and ``why`` is the sentence that says so, naming the FMU and what it refused."""
    try:
        return stability.model_of(scene, fmu_dir, say), ""
    except port_probe.ProbeRefused as refusal:
        return None, (f"No prediction was made: the scene's linear model needs its ports measured, and {refusal}; "
                      "this map shows the observed runs only.")


def default_plan(scene: scenes.Scene, dense: bool = False, fmu_dir: Path = FMUS, say=None) -> Plan:
    """The default sweep (a few minutes on 2 cores): the scene's stiffness, 1e4, 1e5 and
    1e6 N*m/rad; the scene's damping, a tenth of it and none; h*omega_n from 0.05 to 5;
    every fixed-step master.  ``dense``: 7 stiffnesses, 5 dampings, 19 steps.  Without a
    linear model (``linear_model``), the plan of a map without prediction: the same
    stiffnesses and dampings, steps from the scene's (``Plan.observed_cases``)."""
    model, _ = linear_model(scene, fmu_dir, say)
    c0, b0 = (model.stiffness, model.damping) if model is not None else coupling_scene.coupling_values(scene)
    if dense:
        stiffnesses = sorted({float(f"{c:.4g}") for c in np.geomspace(c0, 1e6, 7)})
        dampings = sorted({b0, b0 / 3.0, b0 / 10.0, b0 / 30.0, 0.0}, reverse=True)
        h_omegas = [float(f"{x:.3g}") for x in np.geomspace(0.01, 10.0, 19)]
    else:
        stiffnesses = sorted({c0, 1e4, 1e5, 1e6})
        dampings = sorted({b0, b0 / 10.0, 0.0}, reverse=True)
        h_omegas = [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0]
    plan = Plan([c for c in stiffnesses if c >= c0], dampings, h_omegas, list(FIXED_STEP_MASTERS))
    if model is None:
        experiment = scene.experiment
        plan.h_omegas, plan.refine = [], False
        plan.scene_step, plan.scene_stiffness = float(experiment.step), float(c0)
        plan.scene_steps = max(1, round((experiment.stop - experiment.start) / experiment.step))
        if dense:
            plan.step_ratios = [float(f"{r:.3g}") for r in np.geomspace(0.03, 300.0, 17)]
    return plan


@dataclass(frozen=True)
class Case:
    master: str
    stiffness: float
    damping: float
    h_omega: float | None        # None in a map without prediction: omega_n is not known
    steps: int                   # communication steps the case runs
    step: float | None = None    # the communication step [s] of a map without prediction

    @property
    def key(self) -> str:
        if self.h_omega is None:
            return case_key(self.master, self.stiffness, self.damping, "h", self.step, self.steps)
        return case_key(self.master, self.stiffness, self.damping, self.h_omega, self.steps)

    @property
    def row(self) -> tuple:
        return self.master, self.stiffness, self.damping


def predicted_growth(rho: float, steps: int) -> float:
    """The growth of the torque amplitude the classification measures (last quarter of
    the run against the first) for a spectral radius ``rho``: ``rho ** (3/4 steps)``."""
    if not math.isfinite(rho):
        return math.inf
    exponent = 0.75 * steps * math.log(rho)
    return math.exp(min(exponent, 700.0))


def predictions(model: stability.TwoInertia, plan: Plan, fmu_dir: Path = FMUS) -> dict:
    """Predicted edge ``h*omega_n`` (None: none in the analysed range) for each
    ``(master, c, b)`` of the plan."""
    return {(m, c, b): stability.stability_edge(model.with_coupling(c, b), m, fmu_dir)
            for m in plan.masters for c in plan.stiffnesses for b in plan.dampings}


def cases_of(plan: Plan, edges: dict, model: stability.TwoInertia | None, fmu_dir: Path = FMUS) -> list[Case]:
    """The plan's cases, plus (``refine``) two about each predicted edge below the
    largest swept step (at 0.9 times it and above it, see ``_above``), where the observed
    edge is judged; a map without prediction (``model`` None): ``Plan.observed_cases``."""
    if model is None:
        return [case for m in plan.masters for c in plan.stiffnesses for b in plan.dampings
                for case in plan.observed_cases(m, c, b)]
    out = []
    high = max(plan.h_omegas)
    for m in plan.masters:
        for c in plan.stiffnesses:
            for b in plan.dampings:
                out += [Case(m, c, b, x, plan.steps_for(x)) for x in plan.h_omegas]
                edge = edges.get((m, c, b))
                if not (plan.refine and edge is not None and stability.EDGE_RANGE[0] < edge < high):
                    continue
                below = float(f"{0.9 * edge:.4g}")
                out.append(Case(m, c, b, below, plan.steps_for(below)))
                out.append(_above(plan, model.with_coupling(c, b), m, edge, fmu_dir))
    return out


def _above(plan: Plan, coupling: stability.TwoInertia, master: str, edge: float, fmu_dir) -> Case:
    """The refinement case above ``edge``: at 1.1 times it, running until the predicted
    growth reaches ``refine_growth``; where that takes more than ``max_refine_steps``
    (slow growth just past the edge), further above it (1.25, 1.5, 2 times)."""
    for factor in (1.1, 1.25, 1.5, 2.0):
        x = float(f"{factor * edge:.4g}")
        rho = stability.spectral_radius(coupling, master, coupling.step_for(x), fmu_dir)
        steps = plan.steps_for(x)
        if not (math.isfinite(rho) and rho > 1.0):
            break                       # fails outright (an iteration): visible at once
        needed = math.ceil(math.log(plan.refine_growth) / (0.75 * math.log(rho)))
        steps = max(steps, min(plan.max_refine_steps, needed))
        if needed <= plan.max_refine_steps:
            break
    return Case(master, coupling.stiffness, coupling.damping, x, steps)


# -- one case -------------------------------------------------------------------------------------

def amplitude_growth(tau: np.ndarray) -> float:
    """Half-range of ``tau`` over the last quarter of the run over that of the first."""
    tau = np.asarray(tau, dtype=float)
    if len(tau) < 8:
        return math.nan
    q = len(tau) // 4
    first, last = np.ptp(tau[:q]) / 2.0, np.ptp(tau[-q:]) / 2.0
    if not (np.isfinite(first) and np.isfinite(last)):
        return math.inf
    return float(last / first) if first > 0 else (math.inf if last > 0 else 1.0)


def classify(growth: float, energy_residual: float | None, failure: str | None,
             energy: bool = True) -> tuple[str, str]:
    """``(status, why)`` from the torque amplitude growth, the energy residual (relative
    to the engine's work) and the run's failure message (criteria: module docstring).
    ``energy=False``: a scene whose energy balance cannot be had (a foreign FMU's work is
    not known) is classified by the growth alone."""
    if failure:
        return "divergent", f"the run failed: {failure}"
    if not math.isfinite(growth) or growth > GROWTH_DIVERGENT:
        return "divergent", f"coupling torque amplitude grew {growth:.3g}x (> {GROWTH_DIVERGENT:g}x)"
    if growth > GROWTH_DRIFT:
        return "energy-drifting", f"coupling torque amplitude grew {growth:.3g}x (> {GROWTH_DRIFT:g}x)"
    if not energy:
        return "stable", f"amplitude x{growth:.3g} (no energy balance: it needs every FMU's equations)"
    if energy_residual is None or not math.isfinite(energy_residual):
        return "energy-drifting", "no finite energy residual"
    if energy_residual > ENERGY_DRIFT:
        return "energy-drifting", f"energy residual {100 * energy_residual:.3g} % of the work in (> {100 * ENERGY_DRIFT:g} %)"
    return "stable", f"amplitude x{growth:.3g}, energy residual {100 * energy_residual:.2g} %"


def unstable(result: dict) -> bool:
    """Observed linear instability: divergent, or growing (the energy residual aside)."""
    if result.get("status") == FAILED:
        return False
    return result["class"] == "divergent" or (result.get("growth") or 0.0) > GROWTH_DRIFT


def run_case(scene: scenes.Scene, case: Case, plan: Plan, fmu_dir: Path = FMUS) -> dict:
    """Run one case on the FMUs and classify it (an exception is the caller's to record)."""
    from harness.engine.run import simulate

    coupling = scene.component_of(coupling_scene.COUPLING_FMU)
    spec = scene.with_overrides([f"{coupling}.stiffness={case.stiffness!r}", f"{coupling}.damping={case.damping!r}"])
    model = None if case.h_omega is None else stability.model_of(spec, fmu_dir)
    step = case.step if model is None else model.step_for(case.h_omega)
    n = case.steps
    balanced = scene_kinds.is_driveline(spec)      # the energy balance needs every equation
    spec = replace(spec, experiment=replace(spec.experiment, start=0.0, stop=n * step, transient=0.0),
                   features=set(spec.features) | ({"energy_balance"} if balanced else set()))
    started = clock.perf_counter()
    result = simulate(spec, case.master, step, fmu_dir=fmu_dir)
    wall = clock.perf_counter() - started
    if result.failure_stage == "initialisation":
        # not a step made, so nothing observed of the master's stability: the case failed
        return {"status": FAILED, "error": result.failure, "where": "the run could not start", "step_s": step,
                "wall_s": wall}
    tau = result.traces.get(metrics.signals(spec)["tau2"], np.empty(0))
    growth = amplitude_growth(tau)
    residual = None
    if balanced and result.ok and len(result.times) > 1:
        residual = metrics.energy_balance(spec, result.times, result.traces)["residual_relative"]
    status, why = classify(growth, residual, result.failure, energy=balanced)
    return {"status": "ok", "class": status, "why": why, "growth": growth, "energy_residual": residual,
            "failure": result.failure, "step_s": step, "steps_planned": n, "steps_done": max(0, len(result.times) - 1),
            "omega_n": model and model.omega_n, "zeta": model and model.zeta, "wall_s": wall}


def _worker(scene, case, plan, fmu_dir):
    return run_case(scene, case, plan, fmu_dir)


# -- the sweep ------------------------------------------------------------------------------------

@dataclass
class StabilityMap:
    scene: scenes.Scene
    plan: Plan
    model: stability.TwoInertia | None             # None: a map without prediction
    edges: dict                     # (master, c, b) -> predicted edge or None
    results: dict = field(default_factory=dict)    # Case -> result dict
    reused: int = 0
    wall_s: float = 0.0
    #: the sentence saying why nothing was predicted ("" where the model was made)
    no_prediction: str = ""


def sweep(scene: scenes.Scene, plan: Plan, out: Path, jobs: int = 1, resume: bool = True,
          fmu_dir: Path = FMUS, progress=None) -> StabilityMap:
    """Run every case of ``plan`` not yet in ``out/cases.jsonl`` (``jobs`` processes),
    recording each as it finishes.  Ctrl-C stops it at once with ``Interrupted``: the
    cases under way are logged as interrupted (run again on resuming), the rest kept."""
    with interrupt.deferred():
        return _sweep(scene, plan, out, jobs, resume, fmu_dir, progress)


def _sweep(scene, plan, out, jobs, resume, fmu_dir, progress) -> StabilityMap:
    say = progress or (lambda *_: None)
    started = clock.perf_counter()
    model, no_prediction = linear_model(scene, fmu_dir, say)
    if no_prediction:
        say(no_prediction)
    if (model is None) == plan.predicted:
        raise ValueError("the plan does not fit the scene: " + (
            no_prediction if model is None else "a plan without prediction for a scene whose model was made"))
    edges = predictions(model, plan, fmu_dir) if model is not None else {}
    cases = cases_of(plan, edges, model, fmu_dir)
    log = CaseLog(out, plan.fingerprint(scene), resume=resume)
    if log.set_aside:
        say(f"the case log belonged to another set-up: moved to {log.set_aside}")
    todo = [c for c in cases if c.key not in log]
    estimate = f"; {duration_text(estimated_seconds(scene, plan, todo, jobs, fmu_dir), NARROW)}" \
        if todo and progress else ""
    say(f"{len(cases)} cases ({len(cases) - len(todo)} already done), {jobs} process(es){estimate}")
    done = 0

    def record(case, result):
        nonlocal done
        log.record(case.key, result)
        done += 1
        if done % 50 == 0 or done == len(todo):
            say(f"  {done}/{len(todo)} cases run")

    if jobs <= 1:
        for case in todo:
            log.run(case.key, lambda case=case: run_case(scene, case, plan, fmu_dir))
            done += 1
            if done % 50 == 0 or done == len(todo):
                say(f"  {done}/{len(todo)} cases run")
    else:
        _run_pool(scene, plan, todo, jobs, log, record, fmu_dir)
    result = StabilityMap(scene, plan, model, edges,
                          {c: log.get(c.key) for c in cases if log.get(c.key) is not None},
                          reused=len(cases) - len(todo), wall_s=clock.perf_counter() - started,
                          no_prediction=no_prediction)
    return result


#: how to make the study shorter, said with its estimate when it is long
NARROW = "--master, --stiffness, --damping or --h-omega narrow the grid"

def estimated_seconds(scene: scenes.Scene, plan: Plan, todo: list[Case], jobs: int, fmu_dir: Path = FMUS) -> float:
    """How long ``todo`` will take, about: each master's cost of a case (set-up) and of a
    step, from two runs of the scene (``CALIBRATION_STEPS``, at h*omega_n = 0.5) timed now,
    summed over the steps its cases plan and shared among ``jobs`` processes.  A case that
    diverges ends early and an implicit master iterates more on a stiffer coupling: an
    estimate, not a promise."""
    def timed(master: str, steps: int) -> float:
        case = (Case(master, plan.stiffnesses[0], plan.dampings[0], 0.5, steps) if plan.predicted else
                replace(plan.observed_cases(master, plan.stiffnesses[0], plan.dampings[0])[0], steps=steps))
        started = clock.perf_counter()
        try:
            run_case(scene, case, plan, fmu_dir)
        except Exception:     # noqa: BLE001 - the study itself records what a case raises
            pass
        return clock.perf_counter() - started

    masters = list(dict.fromkeys(c.master for c in todo))
    timed(masters[0], CALIBRATION_STEPS[0])          # the first run pays for imports and loading the FMUs
    cost = {master: step_cost(lambda steps, master=master: timed(master, steps)) for master in masters}
    total = sum(cost[c.master][0] + cost[c.master][1] * c.steps for c in todo)
    return total / max(1, min(jobs, len(todo)))


def _failed(error: BaseException, where: str) -> dict:
    return {"status": FAILED, "error": f"{type(error).__name__}: {error}", "where": where}


def _run_pool(scene, plan, todo, jobs, log, record, fmu_dir):
    """Cases in worker processes (forked: each exits without the interpreter teardown
    that pythonfmu's native library does not survive).  A worker that dies breaks the
    pool: the rest are resubmitted to a single worker, where the case that kills it is
    known and recorded as failed."""
    context = multiprocessing.get_context("fork")
    queue, workers = list(todo), jobs
    while queue:
        broken = False
        with ProcessPoolExecutor(workers, mp_context=context) as pool:
            futures = {pool.submit(_worker, scene, case, plan, fmu_dir): case for case in queue}
            try:
                collect(pool, futures, log, lambda case: case.key, lambda error: _failed(error, "stability case"),
                        record, passes=(BrokenProcessPool,))
            except BrokenProcessPool:
                broken = True
                for future in futures:
                    future.cancel()
        remaining = [c for c in queue if c.key not in log]
        if broken and workers == 1 and remaining:
            record(remaining[0], _failed(RuntimeError("the worker process died running this case"), "worker"))
            remaining = remaining[1:]
        if broken:
            workers = 1
        queue = remaining


# -- summaries ------------------------------------------------------------------------------------

def predicted_radius(model, case: Case, fmu_dir: Path = FMUS) -> float:
    m = model.with_coupling(case.stiffness, case.damping)
    return stability.spectral_radius(m, case.master, m.step_for(case.h_omega), fmu_dir)


def inconclusive(result: StabilityMap, case: Case, fmu_dir: Path = FMUS) -> bool:
    """A run too short to show the growth its spectral radius (> 1) predicts."""
    rho = predicted_radius(result.model, case, fmu_dir)
    return rho > 1.0 + stability.RHO_TOLERANCE and predicted_growth(rho, case.steps) <= GROWTH_DRIFT


def edge_rows(result: StabilityMap, fmu_dir: Path = FMUS) -> list[dict]:
    """Per (master, c, b): the predicted edge and the observed bracket (the last
    ``h*omega_n`` observed stable below the first observed unstable one), leaving out
    the inconclusive runs."""
    rows = []
    for m in result.plan.masters:
        for c in result.plan.stiffnesses:
            for b in result.plan.dampings:
                row_cases = sorted((case for case in result.results if case.row == (m, c, b)),
                                   key=lambda case: case.h_omega)
                runs = [(case.h_omega, result.results[case]) for case in row_cases
                        if result.results[case].get("status") != FAILED and not inconclusive(result, case, fmu_dir)]
                first_unstable = next((x for x, r in runs if unstable(r)), None)
                last_stable = max((x for x, r in runs if first_unstable is None or x < first_unstable), default=None)
                model = result.model.with_coupling(c, b)
                edge = result.edges.get((m, c, b))
                observed = (math.sqrt(first_unstable * last_stable) if first_unstable and last_stable else None)
                rows.append({"master": m, "stiffness": c, "damping": b, "omega_n": model.omega_n, "zeta": model.zeta,
                             "predicted_edge": edge, "last_stable": last_stable, "first_unstable": first_unstable,
                             "observed_edge": observed,
                             "bracketed": (edge is not None and last_stable is not None and first_unstable is not None
                                           and last_stable <= edge <= first_unstable) if first_unstable else None,
                             "ratio": observed / edge if observed and edge else None})
    return rows


def observed_rows(result: StabilityMap) -> list[dict]:
    """Per (master, c, b) of a map without prediction: the steps [s] of the last case
    observed stable below the first observed unstable one (None: no such case), and the
    count of each class."""
    rows = []
    for m in result.plan.masters:
        for c in result.plan.stiffnesses:
            for b in result.plan.dampings:
                runs = sorted(((case.step, r) for case, r in result.results.items() if case.row == (m, c, b)),
                              key=lambda item: item[0])
                ran = [(h, r) for h, r in runs if r.get("status") != FAILED]
                first_unstable = next((h for h, r in ran if unstable(r)), None)
                last_stable = max((h for h, r in ran if first_unstable is None or h < first_unstable), default=None)
                classes = {}
                for _, r in runs:
                    key = FAILED if r.get("status") == FAILED else r["class"]
                    classes[key] = classes.get(key, 0) + 1
                rows.append({"master": m, "stiffness": c, "damping": b, "last_stable_step": last_stable,
                             "first_unstable_step": first_unstable, "largest_step": max((h for h, _ in ran), default=None),
                             "classes": classes})
    return rows


def observed_advice(result: StabilityMap) -> list[str]:
    """What the runs of a map without prediction say, one line a swept coupling: up to
    which step each master was observed stable (below its first unstable case), and which
    were unstable at every swept step.  Observed, not predicted: a longer run or a step
    between two swept ones may still differ."""
    lines = []
    rows = observed_rows(result)
    for c in result.plan.stiffnesses:
        for b in result.plan.dampings:
            row = [r for r in rows if (r["stiffness"], r["damping"]) == (c, b)]
            stable = sorted((r for r in row if r["last_stable_step"] is not None),
                            key=lambda r: -r["last_stable_step"])
            never = [r["master"] for r in row if r["last_stable_step"] is None and r["first_unstable_step"] is not None]
            not_run = [r["master"] for r in row if r["largest_step"] is None]
            text = f"c = {c:.4g} N*m/rad, b = {b:.3g} N*m*s/rad: "
            text += ("observed stable up to h = " + ", ".join(
                f"{r['last_stable_step']:.3g} s with {r['master']}"
                + ("" if r["first_unstable_step"] else " (stable at every swept step)") for r in stable)
                if stable else "no master observed stable at any swept step")
            if never:
                text += f"; unstable at every swept step: {', '.join(never)}"
            if not_run:
                text += f"; no run could start (stability.md lists why): {', '.join(not_run)}"
            lines.append(text)
    return lines


def agreement(result: StabilityMap, fmu_dir: Path = FMUS) -> dict:
    """Prediction against observation; for a map without prediction (``result.model``
    None) the same keys, empty, with ``no_prediction`` (the sentence why), ``observed_rows``
    and ``advice`` (``observed_advice``).

    Case by case: a case is predicted to show instability when its spectral radius
    gives a growth over the run (``predicted_growth``) above ``GROWTH_DRIFT`` - what the
    classification can see in a finite run - and compared with observed *unstable*.
    Growth rates: where both grow measurably, the observed growth per step against the
    spectral radius.  Edges: the predicted edge against the observed bracket, per row."""
    if result.model is None:
        return {"by_master": {}, "mismatches": [], "edge_rows": [], "rates": [], "inconclusive": 0,
                "explicit_bracketed": 0, "explicit_rows": 0, "explicit_ratio_median": None,
                "explicit_ratio_range": None, "rate_ratio_median": None, "rate_ratio_range": None,
                "no_prediction": result.no_prediction, "observed_rows": observed_rows(result),
                "advice": observed_advice(result)}
    by_master, mismatches, rates = {}, [], []
    for case, r in result.results.items():
        if r.get("status") == FAILED:
            continue
        rho = predicted_radius(result.model, case, fmu_dir)
        predicted = predicted_growth(rho, case.steps) > GROWTH_DRIFT
        observed = unstable(r)
        stats = by_master.setdefault(case.master, {"cases": 0, "agree": 0})
        stats["cases"] += 1
        if predicted == observed:
            stats["agree"] += 1
        else:
            edge = result.edges.get(case.row)
            mismatches.append({"case": case, "rho": rho, "observed": r["class"], "growth": r.get("growth"),
                               "predicted_growth": predicted_growth(rho, case.steps), "edge": edge,
                               "x_over_edge": case.h_omega / edge if edge else None})
        growth = r.get("growth")
        if not r.get("failure") and growth and math.isfinite(growth) and growth > GROWTH_DRIFT and math.isfinite(rho) and rho > 1.0:
            rates.append({"case": case, "observed": math.log(growth) / (0.75 * case.steps),
                          "predicted": math.log(rho)})
    rows = edge_rows(result, fmu_dir)
    explicit = [r for r in rows if r["master"] in EXPLICIT and r["predicted_edge"] is not None
                and r["first_unstable"] is not None and r["last_stable"] is not None]
    ratios = [r["ratio"] for r in explicit if r["ratio"]]
    rate_ratios = [x["observed"] / x["predicted"] for x in rates]
    n_inconclusive = sum(1 for case, r in result.results.items()
                         if r.get("status") != FAILED and inconclusive(result, case, fmu_dir))
    return {"by_master": by_master, "mismatches": mismatches, "edge_rows": rows, "rates": rates,
            "inconclusive": n_inconclusive,
            "explicit_bracketed": sum(1 for r in explicit if r["bracketed"]), "explicit_rows": len(explicit),
            "explicit_ratio_median": float(np.median(ratios)) if ratios else None,
            "explicit_ratio_range": (float(min(ratios)), float(max(ratios))) if ratios else None,
            "rate_ratio_median": float(np.median(rate_ratios)) if rate_ratios else None,
            "rate_ratio_range": (float(min(rate_ratios)), float(max(rate_ratios))) if rate_ratios else None}


# -- output (harness.studies.stability_report writes it) ------------------------------------------

def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "stability" / scene.name
