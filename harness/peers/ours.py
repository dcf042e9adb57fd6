"""Our own harness under the peers' contract (``lever`` with the scene's master,
``lever-jacobi`` with master ``jacobi``), so that a study sets it beside the other engines
without a case of its own.  It is ``harness.engine.run.simulate``; its wall time is the
stepping loop's (master, FMU calls, recording), as there."""
from __future__ import annotations

from dataclasses import replace

from harness.engine import masters as master_family
from harness.engine.run import RunResult, simulate
from harness.peers.base import Peer, SceneSetup


class OurHarness(Peer):
    counters = ("steps", "fmu_calls", "rollbacks", "iterations", "rejected")
    fmi_versions = ("2", "3")

    def __init__(self, master: str | None = None):
        self.master = master
        self.name = "lever" if master is None else f"lever-{master}"
        self.summary = "our harness, the scene's master" if master is None else f"our harness, master {master}"

    def steps_fixed(self, scene) -> bool:
        return not master_family.MASTERS[self.master or scene.experiment.master].adaptive

    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        # the run records what is asked (and what the scene's features need: left out of the result)
        result = simulate(replace(setup.scene, record=list(setup.record)), self.master, step, setup.fmu_dir)
        return replace(result, scene=setup.scene, traces={n: result.traces[n] for n in setup.record})
