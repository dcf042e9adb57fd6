"""Events under the Model Exchange master ``me-cvode``: after an event CVODE restarts from
the states the FMUs' event update reports, not from its own.  Our FMUs' updates mostly
snap a state to the value it already has at the root (a stopping load sets w = 0 where w
crossed zero), so two runs check it where it shows: a ball whose event update reverses
its velocity (BouncingBall, a Model Exchange FMU in C of the suite's own making,
tests/engine/foreign_fmu) against its closed form, and a load held by friction whose
speed is exactly zero from its stop on."""
from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.description import scene as scenes
from harness.engine.run import simulate

sys.path.insert(0, str(Path(__file__).parent / "foreign_fmu"))
import build as foreign  # noqa: E402

#: CVODE's global error on these runs stays within a few times its local tolerance; the
#: bound the Model Exchange master's tests hold it to (test_model_exchange_master.BOUND)
BOUND = 50.0
GRAVITY, RESTITUTION, DROP = 9.81, 0.7, 1.0


@pytest.fixture(scope="module")
def ball_scene(tmp_path_factory) -> scenes.Scene:
    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler")
    folder = tmp_path_factory.mktemp("ball")
    foreign.build_bouncing_ball(folder)
    path = folder / "ball.toml"
    path.write_text(f'''name = "bouncing_ball"
description = "A ball dropped from {DROP} m, bouncing back with {RESTITUTION} of its speed"
connections = []
record = ["ball.h", "ball.v"]
[experiment]
start = 0.0
stop = 2.0
step = 0.01
master = "me-cvode"
transient = 0.0
[components.ball]
fmu = "BouncingBall.fmu"
[components.ball.parameters]
g = {GRAVITY}
e = {RESTITUTION}
h0 = {DROP}
''')
    return scenes.load(path)


def bouncing_ball(t: float) -> tuple[float, float]:
    """Height and velocity at ``t`` in closed form: parabolas between the bounces, each
    bounce leaving with ``RESTITUTION`` times the speed it arrived with."""
    start, h, v = 0.0, DROP, 0.0
    while True:
        flight = (v + math.sqrt(v * v + 2.0 * GRAVITY * h)) / GRAVITY      # until h = 0
        if t < start + flight:
            s = t - start
            return h + v * s - 0.5 * GRAVITY * s * s, v - GRAVITY * s
        start, h, v = start + flight, 0.0, RESTITUTION * (GRAVITY * flight - v)


def bounce_times(stop: float) -> list[float]:
    times, start, v = [], math.sqrt(2.0 * DROP / GRAVITY), math.sqrt(2.0 * GRAVITY * DROP)
    while start < stop:
        times.append(start)
        v *= RESTITUTION
        start += 2.0 * v / GRAVITY
    return times


@pytest.mark.parametrize("method", ["Adams", "BDF"])
def test_a_velocity_reversed_by_the_event_update_is_where_cvode_restarts(ball_scene, method):
    tolerance = 1e-6
    result = simulate(ball_scene, "me-cvode", options={"tolerance": tolerance, "method": method})
    assert result.ok, result.failure
    exact = np.array([bouncing_ball(t) for t in result.times])
    # at the four bounces v jumps by up to 7.5 m/s; restarted from CVODE's own states the
    # ball would fall on through the floor (h -18.7 m at 2 s)
    height_error = np.max(np.abs(result.traces["ball.h"] - exact[:, 0]))
    speed_error = np.max(np.abs(result.traces["ball.v"] - exact[:, 1]))
    impact = math.sqrt(2.0 * GRAVITY * DROP)
    assert height_error <= BOUND * tolerance * DROP, f"height off its closed form by {height_error:.3g} m"
    assert speed_error <= BOUND * tolerance * impact, f"velocity off its closed form by {speed_error:.3g} m/s"
    assert np.all(result.traces["ball.h"] >= -BOUND * tolerance * DROP)
    assert result.counters["events"] == len(bounce_times(2.0)) == 4
    assert result.counters["time_events"] == 0      # the ball's nextEventTime is not defined


def test_a_held_load_is_at_rest_exactly_from_its_stop_on():
    # kavz685_stall_resistive: the brake and the bearing's stiction hold 708 N*m > 623 N*m
    # the engine can give, so the driven shaft stops (at 0.012-0.013 s) and stays held.
    # The load's event update puts w = 0 exactly at the stop; CVODE's own state there is a
    # rounding away from it (-4.4e-16 rad/s), which a held mode (every derivative 0) keeps.
    scene = scenes.load("kavz685_stall_resistive").with_overrides(["experiment.stop=0.05",
                                                                    "experiment.transient=0.025"])
    result = simulate(scene, "me-cvode")
    assert result.ok, result.failure
    assert result.counters["events"] == 1
    w, a = result.traces["load.w"], result.traces["load.a"]
    assert w[result.times <= 0.012].min() > 0.0
    held = result.times >= 0.014
    assert np.all(w[held] == 0.0) and np.all(a[held] == 0.0), \
        f"held load's speed not exactly 0 after its stop: {w[held][w[held] != 0.0][:3]} rad/s"


def test_time_events_of_an_fmu_without_states(tmp_path):
    # a misalignment source alone: no state for CVODE to integrate, its table's points
    # (0.25, 0.5, 0.75 s) still time events, handled in event mode one by one
    path = tmp_path / "tilt.toml"
    path.write_text('''name = "tilt_alone"
description = "A misalignment source alone"
connections = []
record = ["tilt.misalignment", "tilt.misalignment_rate"]
[experiment]
start = 0.0
stop = 1.0
step = 0.01
master = "me-cvode"
transient = 0.0
[components.tilt]
fmu = "MisalignmentSource"
[components.tilt.parameters]
table = "0:15; 0.25:15; 0.5:17; 0.75:15"
table_unit = "deg"
''')
    result = simulate(scenes.load(path), "me-cvode")
    assert result.ok, result.failure
    assert (result.counters["time_events"], result.counters["events"]) == (3, 0)
    expected = np.interp(result.times, [0.0, 0.25, 0.5, 0.75], [15.0, 15.0, 17.0, 15.0])
    assert np.max(np.abs(np.degrees(result.traces["tilt.misalignment"]) - expected)) <= 1e-12
