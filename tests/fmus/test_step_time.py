"""Communication points: a host's point may differ from the FMU's time by rounding only
(``LeverSlave.ROUNDING_ULPS`` ulps of the time's magnitude), never by a step or a fraction of
one: a step that skips or repeats time is refused, the time stays and the instance goes on.

The hosts' ways of counting time - ``t += h``, ``t0 + k*h`` (fmpy), an integer-nanosecond
clock (libcosim) - are run over a million steps on the model itself (in this process: a
native round trip per step would take minutes); the refusals at t = 1e6 s go through the
built FMU's native entry (tests/fmus/test_fmi_boundary_native.py has the helper)."""
from __future__ import annotations

import math

import pytest

from lever.fmus.sources import MisalignmentSource

STEPS = 1_000_000


def _source(start: float = 0.0) -> MisalignmentSource:
    s = MisalignmentSource(instance_name="time")
    s.setup_experiment(start)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    return s


def _errors(s) -> list[str]:
    return [m.msg for m in s.log_queue]


@pytest.mark.parametrize("clock", ["t += h", "t0 + k*h", "integer nanoseconds"])
def test_a_million_steps_of_each_hosts_clock_are_accepted(clock):
    start, h, ns_step = 0.25, 1e-4, 100_000
    s = _source(start)
    t, ns = start, 250_000_000
    for k in range(1, STEPS + 1):
        if not s.do_step(t, h if clock != "integer nanoseconds" else ns_step * 1e-9):
            pytest.fail(f"{clock}: step {k} at t = {t!r} refused: {_errors(s)[-1:]}")
        if clock == "t += h":
            t += h
        elif clock == "t0 + k*h":
            t = start + k * h
        else:
            ns += ns_step
            t = ns * 1e-9
    assert abs(s._time - t) <= s._rounding() and abs(t - (start + STEPS * h)) < 1e-6


@pytest.mark.parametrize("start", [0.0, 1.0, 1e6, -1e6, 1e12])
def test_one_ulp_either_way_is_accepted(start):
    s = _source(start)
    assert s.do_step(start, 1e-3)
    t = s._time
    assert s.do_step(math.nextafter(t, math.inf), 1e-3)
    t = s._time
    assert s.do_step(math.nextafter(t, -math.inf), 1e-3), _errors(s)


@pytest.mark.parametrize("offset", [1e-3, -1e-3, 1e-6, -1e-6, 1e-4, -1e-4])
def test_a_step_skipped_or_repeated_at_t_1e6_is_refused(offset):
    s = _source(1e6)
    assert s.do_step(1e6, 1e-4)
    t = s._time
    assert not s.do_step(t + offset, 1e-4)
    said = _errors(s)[-1]
    assert "does not match the FMU's time" in said and "rounding" in said, said
    assert s._time == t                       # nothing moved
    assert s.do_step(t, 1e-4) and s._time == t + 1e-4


def test_the_tolerance_is_a_few_ulps_not_a_fraction_of_the_time():
    s = _source(1e6)
    assert s._rounding() == MisalignmentSource.ROUNDING_ULPS * math.ulp(1e6) < 1e-9
