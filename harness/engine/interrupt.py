"""Ctrl-C (SIGINT) taken at a step boundary, not wherever it lands.

A pythonfmu FMU runs its model in this interpreter, so a KeyboardInterrupt raised while
an FMU call is under way surfaces inside the FMU's code: the FMU catches it, returns
fmi2Fatal, and the run looked like an FMU failure.  Inside ``deferred()`` a SIGINT only
sets a flag; the stepping loop (``harness.engine.run.simulate``) and the studies look at
it between steps and cases and stop there with ``Interrupted``.  A second Ctrl-C while
the first is pending raises KeyboardInterrupt at once (the user insists).

Forked worker processes inherit the handler, so a study's workers stop at their next
step boundary too when the terminal sends SIGINT to the whole process group.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

_requested = False
_depth = 0


class Interrupted(KeyboardInterrupt):
    """Ctrl-C taken at a step boundary; ``time``: the simulated time reached (None
    outside a run).  A KeyboardInterrupt, so handlers of Exception let it pass."""

    def __init__(self, time: float | None = None):
        self.time = time
        super().__init__("interrupted" + (f" at t = {time:.6g} s" if time is not None else ""))

    def __reduce__(self):          # comes back from a worker process whole
        return Interrupted, (self.time,)


def _on_sigint(signum, frame):
    global _requested
    if _requested:
        raise KeyboardInterrupt
    _requested = True


def phase(name: str):
    """The process enters the phase ``name`` of its work ("stepping", "reference",
    "writing traces.csv", "plotting speeds.png", ...).  Nothing happens here: the named
    points are where a test sends SIGINT to check what each phase leaves on disk
    (``tests/engine/test_interrupts.py`` replaces this function)."""


def requested() -> bool:
    """True once Ctrl-C was pressed inside ``deferred()``."""
    return _requested


def check(time: float | None = None):
    """Raise ``Interrupted`` when Ctrl-C was pressed."""
    if _requested:
        raise Interrupted(time)


@contextmanager
def deferred():
    """SIGINT sets the flag instead of raising, while inside (nested: the outermost one
    installs and restores the handler).  A no-op outside the main thread, and where
    SIGINT is ignored or someone else handles it (a process started with SIGINT ignored
    stays so)."""
    global _depth, _requested
    if _depth or threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        # Nested, or not ours to take: a forked worker inherits our handler and flag.
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        signal.signal(signal.SIGINT, previous)
        _requested = False
