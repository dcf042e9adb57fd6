"""The registry of masters: the one place a master's name is looked up and checked
(``master_class``, ``check``) and a master is made for a system (``make``)."""
from __future__ import annotations

from harness.engine.masters.adaptive import AdaptiveMaster, AdaptiveTrapezoidalMaster, StepControl
from harness.engine.masters.base import Master, MasterFailure
from harness.engine.masters.explicit import (GaussSeidelMaster, JacobiMaster, LinearExtrapolationMaster,
                                             MidpointPredictionMaster, QuadraticExtrapolationMaster)
from harness.engine.masters.iterative import (ImplicitFixedPointMaster, ImplicitNewtonMaster, IterativeMaster,
                                              TrapezoidalFixedPointMaster, TrapezoidalNewtonMaster)
from harness.engine.masters.model_exchange import ModelExchangeCvodeMaster
from harness.engine.system import System

MASTERS = {cls.name: cls for cls in (JacobiMaster, GaussSeidelMaster, LinearExtrapolationMaster,
                                     QuadraticExtrapolationMaster, MidpointPredictionMaster,
                                     ImplicitFixedPointMaster, ImplicitNewtonMaster,
                                     TrapezoidalFixedPointMaster, TrapezoidalNewtonMaster, AdaptiveMaster,
                                     AdaptiveTrapezoidalMaster, ModelExchangeCvodeMaster)}


class UnknownMaster(ValueError):
    """A master name that is not in ``MASTERS``."""


class TakesNoTolerance(ValueError):
    """A scene states a tolerance for a master that takes none."""


def check(*names: str):
    """Raise ``UnknownMaster`` naming every one of ``names`` that is not a master, and the known ones."""
    unknown = [name for name in names if name not in MASTERS]
    if unknown:
        raise UnknownMaster(f"master '{', '.join(unknown)}' is unknown (known: {', '.join(MASTERS)})")


def master_class(name: str) -> type[Master]:
    check(name)
    return MASTERS[name]


def stated_options(name: str, experiment) -> dict:
    """The options a scene's experiment states for master ``name``: its ``tolerance`` when
    ``name`` is the scene's own master (another master run on the scene keeps its defaults).
    ``TakesNoTolerance`` when the scene's master takes none."""
    if experiment.tolerance is None or name != experiment.master:
        return {}
    if "tolerance" not in master_class(name).options:
        raise TakesNoTolerance(f"experiment.tolerance = {experiment.tolerance:g}: master '{name}' takes no tolerance "
                               f"(masters that do: {', '.join(takes_tolerance())})")
    return {"tolerance": experiment.tolerance}


def takes_tolerance() -> list[str]:
    """The masters with a ``tolerance`` option."""
    return [n for n, m in MASTERS.items() if "tolerance" in m.options]


def make(name: str, system: System, step: float, **options) -> Master:
    cls = master_class(name)
    if issubclass(cls, (IterativeMaster, StepControl)) and not system.scene.connections:
        # nothing to iterate on or to estimate an error from (e.g. the rectifier scene's one FMU)
        raise MasterFailure(f"master '{name}' iterates on the values the scene's components exchange, and scene "
                            f"'{system.scene.name}' connects none: use jacobi")
    if issubclass(cls, (IterativeMaster, StepControl)):
        # these masters roll every step back with FMU states (an FMU without them would
        # refuse the first fmiGetFMUstate, or worse, return a state it cannot restore)
        lacking = [f"{n} ({c.fmu_path.name}, FMI {c.description.fmiVersion})" for n, c in
                   ((n, system.components[n]) for n in system.stateful)
                   if not getattr(c.description.coSimulation, "canGetAndSetFMUstate", True)]
        if lacking:
            raise MasterFailure(f"master '{name}' rolls steps back with FMU states, and {', '.join(lacking)} "
                                "declares canGetAndSetFMUstate = false: use a master that does not roll back "
                                "(jacobi, gauss-seidel, jacobi-linear, jacobi-quadratic, jacobi-midpoint)")
    return cls(system, step, **options)
