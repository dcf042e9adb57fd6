"""The registry of peer engines: the one place a peer's name is looked up and checked
(``available``) and a scene is run by one (``simulate_peer``), in the manner of scipy's
``integrate._ivp`` (``METHODS`` and one check in ``solve_ivp``)."""
from __future__ import annotations

from pathlib import Path

from harness.description import scene as scenes
from harness.description.scene import step_problem
from harness.description.plan import recorded_names
from harness.engine.run import RunResult
from harness.paths import FMUS
from harness.peers.base import Peer, SceneSetup, experiment_problem
from harness.peers.container_fmu import ContainerFmu
from harness.peers.ecos import Ecos
from harness.peers.fmpy_jacobi import FmpyJacobi
from harness.peers.fmpy_ssp import FmpySsp
from harness.peers.libcosim import LibcosimEcco, LibcosimFixed, LibcosimOsp, LibcosimSsp
from harness.peers.ours import OurHarness

PEERS: dict[str, Peer] = {peer.name: peer for peer in (
    FmpyJacobi(), FmpySsp(), LibcosimFixed(), LibcosimSsp(), LibcosimOsp(), LibcosimEcco(),
    Ecos(), Ecos("ecos-serial", parallel=False), Ecos("ecos-log-all", log_all=True),
    ContainerFmu(), OurHarness(), OurHarness("jacobi"))}


def available(name: str) -> str | None:
    """None if peer ``name`` can run here, else why not."""
    if name not in PEERS:
        return f"unknown peer '{name}' (known: {', '.join(PEERS)})"
    return PEERS[name].unavailable()


def problem(name: str, scene: scenes.Scene, fmu_dir: Path = FMUS) -> str | None:
    """What stops peer ``name`` from running ``scene`` - unknown, unavailable here, an FMI
    version or a part of the scene it cannot run - said before anything runs; None if
    nothing does.  ``SceneInvalid`` for a scene the FMUs cannot run."""
    reason = available(name)
    if reason:
        return f"peer '{name}' is not available: {reason}"
    peer = PEERS[name]
    setup = SceneSetup(scene, Path(fmu_dir), list(recorded_names(scene)))
    return peer.fmi_problem(setup) or peer.scene_problem(setup)


def simulate_peer(name: str, scene: scenes.Scene, step: float, fmu_dir: Path = FMUS,
                  record: list[str] | None = None, tolerance: float | None = None,
                  environment: dict | None = None) -> RunResult:
    """Run ``scene`` with peer ``name`` at communication step ``step`` (an adaptive peer:
    its first step), recording ``record`` (default: what the harness records).
    ``tolerance`` is an adaptive peer's (ECCO's absolute and relative tolerance on the
    energy residual); the others ignore it.  ``environment``: that of a peer run as its own
    program (ecos; default bare).  Raises ``ValueError`` for an unknown or unavailable peer
    or a scene the peer cannot run, ``SceneInvalid`` for a scene the FMUs cannot run, and
    ``LibcosimError`` when libcosim cannot load or wire the FMUs.  A run that did not run
    the scene's experiment is refused (``refuse_other_experiment``)."""
    reason = available(name)
    if reason:
        raise ValueError(f"peer '{name}' is not available: {reason}")
    if problem := step_problem(step, "communication step"):
        raise ValueError(problem)
    peer = PEERS[name]
    setup = SceneSetup(scene, Path(fmu_dir), list(recorded_names(scene) if record is None else record))
    if problem := peer.fmi_problem(setup) or peer.scene_problem(setup):
        raise ValueError(problem)
    result = peer.run(setup, float(step), None if tolerance is None else float(tolerance), environment)
    return refuse_other_experiment(result, name, scene, float(step))


def refuse_other_experiment(result: RunResult, name: str, scene: scenes.Scene, step: float) -> RunResult:
    """A peer's run that did not run the scene's experiment (``experiment_problem``) is
    refused: its errors and run time would compare another experiment with ours."""
    if result.ok:
        peer = PEERS[name]
        problem = experiment_problem(result.times, scene, step, fixed_step=peer.steps_fixed(scene),
                                     from_first_step=peer.from_first_step)
        if problem:
            result.failure = f"refused: peer {name} {problem}"
            result.failure_stage = "stepping"
    return result
