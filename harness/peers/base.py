"""The contract every peer engine keeps (``Peer``) and what every one needs from a scene
(``SceneSetup``).

A peer loads the scene's FMUs as they are, applies the scene's parameters and connections,
and returns a ``harness.engine.run.RunResult`` like the harness's own masters: traces keyed
``component.variable`` (Real variables), one row per communication point from start to
stop, and a failed run keeps the rows recorded before the failure.  Loading or wiring
failures raise (as the harness's instantiation failures do); failures while initialising or
stepping are reported in ``RunResult.failure``.  Its ``wall_time`` is what ``Peer.timed``
says: as ``harness.engine.run.simulate`` times it (from applying the parameters to the last
communication point) unless the engine can only be timed otherwise.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from harness.description import scene as scenes
from harness.engine.run import RunResult
from harness.description.plan import descriptions_for, fmu_path
from harness.engine.system import SceneInvalid, dependency_order, feedthrough_components

#: The environment of a host that is not a Python process and was set up for nothing: what an
#: engine run as its own program gets by default (our FMUs find their Python themselves).
BARE_ENVIRONMENT = {"PATH": "/usr/bin:/bin"}

#: what ``Peer.timed`` says by default
STEPPING = "from applying the parameters to the last communication point"


class Peer(ABC):
    """One engine that runs a scene.  A new engine subclasses this in a module of its own
    and is named in ``harness.peers.registry.PEERS``; nothing else changes."""

    #: the name users give it (``[bench.peers]``, ``lever engines``, ``lever hosts``)
    name: str = ""
    #: one line: what runs and how it couples
    summary: str = ""
    #: its step varies: it chooses its number of steps (``tolerance`` steers it)
    adaptive: bool = False
    #: the FMI versions (major) of the FMUs it runs; a scene with another is refused by name
    fmi_versions: tuple[str, ...] = ("2",)
    #: why it runs no other FMI version (what in the engine stops it), said in the refusal
    fmi_limit: str = ""
    #: it records no row at the start time: its first row is after the first step
    from_first_step: bool = False
    #: what its ``RunResult.wall_time`` covers
    timed: str = STEPPING
    #: the counters its ``RunResult.counters`` holds
    counters: tuple[str, ...] = ("steps",)

    def unavailable(self) -> str | None:
        """None if it can run here, else why not (a package missing, a library that does not load)."""
        return None

    def scene_problem(self, setup: SceneSetup) -> str | None:
        """What of ``setup.scene`` it cannot run (its start time, a parameter it cannot
        set, ...), said before anything runs; None if it can run it."""
        return None

    def fmi_problem(self, setup: SceneSetup) -> str | None:
        """The scene's FMUs of an FMI version it does not run, named; None if there are none."""
        others = [f"{name} (FMI {md.fmiVersion})" for name, md in setup.descriptions.items()
                  if md.fmiVersion.split(".")[0] not in self.fmi_versions]
        if not others:
            return None
        return (f"peer '{self.name}' runs FMI {' and '.join(v + '.0' for v in self.fmi_versions)} FMUs; scene "
                f"'{setup.scene.name}' has {', '.join(others)}" + (f": {self.fmi_limit}" if self.fmi_limit else ""))

    def steps_fixed(self, scene: scenes.Scene) -> bool:
        """Whether its run of ``scene`` makes the scene's fixed steps (else it only has to
        reach the stop time)."""
        return not self.adaptive

    @abstractmethod
    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        """Run ``setup.scene`` at communication step ``step`` (an adaptive engine: its first
        step), recording ``setup.record``.  ``tolerance``: an adaptive engine's tolerance
        (None: its own default; others ignore it); ``environment``: the environment of an
        engine that runs as its own program (None: ``BARE_ENVIRONMENT``; engines in Python
        ignore it)."""

    def __repr__(self) -> str:
        return f"<peer {self.name}>"


class SceneSetup:
    """What every peer needs from the scene: model variables by component, parameter
    values in SI, the components in dependency order, what to record.  Made (and the
    scene checked) before a peer runs; a scene the FMUs cannot run is ``SceneInvalid``."""

    def __init__(self, scene: scenes.Scene, fmu_dir, record: list[str]):
        descriptions = descriptions_for(scene, fmu_dir)
        findings = scenes.validate(scene, descriptions)
        for item in record:
            comp, _, var = item.partition(".")
            spec = scene.components.get(comp)
            if spec is None:
                findings.append(f"record '{item}': no component '{comp}'")
            elif spec.fmu in descriptions:
                variable = next((v for v in descriptions[spec.fmu].modelVariables if v.name == var), None)
                if variable is None:
                    findings.append(f"record '{item}': {comp} has no variable '{var}'")
                elif variable.type not in ("Real", "Float64"):       # FMI 2.0's and 3.0's name
                    findings.append(f"record '{item}': peers record Real variables only, not {variable.type}")
        if findings:
            raise SceneInvalid(scene.name, findings)
        self.scene = scene
        self.fmu_dir = fmu_dir
        self.record = record
        self.fmu_paths = {name: fmu_path(spec.fmu, fmu_dir, scene.experiment.fmi) for name, spec in scene.components.items()}
        self.descriptions = {name: descriptions[spec.fmu] for name, spec in scene.components.items()}
        self.variables = {name: {v.name: v for v in md.modelVariables} for name, md in self.descriptions.items()}
        self.parameters = {name: {k: scenes.quantity(v, f"{name}.{k}") for k, v in spec.parameters.items()}
                           for name, spec in scene.components.items()}
        # The order the harness propagates in.
        self.order = dependency_order(scene, feedthrough_components(scene, self.descriptions))

    def vr(self, component: str, variable: str) -> int:
        return self.variables[component][variable].valueReference

    def time_grid(self, step: float) -> np.ndarray:
        """The fixed-step communication points, as ``harness.engine.run.simulate`` steps them."""
        e = self.scene.experiment
        n_steps = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
        return np.minimum(e.start + step * np.arange(n_steps + 1), e.stop)

    def nothing_run(self, peer: str, step: float, wall_time: float, failure: str, stage: str) -> RunResult:
        """The result of a run that recorded no row."""
        return RunResult(self.scene, peer, step, np.empty(0), {n: np.empty(0) for n in self.record}, wall_time, {},
                         failure, stage)


def experiment_problem(times, scene: scenes.Scene, step: float, fixed_step: bool = True,
                       from_first_step: bool = False) -> str | None:
    """What a run's communication points ``times`` show of an experiment other than the
    scene's: another start, another stop, another number of steps of ``step`` (a fixed-step
    run).  ``from_first_step``: the run records no row at the start time.  None when it ran
    the scene's experiment."""
    e = scene.experiment
    if len(times) == 0:
        return None
    # the peers write times to six decimals or more; a thousandth of a step tells a missing step
    slack = max(1e-9 * max(1.0, abs(e.stop)), 1e-3 * step)
    wanted = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
    made = len(times) - (0 if from_first_step else 1)
    first = e.start + step if from_first_step else e.start
    problems = []
    if abs(times[0] - first) > slack:
        problems.append(f"started at t = {times[0]:.9g} s, not {e.start:g} s"
                        + (f" + one step ({first:g} s: it records no row at the start)" if from_first_step else ""))
    if fixed_step and made != wanted:
        problems.append(f"made {made} steps of {step:g} s, not the {wanted} from {e.start:g} to {e.stop:g} s")
    if (abs(times[-1] - e.stop) > slack) if fixed_step else (times[-1] < e.stop - slack):
        problems.append(f"stopped at t = {times[-1]:.9g} s, not {e.stop:g} s")
    return "; ".join(problems) or None


def first_non_finite(times: np.ndarray, traces: dict[str, np.ndarray]) -> tuple[int, str] | None:
    """The first row with a non-finite value and the harness's message for it, or None."""
    if not traces or len(times) == 0:
        return None
    table = np.column_stack(list(traces.values()))
    bad_rows = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if len(bad_rows) == 0:
        return None
    i = int(bad_rows[0])
    bad = [name for k, name in enumerate(traces) if not math.isfinite(table[i, k])]
    return i, f"non-finite value of {', '.join(bad)} at t = {times[i]:.6g} s"
