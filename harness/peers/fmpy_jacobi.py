"""``fmpy-jacobi``: the plain baseline, a fixed-step Jacobi loop written on fmpy's
high-level API (``FMU2Slave``: ``getReal``/``setReal``/``doStep``; an FMI 3.0 FMU's
``FMU3Slave``: ``getFloat64``/``setFloat64``/``doStep``; one Python call each), as an fmpy
user would write it.  The same algorithm as the harness's ``jacobi`` (after every step,
outputs are propagated in dependency order, so the coupling's torques are those of the
shafts' new states) without the harness's raw ctypes calls: its traces are the harness's
bit for bit.  An FMI 3.0 instance is made with Event Mode and early return off, as the
harness makes it: a step that asks for Event Mode, ends the simulation or returns early
ends the run, never a silently short step.
"""
from __future__ import annotations

import math
import time as clock
from collections import deque

import numpy as np

from harness.description import typed_values
from harness.engine import component as harness_component
from harness.engine.run import RunResult
from harness.peers.base import Peer, SceneSetup


class _Fmi3Slave:
    """An fmpy ``FMU3Slave`` behind the calls the loop makes of an ``FMU2Slave``:
    ``getReal``/``setReal`` are ``getFloat64``/``setFloat64``, ``setupExperiment`` is kept
    for ``enterInitializationMode`` (FMI 3.0 takes the start and stop time there), and a
    ``doStep`` that sets one of its flags raises (see the module docstring)."""

    def __init__(self, md, unzipped: str, instance: str):
        from fmpy.fmi3 import FMU3Slave

        self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=instance)

        # FMI 3.0's callback carries no instance name: each instance gets one that routes by its name
        def log(environment, status, category, message):
            harness_component.dispatch_message(instance, status, category, message)

        self.fmu.instantiate(eventModeUsed=False, earlyReturnAllowed=False, logMessage=log)
        self.getReal, self.setReal = self.fmu.getFloat64, self.fmu.setFloat64
        self.times: tuple[float, float | None] = (0.0, None)

    def __getattr__(self, name):
        return getattr(self.fmu, name)

    def setupExperiment(self, startTime: float, stopTime: float | None):
        self.times = (startTime, stopTime)

    def enterInitializationMode(self):
        self.fmu.enterInitializationMode(startTime=self.times[0], stopTime=self.times[1])

    def doStep(self, currentCommunicationPoint: float, communicationStepSize: float):
        events, terminate, early, last = self.fmu.doStep(currentCommunicationPoint, communicationStepSize)
        if events or terminate or early:
            asked = ", ".join(name for name, flag in (("eventHandlingNeeded", events), ("terminateSimulation", terminate),
                                                      ("earlyReturn", early)) if flag)
            raise RuntimeError(f"fmi3DoStep(t = {currentCommunicationPoint:.6g} s) set {asked} (lastSuccessfulTime = "
                               f"{last:.9g} s): this loop makes every step whole, without Event Mode")


class FmpyJacobi(Peer):
    name = "fmpy-jacobi"
    summary = ("fixed-step Jacobi on fmpy's FMU2Slave/FMU3Slave API (getReal/setReal/doStep, "
               "getFloat64/setFloat64/doStep per call)")
    fmi_versions = ("2", "3")

    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        from fmpy.fmi2 import FMU2Slave

        scene, e = setup.scene, setup.scene.experiment
        grid = setup.time_grid(step)
        # Each component's outputs are read with one getReal per step: the connected ones,
        # then the recorded ones; each connection is one setReal.
        reads = {name: [] for name in setup.order}
        for item in [f"{c.source}.{c.output}" for c in scene.connections] + setup.record:
            comp, _, var = item.partition(".")
            if var not in reads[comp]:
                reads[comp].append(var)
        read_vrs = {name: [setup.vr(name, var) for var in names] for name, names in reads.items()}
        position = {(name, var): i for name, names in reads.items() for i, var in enumerate(names)}
        transfers = {name: [(c.target, setup.vr(c.target, c.input), position[(name, c.output)])
                            for c in scene.connections if c.source == name] for name in setup.order}
        recorded = [(item.partition(".")[0], position[tuple(item.split(".", 1))]) for item in setup.record]

        slaves: dict[str, FMU2Slave | _Fmi3Slave] = {}
        unzipped: list[str] = []
        messages: deque[str] = deque(maxlen=5)
        values: dict[str, list[float]] = {}
        rows: list[list[float]] = []
        n_steps = 0
        failure = stage = None
        finished = False    # every step taken: Terminate allowed (not after an error or before stepping)

        def propagate():
            for name in setup.order:
                values[name] = slaves[name].getReal(read_vrs[name]) if read_vrs[name] else []
                for target, vr, i in transfers[name]:
                    slaves[target].setReal([vr], [values[name][i]])

        def record_row(t: float):
            row = [values[comp][i] for comp, i in recorded]
            rows.append(row)
            if not all(math.isfinite(x) for x in row):
                bad = [item for item, x in zip(setup.record, row) if not math.isfinite(x)]
                raise FloatingPointError(f"non-finite value of {', '.join(bad)} at t = {t:.6g} s")

        try:
            for name in setup.order:
                md = setup.descriptions[name]
                unzipped.append(harness_component.unzipped(setup.fmu_paths[name]))   # shared: see there
                instance = f"{name}@{self.name}"
                # The harness's process-wide logger routes messages by instance name: keep
                # this peer's, to say in a failure what the FMU said.
                harness_component.route_messages(instance, messages)
                if md.fmiVersion.startswith("3."):
                    slaves[name] = _Fmi3Slave(md, unzipped[-1], instance)
                    continue
                fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped[-1],
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=instance)
                fmu.instantiate(callbacks=harness_component.log_callbacks())
                slaves[name] = fmu

            started = clock.perf_counter()
            try:
                stage = "initialisation"
                for name, fmu in slaves.items():
                    for param, value in setup.parameters[name].items():
                        # an FMI 3.0 parameter through the setter of its type (setInt32, setBoolean, ...)
                        typed_values.set_on(fmu.fmu if isinstance(fmu, _Fmi3Slave) else fmu,
                                            setup.variables[name][param], value, f"{name}.{param}")
                    fmu.setupExperiment(startTime=e.start, stopTime=e.stop)
                    fmu.enterInitializationMode()
                propagate()
                for fmu in slaves.values():
                    fmu.exitInitializationMode()
                propagate()
                record_row(grid[0])
                stage = "stepping"
                for n in range(1, len(grid)):
                    t, h = grid[n - 1], grid[n] - grid[n - 1]
                    for fmu in slaves.values():
                        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                    propagate()
                    n_steps += 1
                    record_row(grid[n])
                finished = True
            except Exception as error:  # noqa: BLE001 - whatever fails ends the run, keeping its rows
                said = [m for m in messages if not m.startswith("[ok]")]
                failure = (f"{type(error).__name__}: {error}" + ("; FMU said: " + " | ".join(said) if said else "")
                           + f" (peer {self.name}, step {step:g} s, after {n_steps} steps)")
            wall = clock.perf_counter() - started
        finally:
            for name, fmu in slaves.items():
                if finished:
                    try:
                        fmu.terminate()
                    except Exception:  # noqa: BLE001 - freeing must go on after a refused terminate
                        pass
                fmu.freeInstance()
            for name in setup.order:
                harness_component.unroute(f"{name}@{self.name}")
        table = np.array(rows, dtype=float).reshape(len(rows), len(setup.record))
        traces = {item: table[:, k].copy() for k, item in enumerate(setup.record)}
        return RunResult(scene, self.name, step, grid[:len(rows)].copy(), traces, wall,
                         {"steps": n_steps}, failure, stage if failure else None)
