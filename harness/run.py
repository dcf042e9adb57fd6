"""Running a scene: instantiate its system, step it with a master, record what the scene
asks for.  A failed run keeps every row recorded before the failure and says what went
wrong, where and when (``RunResult.failure``)."""
from __future__ import annotations

import math
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import masters as master_family
from . import scene as scenes
from .component import FmuCallError
from .paths import FMUS
from .system import System


class Diverged(RuntimeError):
    pass


@dataclass
class RunResult:
    scene: scenes.Scene
    master: str
    step: float
    times: np.ndarray
    traces: dict[str, np.ndarray]
    wall_time: float
    counters: dict = field(default_factory=dict)
    failure: str | None = None
    #: where a failed run stopped: "initialisation" (the inputs were refused) or "stepping"
    failure_stage: str | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None


class Recorder:
    """Preallocated rows of the recorded variables, filled from the system's buffers."""

    def __init__(self, system: System, names: list[str], n_rows: int):
        self.names = names
        self.sources = []
        for item in names:
            comp, _, var = item.partition(".")
            self.sources.append((system.buffers[comp][1], system.index[(comp, var)]))
        self.times = np.empty(n_rows)
        self.rows = np.empty((n_rows, len(names)))
        self.count = 0

    def record(self, t: float):
        row = self.rows[self.count]
        for k, (values, i) in enumerate(self.sources):
            row[k] = values[i]
        self.times[self.count] = t
        self.count += 1
        if not np.isfinite(row).all():
            bad = [self.names[k] for k in range(len(self.names)) if not math.isfinite(row[k])]
            raise Diverged(f"non-finite value of {', '.join(bad)} at t = {t:.6g} s")

    def traces(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        n = self.count
        return self.times[:n].copy(), {name: self.rows[:n, k].copy() for k, name in enumerate(self.names)}


def recorded_names(scene: scenes.Scene) -> list[str]:
    """What a run records: the scene's list, plus what its features need."""
    names = list(scene.record)
    if "energy_balance" in scene.features:
        from .metrics import energy_variables
        names += [n for n in energy_variables(scene) if n not in names]
    return names


def simulate(scene: scenes.Scene, master: str | None = None, step: float | None = None,
             fmu_dir: Path = FMUS, progress: bool = False) -> RunResult:
    e = scene.experiment
    master = master or e.master
    step = float(step or e.step)
    if master not in master_family.MASTERS:
        raise ValueError(f"unknown master '{master}' (known: {', '.join(master_family.MASTERS)})")
    n_steps = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
    names = recorded_names(scene)
    system = System(scene, fmu_dir, record=names)
    failure = stage = None
    started = clock.perf_counter()
    recorder = None
    driver = None
    try:
        system.initialize()
        driver = master_family.make(master, system, step)
        recorder = Recorder(system, names, n_steps + 1)
        recorder.record(e.start)
        bar = _progress(n_steps, scene.name, master) if progress else None
        for n in range(1, n_steps + 1):
            driver.step(t_next=min(e.start + n * step, e.stop))
            recorder.record(driver.t)
            if bar is not None and n % 500 == 0:
                bar.update(500)
        if bar is not None:
            bar.close()
    except (FmuCallError, Diverged) as error:
        stage = "stepping" if driver else "initialisation"
        failure = (f"{error} (master {master}, step {step:g} s"
                   + (f", after {driver.n_steps} steps" if driver else ", during initialisation") + ")")
    finally:
        wall = clock.perf_counter() - started
        counters = driver.counters() if driver else {"fmu_calls": system.fmu_calls}
        system.free()
    times, traces = recorder.traces() if recorder else (np.empty(0), {n: np.empty(0) for n in names})
    return RunResult(scene, master, step, times, traces, wall, counters, failure, stage)


def _progress(total: int, scene: str, master: str):
    from tqdm import tqdm
    return tqdm(total=total, desc=f"{scene} [{master}]", unit="step", unit_scale=True, leave=False,
                mininterval=0.5)
