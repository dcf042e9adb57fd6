"""Step observers: what ``harness.engine.run.simulate`` tells about its stepping loop to
whoever asks (``simulate(observer=...)``), without a copy of the loop.

An observer has ``started(t)`` (the loop is about to take its first step), ``stepped(n, t)``
(step ``n`` is done: stepped, recorded, checked) and ``ended()``.  A run without one pays
a single ``is not None`` test a step.

``StepTimer`` times every step for real-time use (hardware in the loop): wall time, the
process's CPU time, involuntary context switches (the OS gave the CPU to another process
in the step) and the garbage collections that ran in it (``gc.callbacks``).
"""
from __future__ import annotations

import gc
import time as clock
from array import array

try:
    import resource
except ImportError:           # not on Windows: no context-switch counts there
    resource = None


class StepTimer:
    """Wall time, CPU time and involuntary context switches of each step, and the garbage
    collections with the step they ran in (index into the arrays) and how long they took."""

    def __init__(self):
        self.wall = array("d")
        self.cpu = array("d")
        self.switches = array("l")
        self.times = array("d")
        #: (step index, seconds, generation) of each collection during the loop
        self.collections: list[tuple[int, float, int]] = []
        self._gc_started = 0.0
        self._last = self._last_cpu = 0.0
        self._last_switches = 0

    @staticmethod
    def _switches() -> int:
        return resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw if resource else 0

    def started(self, t: float):
        gc.callbacks.append(self._on_gc)
        self._last_switches = self._switches()
        self._last_cpu = clock.process_time()
        self._last = clock.perf_counter()

    def stepped(self, n: int, t: float):
        now = clock.perf_counter()
        cpu = clock.process_time()
        switches = self._switches()
        self.wall.append(now - self._last)
        self.cpu.append(cpu - self._last_cpu)
        self.switches.append(switches - self._last_switches)
        self.times.append(t)
        # the observer's own reads are left out of the next step
        self._last_switches = switches
        self._last_cpu = clock.process_time()
        self._last = clock.perf_counter()

    def ended(self):
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)

    def _on_gc(self, phase: str, info: dict):
        if phase == "start":
            self._gc_started = clock.perf_counter()
        else:
            self.collections.append((len(self.wall), clock.perf_counter() - self._gc_started, info["generation"]))


class PaceWatch:
    """Says once how long a run will take when it will take long: after ``after`` seconds of
    stepping, the run's own pace so far (simulated time per wall second) projected to its
    stop time; ``say(message)`` is called when the whole would exceed ``longer_than``
    seconds.  The clock is read every ``EVERY`` steps only."""

    EVERY = 32

    def __init__(self, stop: float, say, after: float = 1.0, longer_than: float = 10.0):
        self.stop, self.say, self.after, self.longer_than = stop, say, after, longer_than
        self.said = False
        self._start = self._t0 = 0.0

    def started(self, t: float):
        self._t0, self._start = t, clock.perf_counter()

    def stepped(self, n: int, t: float):
        if self.said or n % self.EVERY:
            return
        elapsed = clock.perf_counter() - self._start
        done = (t - self._t0) / (self.stop - self._t0) if self.stop > self._t0 else 1.0
        if elapsed < self.after or not 0.0 < done < 1.0:
            return
        self.said = True
        total = elapsed / done
        if total > self.longer_than:
            self.say(f"the run takes about {duration(total)} ({100 * done:.2g} % of t = {self._t0:g} ... "
                     f"{self.stop:g} s done in {elapsed:.2g} s; about {duration(total - elapsed)} to go)")

    def ended(self):
        pass


def duration(seconds: float) -> str:
    """A wait in words to two digits: "8.4 s", "3.5 min", "1.2 h"."""
    return f"{seconds:.2g} s" if seconds < 90 else f"{seconds / 60:.2g} min" if seconds < 5400 else \
        f"{seconds / 3600:.2g} h"
