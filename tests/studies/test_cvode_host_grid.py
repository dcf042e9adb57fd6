"""The CVODE host's output grid (harness/studies/cvode_host.py): a row every ``step`` from 0,
and the last exactly at ``stop`` - also where ``stop / step`` is no exact binary number
(0.7 s at 1 ms: 0.7 / 0.001 = 699.999..., 701 rows ending at 0.7 s; 0.3 s at 0.1 s:
2.999..., 4 rows) - a stop that is no whole number of steps (0.25 s at 0.1 s) ends on a shorter last step,
and a stop shorter than one step (0.05 s at 0.1 s) is that one step -
with each row's values those of the closed form of the FMU's motion
at that row's time.

The FMU: the load shaft's Model Exchange edition alone, its drive torque held at
``TAU`` against a constant resistance ``MEAN``, no friction: J dw/dt = TAU - MEAN, so
w(t) = w0 + (TAU - MEAN) t / J and phi(t) = phi0 + w0 t + (TAU - MEAN) t**2 / (2 J); with
viscous friction, an exponential decay in closed form (the tolerances kept); with Coulomb
and static friction against a resistance table, a stop, a stick and a breakaway worked out
by hand (the events, their log and the restarts)."""
from __future__ import annotations

import os

import numpy as np
import pytest

from harness.studies import cvode_host, me_hosts

J, TAU, MEAN, W0, PHI0 = 0.5, 30.0, 10.0, 3.0, 0.25
START = {"load_kind": "constant", "mean_torque": MEAN, "inertia": J, "w_start": W0, "phi_start": PHI0, "tau": TAU}


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("stop,step,rows", [(0.7, 1e-3, 701), (0.3, 0.1, 4), (0.5, 0.1, 6), (0.07, 0.01, 8),
                                            (0.25, 0.1, 4), (0.05, 0.1, 2)])
def test_the_rows_are_every_step_and_the_last_is_the_stop(fmi, stop, step, rows, fmu_dir):
    path = (fmu_dir if fmi == 2 else me_hosts.fmi3_dir(fmu_dir)) / "LoadShaft.fmu"
    run = cvode_host.run(path, fmi, START, ["phi", "w"], stop, step)
    assert len(run.times) == rows
    assert run.times[-1] == stop and run.t_end == stop
    grid = np.minimum(np.arange(rows) * step, stop)     # a stop that is no whole number of steps: a last, shorter one
    assert np.allclose(run.times, grid, rtol=0.0, atol=1e-12)
    assert np.all(np.diff(run.times) > 0)
    a = (TAU - MEAN) / J
    t = run.times
    assert np.allclose(run.outputs["w"], W0 + a * t, rtol=1e-6, atol=1e-8)
    assert np.allclose(run.outputs["phi"], PHI0 + W0 * t + a * t ** 2 / 2, rtol=1e-6, atol=1e-8)
    assert run.events == 0 and run.restarts == 0


@pytest.mark.parametrize("rtol,atol,within", [(1e-4, 1e-6, 1e-3), (1e-10, 1e-12, 1e-8)])
def test_the_host_keeps_the_tolerances_it_is_given(rtol, atol, within, fmu_dir):
    """With viscous friction b the speed decays to its end value exponentially, no polynomial
    BDF integrates exactly: w(t) = w_end + (W0 - w_end) exp(-b t / J), w_end = (TAU - MEAN) / b,
    phi(t) = PHI0 + w_end t + (W0 - w_end) J / b (1 - exp(-b t / J)).  The error follows the
    tolerances asked for: within ``within`` of the speed's range at each, and the tight one
    far below what CVODE's own defaults reach."""
    b = 2.0
    run = cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, {**START, "viscous_damping": b}, ["phi", "w"], 0.5, 0.01,
                         rtol=rtol, atol=atol)
    t = run.times
    w_end = (TAU - MEAN) / b
    decay = np.exp(-b * t / J)
    w = w_end + (W0 - w_end) * decay
    phi = PHI0 + w_end * t + (W0 - w_end) * J / b * (1.0 - decay)
    span = np.ptp(w)
    assert np.max(np.abs(run.outputs["w"] - w)) <= within * span
    assert np.max(np.abs(run.outputs["phi"] - phi)) <= within * np.ptp(phi)
    if rtol < 1e-6:     # and not by chance: the loose run is off by more than the tight one allows
        loose = cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, {**START, "viscous_damping": b}, ["phi", "w"], 0.5,
                               0.01, rtol=1e-4, atol=1e-6)
        assert np.max(np.abs(loose.outputs["w"] - w)) > within * span


def test_an_output_interval_may_take_thousands_of_internal_steps(fmu_dir):
    """A random load (a multisine up to 450 rad/s) at rtol 1e-10: CVODE takes far more than
    its default 500 internal steps to cross 0.5 s.  One output interval over the whole run
    ends where the same run with a row every 10 ms ends (a second run of the host, each of
    its intervals short)."""
    start = {**START, "load_kind": "random", "random_amplitude": 5.0}
    whole = cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, start, ["phi", "w"], 0.5, 0.5, rtol=1e-10, atol=1e-12)
    rows = cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, start, ["phi", "w"], 0.5, 0.01, rtol=1e-10, atol=1e-12)
    assert list(whole.times) == [0.0, 0.5] and len(rows.times) == 51
    for name in ("phi", "w"):
        assert whole.outputs[name][-1] == pytest.approx(rows.outputs[name][-1], rel=1e-8)


def test_a_run_cvode_cannot_start_says_where_it_stopped(fmu_dir):
    """Tolerances below double precision: CVODE refuses its first step, and the host's
    failure says so from where it was, the start (t = 0 s), with CVODE's reason."""
    with pytest.raises(cvode_host.HostFailure, match=r"^CVODE stopped after t = 0 s: .*accuracy.*\(status -2; after 0 "
                                                     r"events\)$"):
        cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, START, ["phi", "w"], 0.2, 0.1, rtol=1e-20, atol=1e-30)


#: the load shaft with friction against a resistance table: it slides to rest, sticks, and
#: breaks away when the table turns the resistance into a drive
STICK_SLIP = {"load_kind": "table", "table": "0:10; 0.2:10; 0.21:-30", "inertia": 0.5, "w_start": 3.0,
              "phi_start": 0.25, "tau": 0.0, "friction_torque": 5.0, "breakaway_torque": 20.0}


def test_events_by_hand_the_shaft_stops_sticks_and_breaks_away(fmu_dir):
    """By hand (J = 0.5, Fc = 5, Fs = 20, no drive): sliding against 10 + 5 N*m the shaft
    decelerates at 30 rad/s**2 from 3 rad/s and stops at t = 0.1 s (phi = 0.25 + 0.3 - 0.15
    = 0.4); stuck, the net torque -Mc grows with the table from -10 at 0.2 s to 30 at 0.21 s
    and reaches Fs = 20 at t = 0.2075 s; then a(tau) = 30 + 8000 tau (tau = t - 0.2075) until
    0.21 s, where w = 0.1 rad/s and phi = 0.4 + 15 tau**2 + 4000 tau**3 / 3; after it
    a = (30 - 5) / J = 50.  Two events, each restarting CVODE from the FMU's new state,
    each with its time and its (zero) indicator in the log; none left exactly at zero."""
    run = cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, STICK_SLIP, ["phi", "w"], 0.3, 0.01)
    assert run.events == 2 and run.restarts == 2 and run.zero_after_event == []
    assert [t for t, _ in run.log] == pytest.approx([0.1, 0.2075], abs=1e-6)
    assert all(len(z) == 1 and abs(z[0]) < 1e-6 for _, z in run.log)
    t = run.times
    gain = 15 * 0.0025 ** 2 + 4000 * 0.0025 ** 3 / 3
    w = np.select([t <= 0.1, t <= 0.2075, t >= 0.21], [3.0 - 30.0 * t, 0.0, 0.1 + 50.0 * (t - 0.21)], np.nan)
    phi = np.select([t <= 0.1, t <= 0.2075, t >= 0.21],
                    [0.25 + 3.0 * t - 15.0 * t ** 2, 0.4, 0.4 + gain + 0.1 * (t - 0.21) + 25.0 * (t - 0.21) ** 2],
                    np.nan)
    assert np.allclose(run.outputs["w"], w, rtol=0.0, atol=1e-6)
    assert np.allclose(run.outputs["phi"], phi, rtol=0.0, atol=1e-6)
    assert np.all(run.outputs["w"][(t > 0.1) & (t < 0.2075)] == 0.0)      # held at rest exactly


def test_the_events_allowed_are_the_events_counted(fmu_dir):
    """Two events (above): a host allowed two runs to the end, one allowed one stops at the
    second, saying how many it allows and when it stopped."""
    assert cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, STICK_SLIP, ["w"], 0.3, 0.01, max_events=2).events == 2
    with pytest.raises(cvode_host.HostFailure, match=r"^more than 1 events by t = 0\.2075\d* s$"):
        cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, STICK_SLIP, ["w"], 0.3, 0.01, max_events=1)


class _FaultyFmu:
    """An FMU that breaks the promises the host checks, standing in for fmpy's raw model and
    the FMI edition's calls (``_integrate``'s two seams): x' = 1 from x = 0; its indicators
    are x - 0.5 and 1 + x; at the event (x = 0.5, t = 0.5 s) it resets x to 0 and enters a
    mode whose first indicator is exactly 0 from then on - the zero a mode entered must
    never start at.  ``settles=False``: it asks for another event round every round."""

    def __init__(self, settles=True):
        self.settles, self.mode, self.x, self.t = settles, 0, 0.0, 0.0

    def setTime(self, t):
        self.t = t

    def setContinuousStates(self, x, nx):
        self.x = x[0]

    def getContinuousStates(self, x, nx):
        x[0] = self.x

    def getEventIndicators(self, z, nz):
        z[0] = self.x - 0.5 if self.mode == 0 else 0.0
        z[1] = 1.0 + self.x

    def enterEventMode(self):
        pass

    def enterContinuousTimeMode(self):
        pass

    def derivatives(self, dx, nx):
        dx[0] = 1.0

    def event_update(self):
        changed = self.mode == 0
        self.mode, self.x = 1, 0.0 if changed else self.x
        return not self.settles, False, changed

    def get(self, vrs):
        return [self.x]


def _faulty_run(fmu):
    from sksundae.cvode import CVODE

    return cvode_host._integrate(fmu, fmu, 1, 2, [0], ["x"], 1.0, 0.25, 1e-8, 1e-10, 10, CVODE)


def test_an_indicator_left_at_zero_after_an_event_is_reported_with_its_time():
    """The event at t = 0.5 s (x = 0.5) located by CVODE's root finding, x reset (one restart),
    then the first indicator exactly 0: reported as (0.5 s, [0]), the other one not; the
    rows by hand: x = t up to the event, t - 0.5 after it."""
    run = _faulty_run(_FaultyFmu())
    assert run.events == 1 and run.restarts == 1
    assert len(run.zero_after_event) == 1
    t, zeros = run.zero_after_event[0]
    assert t == pytest.approx(0.5, abs=1e-9) and zeros == [0]
    assert list(run.times) == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert np.allclose(run.outputs["x"], [0.0, 0.25, 0.0, 0.25, 0.5], rtol=0.0, atol=1e-8)


def test_an_fmu_whose_event_never_settles_is_a_failure_saying_when():
    with pytest.raises(cvode_host.HostFailure,
                       match=r"^the FMU still asked for event iterations after 100 rounds at t = 0\.5 s$"):
        _faulty_run(_FaultyFmu(settles=False))


def test_sundials_warnings_go_to_stderr_unless_the_user_sends_them_elsewhere(fmu_dir, monkeypatch):
    """SUNDIALS prints its warnings (``t + h = t``, ...) to stdout, among a host's rows, unless
    its logger's variable says otherwise: the host sets it to stderr, and keeps a user's own."""
    monkeypatch.delenv("SUNLOGGER_WARNING_FILENAME", raising=False)
    cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, START, ["w"], 0.1, 0.1)
    assert os.environ["SUNLOGGER_WARNING_FILENAME"] == "stderr"
    monkeypatch.setenv("SUNLOGGER_WARNING_FILENAME", "/dev/null")
    cvode_host.run(fmu_dir / "LoadShaft.fmu", 2, START, ["w"], 0.1, 0.1)
    assert os.environ["SUNLOGGER_WARNING_FILENAME"] == "/dev/null"
