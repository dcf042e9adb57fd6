"""What the benchmark runs: the scene's plan (the masters at their steps or tolerances,
the peers, the monolithic tolerances, the target error, the baseline), the ``Case`` it
records for each run setting, and the case log a benchmark killed part-way resumes from
(``harness.studies.cases``), which never mixes in cases of another fingerprint."""
from __future__ import annotations

import json
import math
import statistics as stats
from dataclasses import asdict, dataclass, field
from pathlib import Path

from harness.description import plan as plans, scene_kinds
from harness.description import scene as scenes
from harness.description.scene_file import BENCH_KEYS
from harness.engine import masters as master_family
from harness.engine.system import MODEL_EXCHANGE
from harness.judges import port_probe, stability
from harness.paths import FMUS
from harness.studies.cases import FAILED, CaseLog, case_key


@dataclass
class Case:
    engine: str                 # a master's name, a peer's, "monolithic" (DOP853) or "monolithic-cvode"
    kind: str                   # "master", "peer", "monolithic"
    step: float | None          # communication step [s] (first step for adaptive runs)
    tolerance: float | None = None
    wall_times: list = field(default_factory=list)
    steps: int = 0
    fmu_calls: int = 0
    rollbacks: int = 0
    errors: dict = field(default_factory=dict)   # rms/max relative, whole run and after transient
    energy_residual: float | None = None
    floor_time: float | None = None
    failure: str | None = None
    largest_step: float | None = None           # the longest communication step taken [s]
    #: the stepping loop's FMI calls, component -> kind -> count (a master's run)
    calls_by_kind: dict = field(default_factory=dict)
    #: where the run time went (``time_split``): crossing, slave, master [s]
    split: dict | None = None
    #: the call prices measured just before and just after the case's runs:
    #: {"ours"|"hollow": [before, after]}, each component -> kind -> seconds a call
    prices: dict | None = None
    #: runs asked for (``repeats``); fewer were made when a run failed or took long
    asked: int = 0
    #: the FMU-call floor [s a step] timed just before each run (masters): one per run
    floor_times: list = field(default_factory=list)
    #: a run of the master and the floor of its own FMI calls, side by side [s, s]: the calls
    #: the master made, recorded once and replayed on fresh FMUs in turns with one more run
    #: (``replay.SideBySide``), timed just before each run: one pair per run
    own_calls_pairs: list = field(default_factory=list)
    #: what was replayed (``replay.OwnCallsFloor.summary``): calls, state calls, steps of
    #: the run's recorded, and why the floor is not measured (``problem``)
    own_calls: dict | None = None
    #: the machine's one-minute load average before and after the case's runs
    load: list = field(default_factory=list)
    #: the master's own time measured directly (``master_time.measure(...).summary()``),
    #: what the split is made of
    timed: dict | None = None
    #: why the split is not shown (``trust.split_problems``), with the machine's noise
    split_unreliable: str | None = None
    #: the integrator and why (the monolithic CVODE's and the Model Exchange master's)
    method: str | None = None
    #: right-hand-side evaluations (monolithic solutions, the Model Exchange master)
    rhs: int | None = None

    @property
    def wall(self) -> float:
        return stats.median(self.wall_times) if self.wall_times else math.nan

    @property
    def stable(self) -> bool:
        return self.failure is None and math.isfinite(self.errors.get("tau_rms", math.nan))

    @property
    def label(self) -> str:
        if self.kind == "monolithic":
            return f"{self.engine} rtol={self.tolerance:g}"
        if self.tolerance is not None:
            return f"{self.engine} tol={self.tolerance:g}"
        return f"{self.engine} h={self.step:g}"

    @property
    def key(self) -> str:
        """The case's key in the case log and in the side-by-side rounds."""
        return case_key(self.kind, self.engine, self.step, self.tolerance)


#: the ladder's tolerances where the scene's [bench] names none: (adaptive masters, Model Exchange)
LADDER_TOLERANCES = {"co-simulation": (1e-2, 1e-3, 1e-4), "model exchange": (1e-4, 1e-6, 1e-8)}
#: the ladder's steps: its largest, then halved this many times
LADDER_RUNGS = 3


def _rounded(x: float) -> float:
    return float(f"{x:.3g}")


def ladder(scene: scenes.Scene, fmu_dir: Path = FMUS, say=None) -> tuple[dict, dict, dict]:
    """``(steps, tolerances, dropped)`` for a scene whose ``[bench]`` names no steps or
    tolerances: each fixed-step co-simulation master at ``LADDER_RUNGS`` steps from near
    its predicted stability edge down (the largest: twice the scene's step, or 0.8 of the
    edge's step where that is shorter; then halved), each adaptive or Model Exchange
    master at ``LADDER_TOLERANCES``; ``dropped``: master -> why it is not run (predicted
    unstable at every step, an FMU without Model Exchange).  Without a stability model
    (a scene without our coupling) the steps are the scene's times 2, 1 and 1/2, and
    ``dropped`` says nothing: nothing was judged."""
    top = 2.0 * scene.experiment.step
    try:
        model = stability.model_of(scene, fmu_dir, say)
    except (scene_kinds.NotADriveline, port_probe.ProbeRefused, ValueError) as error:
        model = None
        if say is not None:
            say(f"bench ladder: no stability model ({error}); steps 2, 1 and 1/2 times the scene's")
    steps, tolerances, dropped = {}, {}, {}
    descriptions = plans.descriptions_for(scene, fmu_dir)
    for name, cls in master_family.MASTERS.items():
        if cls.interface == MODEL_EXCHANGE:
            lacking = [n for n, c in scene.components.items()
                       if c.fmu in descriptions and descriptions[c.fmu].modelExchange is None]
            if lacking:
                dropped[name] = ("it needs Model Exchange in every FMU; " + ", ".join(
                    f"{n} ({scene.components[n].fmu})" for n in lacking) + " offer(s) co-simulation only")
                continue
        if cls.adaptive or cls.interface == MODEL_EXCHANGE:
            tolerances[name] = list(LADDER_TOLERANCES[cls.interface])
            continue
        largest = top
        if model is not None:
            edge = stability.stability_edge(model, name, fmu_dir)
            if edge is not None and edge <= stability.EDGE_RANGE[0]:
                dropped[name] = (f"predicted unstable at every step on this scene (coupling mode omega_n = "
                                 f"{model.omega_n:.4g} rad/s, zeta = {model.zeta:.3g})")
                continue
            if edge is not None:
                largest = min(top, stability.MARGIN * model.step_for(edge))
        steps[name] = [_rounded(largest / 2 ** k) for k in range(LADDER_RUNGS)]
    return steps, tolerances, dropped


def check(scene: scenes.Scene, only: list[str] | None = None):
    """``ValueError`` for a ``[bench]`` key or a master (in it or in ``only``) that is not
    known: what ``plan`` refuses, without making the plan."""
    table = dict(scene.bench)
    unknown = sorted(set(table) - set(BENCH_KEYS))
    if unknown:
        raise ValueError(f"scene '{scene.name}' [bench]: unknown key(s) {', '.join(unknown)} (known: "
                         f"{', '.join(BENCH_KEYS)})")
    try:
        master_family.check(*table.get("steps", {}), *table.get("tolerances", {}), *table.get("output_steps", {}))
    except master_family.UnknownMaster as error:
        raise ValueError(f"scene '{scene.name}' [bench]: {error}") from None
    master_family.check(*(only or ()))


def plan(scene: scenes.Scene, only: list[str] | None = None, fmu_dir: Path = FMUS, say=None) -> dict:
    """The scene's benchmark plan, with defaults (``scene_file.BENCH_KEYS``); without steps and tolerances
    in its ``[bench]``, the ladder (``ladder``).  ``dropped``: each master not run (asked
    for with ``only``, or in the ladder) and why."""
    table = dict(scene.bench)
    steps = {name: [float(h) for h in values] for name, values in table.get("steps", {}).items()}
    tolerances = {name: [float(x) for x in values] for name, values in table.get("tolerances", {}).items()}
    check(scene, only)
    dropped = {}
    if not steps and not tolerances:
        steps, tolerances, dropped = ladder(scene, fmu_dir, say)
    if only:
        for name in only:
            if name not in steps and name not in tolerances and name not in dropped:
                dropped[name] = "the scene's [bench] names no steps or tolerances for it"
        steps = {k: v for k, v in steps.items() if k in only}
        tolerances = {k: v for k, v in tolerances.items() if k in only}
        dropped = {k: v for k, v in dropped.items() if k in only}
    output_steps = {name: float(h) for name, h in table.get("output_steps", {}).items()}
    return {
        "steps": steps,
        "tolerances": tolerances,
        "peers": {name: [float(h) for h in values] for name, values in table.get("peers", {}).items()},
        # ECCO: (first step, tolerance) pairs, its tolerance in joules per step
        "peer_tolerances": {name: [float(x) for x in values]
                            for name, values in table.get("peer_tolerances", {}).items()},
        "monolithic": [float(x) for x in table.get("monolithic_rtol", [1e-4, 1e-6, 1e-8])],
        # the same unsplit equations under CVODE (BDF or Adams, as the stability analysis
        # chooses for the Model Exchange master): the strongly coupled master's own peer,
        # where the scene's plan names its tolerances
        "monolithic_cvode": [float(x) for x in table.get("monolithic_cvode_rtol", [])],
        # the output grid [s] of a master's tolerance runs where it records on a grid (the
        # Model Exchange master; default the scene's step), e.g. the grid the masters it is
        # compared with record on
        "output_steps": output_steps,
        # the grid the unsplit solutions record on: the Model Exchange master's, where the
        # plan names it (the price of the FMU boundary is a ratio of like with like: the same
        # points recorded, the same outputs computed at them), the scene's step otherwise
        "monolithic_step": next((h for name, h in output_steps.items()
                                 if master_family.master_class(name).interface == MODEL_EXCHANGE),
                                scene.experiment.step),
        "target_error": float(table.get("target_error", 1e-3)),
        "baseline": table.get("baseline", "jacobi"),
        "repeats_limit_s": float(table.get("repeats_limit_s", 5.0)),
        "dropped": dropped,
    }


def fingerprint(scene: scenes.Scene, repeats: int, fmu_dir: Path = FMUS) -> dict:
    """What a benchmark's results depend on: a case log with another fingerprint is set
    aside, never mixed in (the scene with its bench plan, the repeats, the FMU build)."""
    from lever import __version__
    stamp = Path(fmu_dir) / "build-stamp.json"
    return {"study": "bench", "scene": asdict(scene), "repeats": repeats, "lever": __version__,
            "fmus": json.loads(stamp.read_text()).get("hash") if stamp.exists() else None}


def logged(log: CaseLog | None, case: Case, measure) -> tuple[Case, bool]:
    """``measure()`` -> Case, through the case log: a case already in the log is taken
    from it; a case that raises is recorded as failed with its diagnosis, and the
    benchmark goes on with the others."""
    if log is None:
        try:
            return measure(), False
        except Exception as error:  # noqa: BLE001 - one failed case must not cost the others
            case.failure = f"{type(error).__name__}: {error}"
            return case, False
    entry, reused = log.run(case.key, lambda: asdict(measure()))
    if entry.get("status") == FAILED:
        case.failure = f"{entry['error']} (at {entry['where']})"
        return case, reused
    return Case(**{k: v for k, v in entry.items() if k in Case.__dataclass_fields__}), reused


def rounds_logged(log: CaseLog | None, key: str, measure) -> dict:
    """``measure()`` -> the side-by-side rounds, through the case log under ``key``."""
    if log is None:
        return measure()
    entry, _ = log.run(key, measure)
    if entry.get("status") == FAILED:
        return {"failure": f"{entry['error']} (at {entry['where']})"}
    return entry
