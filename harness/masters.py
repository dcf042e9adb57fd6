"""Co-simulation masters: how a system of FMUs is stepped from one communication point
to the next.

Like scipy's ``OdeSolver``, one base class states the contract and keeps the books, and
each master implements one step in ``_step_impl``:

* ``step(h)`` advances the system from ``t`` to ``t + h`` and leaves it *consistent*
  at the new time: every connected input holds its source's current output, so a
  recorder can read any exposed value.  It raises ``FmuCallError`` (from the component
  that failed) and otherwise returns nothing.
* Counters: ``n_steps``, ``n_rollbacks``, ``n_iterations``; ``fmu_calls`` counts the
  FMI calls on the hot path (read, write, doStep) of all components.
* ``order``: the global convergence order the master promises on smooth problems
  (the tests check it against the monolithic reference).

Masters know nothing of the models: only the system's stateful components (no direct
feedthrough, stepped in scene order) and its propagation.
"""
from __future__ import annotations

from .system import System


class Master:
    name = "abstract"
    order = 0
    description = ""

    def __init__(self, system: System, step: float):
        if not step > 0.0:
            raise ValueError(f"communication step must be > 0, got {step}")
        self.system = system
        self.h = float(step)
        self.t = system.scene.experiment.start
        self.n_steps = 0
        self.n_rollbacks = 0
        self.n_iterations = 0

    @property
    def fmu_calls(self) -> int:
        return self.system.fmu_calls

    def step(self, h: float | None = None, t_next: float | None = None):
        """Advance by ``h`` (default: the master's step).  ``t_next`` may give the
        target time exactly, to avoid accumulating rounding in ``t``."""
        h = self.h if h is None else h
        target = self.t + h if t_next is None else t_next
        self._step_impl(self.t, target - self.t)
        self.t = target
        self.n_steps += 1

    def _step_impl(self, t: float, h: float):
        raise NotImplementedError

    def counters(self) -> dict:
        return {"steps": self.n_steps, "fmu_calls": self.fmu_calls, "rollbacks": self.n_rollbacks,
                "iterations": self.n_iterations}


class JacobiMaster(Master):
    """All components step in parallel on the inputs of ``t`` (zero-order hold), then
    the outputs of ``t + h`` are propagated."""

    name = "jacobi"
    order = 1
    description = "parallel steps, inputs held from the start of the step (zero-order hold)"

    def _step_impl(self, t, h):
        system = self.system
        for component in system.components.values():
            component.do_step(t, h)
        system.propagate()


class GaussSeidelMaster(Master):
    """Stateful components step one after the other; after each, its new outputs are
    propagated (through the coupling, evaluated on the shafts' current states) before
    the next one steps."""

    name = "gauss-seidel"
    order = 1
    description = "sequential steps, each shaft sees the coupling on the latest states"

    def _step_impl(self, t, h):
        system = self.system
        components = system.components
        for name in system.stateful:
            components[name].do_step(t, h)
            system.propagate([name])
        for name in system.feedthrough:
            components[name].do_step(t, h)


MASTERS = {cls.name: cls for cls in (JacobiMaster, GaussSeidelMaster)}


def make(name: str, system: System, step: float) -> Master:
    try:
        return MASTERS[name](system, step)
    except KeyError:
        raise ValueError(f"unknown master '{name}' (known: {', '.join(MASTERS)})") from None
