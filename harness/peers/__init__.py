"""Peer engines: the same scene run by engines other than our masters (fmpy, libcosim,
ecos, our container FMU in fmpy; our own harness under the same contract), for the
benchmark (``lever bench``'s peers), ``lever engines`` and ``lever hosts``.  The contract
(``base.Peer``: name, what it needs of a scene, whether it can run here, run -> traces, what
it reports), one module per engine, and the registry (``registry.PEERS``), the one place a
peer's name is checked.  A new engine: a module with a ``Peer`` subclass, named in
``registry.PEERS``."""
from harness.peers.base import BARE_ENVIRONMENT, Peer, SceneSetup, experiment_problem
from harness.peers.libcosim import LibcosimError
from harness.peers.registry import PEERS, available, problem, refuse_other_experiment, simulate_peer

__all__ = ["BARE_ENVIRONMENT", "Peer", "SceneSetup", "experiment_problem", "LibcosimError", "PEERS", "available",
           "problem", "refuse_other_experiment", "simulate_peer"]
