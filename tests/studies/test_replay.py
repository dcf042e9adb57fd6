"""The floor of a run's own calls (harness.studies.bench.replay): a run's FMI calls recorded
and replayed alone on fresh FMUs must leave the FMUs where the run left them, bit for bit,
and make the run's stepping calls - no more, no fewer."""
from __future__ import annotations

import array
import statistics as stats
import time

import pytest

from harness.description import scene
from harness.engine.run import simulate
from harness.paths import fmi3_dir
from harness.studies.bench import replay
from harness.studies.bench.replay import GET, SET, STEP

#: a short run: masters with state calls at start-up (jacobi-quadratic), extra coupling
#: calls (jacobi-midpoint) and rollbacks (adaptive)
SHORT = ["experiment.stop=0.03", "experiment.transient=0"]


def _scene():
    return scene.load("kavz685").with_overrides(SHORT)


def _plain(recording, calls) -> list[tuple]:
    """Recorded calls with their value references as tuples (comparable by value)."""
    refs = recording.value_references
    return [(call[0], call[1], tuple(refs[call[2]]), *call[3:]) if call[1] in (GET, SET) else call
            for call in calls]


def _replay_loop_calls(recording) -> dict:
    """Component -> kind -> count of the calls the replay times (its compiled loop)."""
    counted = {name: {"get": 0, "set": 0, "step": 0, "state": 0} for name in recording.components}
    kinds = {GET: "get", SET: "set", STEP: "step"}
    for call in recording.calls[recording.start:]:
        counted[recording.components[call[0]]][kinds.get(call[1], "state")] += 1
    return counted


@pytest.mark.parametrize("name, master", [("kavz685", "jacobi"), ("kavz685", "jacobi-quadratic"),
                                          ("kavz685", "jacobi-midpoint"), ("kavz685", "adaptive"),
                                          # four FMUs, one a source; a single FMU
                                          ("kavz685_misalignment_ramp", "jacobi-linear"),
                                          ("freewheel_rectifier", "jacobi")])
def test_the_replay_leaves_the_fmus_where_the_run_left_them_bit_for_bit(fmu_dir, name, master):
    spec = scene.load(name).with_overrides(SHORT)
    recording = replay.record(spec, master, 1e-3, fmu_dir=fmu_dir)
    assert recording.failure is None and recording.whole
    # a plain run of the master (no wrapper) as the independent account: its stepping calls
    # and its last recorded values
    run = simulate(spec, master, 1e-3, fmu_dir)
    assert run.ok
    assert recording.calls_by_kind == run.counters["calls_by_kind"]
    r = replay.Replay(recording)
    try:
        assert len(r.loop) == sum(sum(kinds.values()) for kinds in run.counters["calls_by_kind"].values())
        assert _replay_loop_calls(recording) == run.counters["calls_by_kind"]
        assert r.timed() > 0.0
        r.check()           # every real variable of each FMU as the recorded run left it
        # and as the plain run ended: its last row, bit for bit
        for name, column in run.traces.items():
            component, _, variable = name.partition(".")
            c = r.system.components[component]
            assert c.get([variable])[0] == column[-1], name
    finally:
        r.free()
    if master == "adaptive":
        assert run.counters["calls_by_kind"]["engine"]["state"] > 0      # rollbacks were replayed


def test_the_fmi3_editions_calls_replay_to_the_same_end(fmu_dir):
    """FMI 3.0's calls (fmi3GetFloat64, fmi3DoStep, the state calls of a rolling-back master)
    replay as FMI 2.0's do."""
    recording = replay.record(_scene(), "adaptive", 1e-3, fmu_dir=fmi3_dir(fmu_dir))
    assert recording.failure is None and recording.calls_by_kind["load"]["state"] > 0
    r = replay.Replay(recording)
    try:
        r.timed()
        r.check()
    finally:
        r.free()


def test_a_replay_that_is_not_the_runs_is_refused(fmu_dir):
    recording = replay.record(_scene(), "jacobi", 1e-3, fmu_dir=fmu_dir)
    # the first torque the run sent the engine, changed by a part in 1e12 (a last bit alone
    # may vanish in the shaft's sum)
    k = next(k for k in range(recording.start, len(recording.calls)) if recording.calls[k][1] == SET
             and recording.components[recording.calls[k][0]] == "engine")
    component, code, vrs, values = recording.calls[k]
    torques = array.array("d", values)
    torques[0] *= 1.0 + 1e-12
    recording.calls[k] = (component, code, vrs, torques.tobytes())
    r = replay.Replay(recording)
    try:
        r.timed()
        with pytest.raises(replay.ReplayDiverged, match="in the replay"):
            r.check()
    finally:
        r.free()
    # in the benchmark: the floor is not measured, and says why
    floor = replay.OwnCallsFloor.__new__(replay.OwnCallsFloor)
    floor.recording, floor.problem = recording, None
    floor.master, floor.step, floor.options, floor.fmu_dir = "jacobi", 1e-3, None, fmu_dir
    assert floor() is None and "not the run's" in floor.problem and floor.summary()["problem"] == floor.problem


def test_a_long_run_is_recorded_for_a_span_of_whole_steps_and_scaled(fmu_dir, monkeypatch):
    spec = _scene()
    whole = replay.record(spec, "jacobi", 1e-3, fmu_dir=fmu_dir)
    per_step = (len(whole.calls) - whole.start) // whole.steps           # 11 calls a jacobi step
    span = replay.record(spec, "jacobi", 1e-3, fmu_dir=fmu_dir, limit=10 * per_step + 1)
    assert (span.steps, span.span_steps) == (whole.steps, 11) and not span.whole
    assert _plain(span, span.calls) == _plain(whole, whole.calls[:span.start + 11 * per_step])
    r = replay.Replay(span)
    try:
        r.timed()
        r.check()           # where the span ended in the run
    finally:
        r.free()
    floor = replay.OwnCallsFloor(spec, "jacobi", 1e-3, fmu_dir=fmu_dir, limit=10 * per_step + 1)
    # a clock that moves by 1 s each time it is read: the span's one turn (11 steps, fewer
    # than a turn's) is 1 s of run and 1 s of replay, scaled to the run's 30 steps
    ticks = iter(range(1000))
    made = replay.SideBySide
    monkeypatch.setattr(replay, "SideBySide", lambda r: made(r, timer=lambda: float(next(ticks))))
    assert floor() == (pytest.approx(whole.steps / 11), pytest.approx(whole.steps / 11))
    assert floor.summary() == {"calls": 11 * per_step, "state_calls": 0, "steps": whole.steps, "span_steps": 11,
                               "problem": None}


def test_a_run_is_not_faster_than_the_replay_of_its_own_calls(fmu_dir):
    """The replay makes the run's calls and nothing else, so a run over its replay is at
    least about 1: below would be a replay that makes more than the run (its set-up timed,
    a second scene's calls).  Side by side, the median of five runs."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.3"])
    floor = replay.OwnCallsFloor(spec, "jacobi-quadratic", 1e-3, fmu_dir=fmu_dir)
    ratios = [run / replayed for run, replayed in (floor() for _ in range(5))]
    assert stats.median(ratios) > 0.95, ratios


def test_the_turns_replay_every_recorded_call_once_in_order(fmu_dir):
    """``SideBySide``'s turns split the replay's loop at the run's step boundaries: every
    call once, in the order made, the last turn shorter where the steps do not divide."""
    spec = _scene()          # 30 steps: turns after steps 25 and 30
    recording = replay.record(spec, "jacobi-midpoint", 1e-3, fmu_dir=fmu_dir)
    r = replay.Replay(recording)
    try:
        turns = replay.SideBySide(r)
        assert list(turns.turns) == [25, 30]
        assert [call for calls in turns.turns.values() for call in calls] == r.loop
        per_step = len(r.loop) // recording.steps
        assert [len(calls) for calls in turns.turns.values()] == [25 * per_step, 5 * per_step]
        assert [len(calls) for calls in replay.SideBySide(r, chunk=7).turns.values()] == \
            [7 * per_step] * 4 + [2 * per_step]
    finally:
        r.free()


def test_a_slower_harness_shows_in_the_run_side_by_side(fmu_dir, monkeypatch):
    """The run's turns hold what the master does beyond its calls and the replay's turns the
    calls alone: a master made to spend about one step's calls' time again in Python (a loop
    sized to it, so that it slows with the machine as the calls do) raises the run against
    its replay by a half or more (about 1 on an idle machine; on a busy one more, as the
    replay's time a step, which the loop is sized to, includes the time others took from
    it, and the loop's short calibration laps mostly do not); counted on the replay's side,
    it would lower it."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.2"])
    floor = replay.OwnCallsFloor(spec, "jacobi", 1e-3, fmu_dir=fmu_dir)
    plain = [floor() for _ in range(3)]
    per_step = stats.median(replayed for _, replayed in plain) / floor.recording.steps

    def spin(n):
        total = 0
        for i in range(n):
            total += i
        return total
    laps = []
    for _ in range(5):
        started = time.perf_counter()
        spin(10_000)
        laps.append(time.perf_counter() - started)
    turns = max(1, round(per_step / (stats.median(laps) / 10_000)))
    from harness.engine.masters.explicit import JacobiMaster
    made = JacobiMaster._step_impl

    def slower(self, t, h):
        made(self, t, h)
        spin(turns)
    monkeypatch.setattr(JacobiMaster, "_step_impl", slower)
    slowed = [floor() for _ in range(3)]
    ratio = stats.median(run / replayed for run, replayed in plain)
    slowed_ratio = stats.median(run / replayed for run, replayed in slowed)
    assert 0.9 < ratio < 1.6, plain
    assert slowed_ratio - ratio > 0.5, (plain, slowed)


def test_runs_faster_than_their_own_replay_are_no_result():
    """The overhead is each run over its replay, the two side by side (the case's timed runs
    give its run time, not this figure); a run below its replay (which makes the same calls
    and nothing else) says the machine changed between the turns."""
    from harness.studies import bench
    from harness.studies.bench.schedule import Case

    case = Case("jacobi-quadratic", "master", 5e-3, wall_times=[1.3, 1.0, 1.4], steps=2000, asked=3,
                own_calls_pairs=[[1.2, 1.0], [1.1, 1.0], [1.5, 1.0]], load=[1.0, 1.0], errors={"tau_rms": 1e-3})
    found = bench.overhead_above_own_calls(case)
    assert found == {"median": pytest.approx(0.2), "min": pytest.approx(0.1), "max": pytest.approx(0.5), "n": 3}
    assert bench.case_problems(case) == []
    row = bench.table_row(case)
    assert row["overhead_above_own_calls"] == pytest.approx(0.2) and row["own_calls_floor_s"] == 1.0
    case.own_calls_pairs = [[1.2, 1.3], [1.1, 1.2], [1.5, 1.2]]     # ratios 0.92, 0.92, 1.25
    assert bench.case_problems(case) == ["the runs took 8 % less than the replay of their own calls timed side "
                                         "by side (the same calls and nothing else)"]
    row = bench.table_row(case)
    assert row["overhead_above_own_calls"] is None and "the replay of their own calls" in row["unreliable"]
    # as quoted, to the percent: 0 % is no contradiction
    case.own_calls_pairs = [[1.2, 1.2 / 0.996], [1.1, 1.1 / 0.996], [1.5, 1.5 / 0.996]]
    assert bench.case_problems(case) == [] and bench.table_row(case)["overhead_above_own_calls"] < 0.0
    # a run without a replay for every run has no figure
    case.own_calls_pairs = [[1.2, 1.0], [1.1, 1.0]]
    assert bench.overhead_above_own_calls(case) is None and bench.case_problems(case) == []


@pytest.mark.parametrize("name, master", [("kavz685_misalignment_ramp", "jacobi-linear"),
                                          ("freewheel_rectifier", "jacobi"), ("kavz685", "gauss-seidel")])
def test_a_run_side_by_side_with_its_replay_ends_where_the_run_alone_does(fmu_dir, name, master):
    """In turns with a run, the replay still makes the run's calls and leaves every real
    variable of each FMU as the recorded run did (``Replay.check`` inside), on scenes of
    other shapes: four FMUs with a source, a single FMU, a master that steps in sequence."""
    spec = scene.load(name).with_overrides(SHORT)
    floor = replay.OwnCallsFloor(spec, master, 1e-3, fmu_dir=fmu_dir)
    pair = floor()
    assert floor.problem is None and pair is not None and all(seconds > 0.0 for seconds in pair)


def test_the_pages_name_the_turns_the_bench_takes():
    """The turns' length the docs state is the bench's own (``CHUNK_STEPS``)."""
    from harness.paths import ROOT

    for page in ("docs/masters-and-stability.md", "docs/record/decisions.md"):
        text = " ".join((ROOT / page).read_text().split())
        assert f"turns of {replay.CHUNK_STEPS} steps" in text, page
