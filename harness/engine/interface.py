"""The interface a component offers the system and the masters, declared once: the FMU
components (``harness.engine.component.Component``) and the stability analysis's linear
stand-ins (``harness.judges.stability``) both satisfy ``CoSimComponent``.

The hot path goes through ``raw``: the C functions of a component and its instance
handle, called by the system's compiled propagation without Python overhead; a status
above 1 (FMI: error, fatal) is passed to ``fail``, which raises with what the component
knows of the failure.
"""
from __future__ import annotations

from typing import Any, Callable, Iterable, NamedTuple, Protocol, runtime_checkable


class RawCalls(NamedTuple):
    """``get_real(handle, vrs, n, values)``, ``set_real(handle, vrs, n, values)`` and
    ``do_step(handle, t, h, no_set_prior_state)`` with FMI 2.0's C signatures, each
    returning an FMI status.  ``n`` is ``count(len(vrs))``: an FMU's getter and setter
    take their arguments as ctypes objects, unconverted (``handle`` a ``c_void_p``,
    ``count`` ``c_size_t``), which saves ctypes' per-call argument conversion."""
    handle: Any
    get_real: Callable
    set_real: Callable
    do_step: Callable
    count: Callable = int


class RawModelExchangeCalls(NamedTuple):
    """A Model Exchange instance's hot-path C functions with FMI 2.0's signatures, each
    returning an FMI status, arguments as ctypes objects (``RawCalls``' convention):
    ``set_time(handle, c_double)``, ``set_states(handle, values, nx)``,
    ``get_derivatives(handle, values, nx)`` and ``directional(handle, unknowns, n_unknowns,
    knowns, n_knowns, seeds, out)``; ``nx`` is the instance's state count as a ``c_size_t``."""
    handle: Any
    set_time: Callable
    set_states: Callable
    get_derivatives: Callable
    directional: Callable
    nx: Any


class CallCounts:
    """A component's FMI calls on the hot path by kind (get, set, step): those made one by
    one (its own methods, the system's interpreting loops: ``count``) and those of the
    compiled functions that hold it (``harness.engine.straight_line``), which count their
    runs once each instead of every call (``tallies``: ``(tally, {kind: calls a run})``)."""

    def _start_counts(self):
        self.counted = {"get": 0, "set": 0, "step": 0}
        self.tallies: list[tuple[Any, dict[str, int]]] = []
        self.state_calls = 0

    def count(self, kind: str):
        """One call of ``kind`` made."""
        self.counted[kind] += 1

    def _calls_of(self, kind: str) -> int:
        return self.counted[kind] + sum(tally.runs * made.get(kind, 0) for tally, made in self.tallies)

    @property
    def gets(self) -> int:
        return self._calls_of("get")

    @property
    def sets(self) -> int:
        return self._calls_of("set")

    @property
    def steps(self) -> int:
        return self._calls_of("step")

    @property
    def calls(self) -> int:
        """FMI calls made on the hot path: read, write, do_step and the state calls."""
        return self.gets + self.sets + self.steps + self.state_calls


@runtime_checkable
class CoSimComponent(Protocol):
    name: str
    description: Any        # fmpy's ModelDescription
    calls: int              # calls made on the hot path (the sum of the four below)
    gets: int               # fmi2GetReal calls
    sets: int               # fmi2SetReal calls
    steps: int              # fmi2DoStep calls
    state_calls: int        # fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate calls
    tallies: list           # the compiled functions' counts (``CallCounts``)
    time: float
    raw: RawCalls

    def count(self, kind: str) -> None: ...

    def variable(self, name: str) -> Any: ...

    def vr(self, name: str) -> int: ...

    def real_buffer(self, names: Iterable[str]) -> tuple[Any, Any]: ...

    def read(self, vrs, values) -> None: ...

    def write(self, vrs, values) -> None: ...

    def do_step(self, t: float, h: float) -> None: ...

    def fail(self, call: str, status: int) -> None: ...

    def save_state(self) -> Any: ...

    def restore_state(self, state, time: float) -> None: ...

    def free_state(self, state) -> None: ...

    def free(self) -> None: ...
