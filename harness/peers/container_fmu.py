"""``container``: the scene packed as our container FMU (``harness.formats.container``, fmpy's
container_fmu: Jacobi inside it) and stepped by ``fmpy.simulate_fmu`` as a single FMU, as a
user of any one-FMU host runs it.  Its wall time is the whole call: unpacking, instantiating
and stepping."""
from __future__ import annotations

import tempfile
import time as clock
from dataclasses import replace
from pathlib import Path

import numpy as np

from harness.engine.run import RunResult
from harness.peers.base import Peer, SceneSetup


class ContainerFmu(Peer):
    name = "container"
    summary = "our container FMU (fmpy container_fmu) stepped by fmpy.simulate_fmu"
    timed = "everything: unpacking, instantiating and stepping (fmpy.simulate_fmu is one call)"
    fmi_limit = ("fmpy 0.3.32's container FMU is an FMI 2.0 FMU that calls its components through the FMI 2.0 API "
                 "and declares their variables with FMI 2.0's types")

    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        import fmpy

        from harness.formats.container import build_container, container_name

        scene, e, names = setup.scene, setup.scene.experiment, setup.record
        record_scene = replace(scene, record=names, experiment=replace(e, step=step))
        with tempfile.TemporaryDirectory(prefix="lever-container-") as scratch:
            fmu = build_container(record_scene, Path(scratch) / f"{scene.name}.fmu", setup.fmu_dir)
            started = clock.perf_counter()
            failure = None
            try:
                table = fmpy.simulate_fmu(str(fmu), start_time=e.start, stop_time=e.stop, output_interval=step,
                                          output=[container_name(n) for n in names])
            except Exception as error:  # noqa: BLE001 - reported as the run's failure
                table, failure = None, f"{type(error).__name__}: {error} ({self.name}, step {step:g} s)"
            wall = clock.perf_counter() - started
        if table is None:
            return setup.nothing_run(self.name, step, wall, failure, "stepping")
        traces = {n: np.asarray(table[container_name(n)], dtype=float) for n in names}
        return RunResult(scene, self.name, step, np.asarray(table["time"], dtype=float), traces, wall,
                         {"steps": len(table) - 1})
