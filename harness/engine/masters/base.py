"""Co-simulation masters: how a system of FMUs is stepped from one communication point
to the next.

Like scipy's ``OdeSolver``, one base class states the contract and keeps the books, and
each master implements one step in ``_step_impl``:

* ``step(h)`` advances the system from ``t`` to ``t + h`` and leaves it *consistent*
  at the new time: every connected input holds its source's current output, so a
  recorder can read any exposed value.  It raises ``FmuCallError`` (from the component
  that failed) and otherwise returns nothing.
* Counters: ``n_steps`` (accepted steps), ``n_rollbacks``, ``n_iterations`` (coupled
  evaluations beyond the first in a step, including those for Jacobians), ``n_rejected``;
  ``fmu_calls`` counts the FMI calls on the hot path (read, write, doStep and the state
  calls) of all components.
* Variable steps: an ``adaptive`` master chooses its own step; ``step()`` without
  arguments takes the step it proposes (``h``), clipped to ``t_end``.
* A master that cannot make a step (an iteration that does not converge, a step size
  that underflows) raises ``MasterFailure`` saying where, when and why.
* ``order``: the global convergence order the master promises on smooth problems
  (the tests check it against the monolithic reference).

Masters know nothing of the models: only the system's stateful components (no direct
feedthrough, stepped in scene order) and its propagation; the components offer them
``harness.engine.interface.CoSimComponent``.

The family: this contract (``base``), the explicit masters (``explicit``: zero-order
hold, Gauss-Seidel, extrapolation, mid-step prediction), the iterative ones
(``iterative``: implicit and trapezoidal coupling, fixed point or Newton, with
rollback), the adaptive ones (``adaptive``: error-controlled steps), the strongly coupled
one (``model_exchange``: the FMUs in Model Exchange, integrated together by CVODE; its
``interface`` says the system instantiates them so), and the registry (``registry``), the
one place a master's name is looked up and checked.
"""
from __future__ import annotations

from harness.description.scene import step_problem
from harness.engine.system import CO_SIMULATION, Inputs, System


class MasterFailure(RuntimeError):
    """A master could not make a step; the system is left at the last accepted step."""


class Master:
    """One co-simulation master: ``step(h)`` advances the system by one communication step.

    What the linear stability analysis (``harness.judges.stability``) replays a master's
    step through, public for that reason and kept stable: ``save_states()`` /
    ``restore_states(states, t)`` (the stateful FMUs' full states); and, where a family has
    them, ``coupled_inputs`` (the ``Inputs`` buffers, component, value references and
    values, of the inputs it predicts), ``history`` (the past communication points ``(t, values)`` its predictor
    uses, oldest first), ``current_inputs()`` and ``evaluate(...)`` (an iterative master's
    fixed-point map ``u -> G(u)``)."""

    name = "abstract"
    order = 0
    description = ""
    adaptive = False
    #: the FMI interface the master's system instantiates the FMUs in
    interface = CO_SIMULATION
    #: the master reads every recorded output itself at the end of each step (the ones that
    #: depend on inputs after those are written), so ``step`` need not read them again
    reads_recorded = False
    #: options ``make`` accepts for this master, with their defaults
    options: dict = {}

    def __init__(self, system: System, step: float, **options):
        if problem := step_problem(step, "communication step"):
            raise ValueError(problem)
        unknown = set(options) - set(self.options)
        if unknown:
            raise ValueError(f"master '{self.name}' takes no option {', '.join(sorted(unknown))}"
                             + (f" (it takes: {', '.join(self.options)})" if self.options else ""))
        for key, default in self.options.items():
            setattr(self, key, options.get(key, default))
        self.system = system
        self.h = float(step)
        self.t = system.scene.experiment.start
        self.t_end = system.scene.experiment.stop
        self.n_steps = 0
        self.n_rollbacks = 0
        self.n_iterations = 0
        self.n_rejected = 0
        self._stateful = [system.components[n] for n in system.stateful]
        self._feedthrough = [n for n in system.order if n in system.feedthrough]
        # every component's doStep, compiled once (a step costs about 100 us: each
        # attribute lookup saved shows)
        self._steps = system.step_plan(system.components)
        self._stateful_steps = system.step_plan(system.stateful)
        self._feedthrough_steps = system.step_plan(self._feedthrough)
        #: ``(t, h)``: fmi2DoStep of the stateful components, then of the feedthrough ones
        #: (one straight-line function each: ``System.runner``)
        self._step_stateful = system.runner((), self._stateful_steps)
        self._step_feedthrough = system.runner((), self._feedthrough_steps)
        #: set by a step that left the coupled inputs in their buffers only (a held plan)
        self._inputs_unsent = False

    @property
    def fmu_calls(self) -> int:
        return self.system.fmu_calls

    def step(self, h: float | None = None, t_next: float | None = None):
        """Advance by ``h`` (default: the master's step).  ``t_next`` may give the
        target time exactly, to avoid accumulating rounding in ``t``."""
        t = self.t
        target = (t + (self.h if h is None else h)) if t_next is None else t_next
        taken = self._step_impl(t, target - t)
        if self.system.has_dependent_outputs and not self.reads_recorded:
            # recorded outputs that depend on inputs (a shaft's acceleration on its torque)
            # were read before the step's last inputs were written: read them with those
            self.system.refresh_dependent(send=self._inputs_unsent)
            self._inputs_unsent = False
        # An adaptive master may take less than it was offered; it returns what it took.
        self.t = target if taken is None else t + taken
        self.n_steps += 1

    def _step_impl(self, t: float, h: float):
        """Advance the system from ``t`` by ``h``; return ``None``, or the step actually
        taken if it is shorter (adaptive masters)."""
        raise NotImplementedError

    def counters(self) -> dict:
        return {"steps": self.n_steps, "fmu_calls": self.fmu_calls, "rollbacks": self.n_rollbacks,
                "iterations": self.n_iterations, "rejected": self.n_rejected}

    # -- shared helpers ------------------------------------------------------------------------
    def _coupled_inputs(self):
        """The input buffers of stateful components that propagation fills (the coupling
        torques), as the last propagation left them: ``[Inputs]``."""
        system = self.system
        return [Inputs(share.component, share.vrs, share.values) for shares in system.writes.values()
                for share in shares if share.component.name in system.stateful]

    # Full FMU states of the stateful components, for masters that roll back.
    def save_states(self) -> list:
        return [component.save_state() for component in self._stateful]

    def restore_states(self, states, t):
        for component, state in zip(self._stateful, states):
            component.restore_state(state, t)
        self.n_rollbacks += 1

    def _free_states(self, states):
        for component, state in zip(self._stateful, states):
            component.free_state(state)
