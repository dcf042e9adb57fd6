"""The work-precision benchmark: its interpolation, and a small end-to-end run that
writes every artefact."""
from __future__ import annotations

import csv
import json
import math

import pytest

from harness.studies import bench
from harness.description import scene
from harness.studies.bench import Case
from harness.engine import masters


def _case(wall, error, engine="m"):
    c = Case(engine, "master", 1e-3, wall_times=[wall], errors={"tau_rms": error})
    return c


def test_time_at_error_interpolates_log_log():
    cases = [_case(1.0, 1e-2), _case(4.0, 1e-4)]
    assert bench.time_at_error(cases, 1e-3) == pytest.approx(2.0)
    assert bench.time_at_error(cases, 1e-2) == pytest.approx(1.0)
    assert bench.time_at_error(cases, 1e-5) is None           # never reached
    assert bench.time_at_error(cases, 1.0) == pytest.approx(1.0)


def test_failed_runs_are_left_out_of_the_curves():
    failed = Case("m", "master", 1e-3, wall_times=[0.1], failure="diverged")
    assert bench.time_at_error([failed, _case(2.0, 1e-4)], 1e-3) == pytest.approx(2.0)


def test_claims_compare_the_target_time_with_the_largest_stable_baseline_step():
    spec = scene.load("kavz685_stiff")              # omega_n = 1184 rad/s
    diverged = Case("jacobi", "master", 1e-4, wall_times=[0.8], failure="diverged")
    stable = Case("jacobi", "master", 7e-5, wall_times=[8.0], errors={"tau_rms": 4e-2}, energy_residual=1e-6)
    coarse = Case("adaptive-trapezoidal", "master", 1e-4, 2e-2, wall_times=[0.4], errors={"tau_rms": 2e-2},
                  energy_residual=1e-5, largest_step=6e-3)
    fine = Case("adaptive-trapezoidal", "master", 1e-4, 1e-2, wall_times=[1.0], errors={"tau_rms": 5e-3},
                energy_residual=1e-6, largest_step=3e-3)
    claims = bench.claims(spec, [diverged, stable, coarse, fine], {"target_error": 1e-2, "baseline": "jacobi"})
    largest = claims["largest_stable_baseline_step"]
    assert largest["step"] == 7e-5 and largest["wall_s"] == 8.0
    at_target = bench.time_at_error([coarse, fine], 1e-2)
    assert largest["time_fraction_at_target"] == {"adaptive-trapezoidal": pytest.approx(at_target / 8.0)}
    # an adaptive run counts at h * omega_n >= 5 by the longest step it took (6e-3 s: 7.1)
    runs = claims["at_h_omega_5_or_more"]["adaptive-trapezoidal"]
    assert [(r["tolerance"], round(r["h_omega"], 1), r["stable"]) for r in runs] == [(2e-2, 7.1, True)]
    text = bench.markdown({"claims": claims, "scene": spec.name, "repeats": 1, "floor_per_step_s": 5e-5}, [])
    assert f"({8.0 / at_target:.1f}x (medians measured apart, not side by side) faster)" in text and "longest step 0.006 s" in text


def _fewer_timed_steps(monkeypatch):
    """The benchmark's floors and call prices timed on a few hundred steps instead of
    thousands (a floor 500 steps, a pricing 100, the editions' turns every 30 steps): every
    figure is still measured and goes through the table, the split, the claims and the
    case log - what these tests check is what is done with the figures, not how precise
    they are (a noisy figure is flagged, and the tests take that branch as on a busy machine)."""
    from harness.studies.bench import editions, timing

    floor = bench.call_floor
    monkeypatch.setattr(bench.floors, "call_floor", lambda scene, fmu_dir, n_steps=0, step=None:
                        floor(scene, n_steps=500, fmu_dir=fmu_dir, step=step))
    monkeypatch.setattr(timing, "PRICE_STEPS", 100)
    monkeypatch.setattr(timing, "TIMED_RUNS", 2)
    monkeypatch.setattr(editions, "FLOOR_STEPS", 200)
    monkeypatch.setattr(editions, "PRICE_STEPS", 100)
    monkeypatch.setattr(editions, "CHUNK", 30)


def test_small_bench_writes_its_table_plot_and_claims(tmp_path, fmu_dir, monkeypatch):
    _fewer_timed_steps(monkeypatch)
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.3", "experiment.transient=0.1"])
    spec.bench = {"steps": {"jacobi": [2e-3, 1e-3], "jacobi-quadratic": [2e-3]},
                  "tolerances": {"adaptive": [1e-2]}, "target_error": 5e-3, "monolithic_rtol": [1e-6]}
    result = bench.bench(spec, repeats=1, fmu_dir=fmu_dir, peers=False)
    paths = bench.write(tmp_path, result)
    assert {p.name for p in paths} == {"bench.csv", "bench.json", "bench.md", "work_precision.png"}
    rows = list(csv.DictReader(open(tmp_path / "bench.csv")))
    assert [r["engine"] for r in rows] == ["jacobi", "jacobi", "jacobi-quadratic", "adaptive", "monolithic"]
    jacobi = [r for r in rows if r["engine"] == "jacobi"]
    assert float(jacobi[1]["tau_rms"]) < float(jacobi[0]["tau_rms"])   # smaller step, smaller error
    # the overhead is the run's time over the floor of the same calls (not a timing bound:
    # under load either can be anything; a floor above the step is flagged, no overhead shown
    # beside a run time that is no result)
    # Two floors: the one-step FMU-call floor times the steps, and the replay of the run's
    # own calls (one run: the run side by side with its replay, over the replay)
    for r in jacobi + [r for r in rows if r["engine"] == "jacobi-quadratic"]:
        assert float(r["floor_s"]) > 0.0 and float(r["own_calls_floor_s"]) > 0.0 and not r["own_calls_note"], r
        if r["unreliable"]:
            assert r["overhead_above_call_floor"] == r["overhead_above_own_calls"] == "", r
            continue
        assert float(r["overhead_above_call_floor"]) == pytest.approx(
            float(r["wall_median_s"]) / float(r["floor_s"]) - 1.0, rel=1e-9), r
        assert float(r["overhead_above_own_calls"]) == pytest.approx(
            float(r["own_calls_run_s"]) / float(r["own_calls_floor_s"]) - 1.0, rel=1e-9), r
        assert r["overhead_above_own_calls_min"] == r["overhead_above_own_calls_max"] == r["overhead_above_own_calls"]
    # an adaptive master's run has no replayed floor (its steps are its own)
    assert [r["own_calls_floor_s"] for r in rows if r["engine"] == "adaptive"] == [""]
    written = json.loads((tmp_path / "bench.json").read_text())
    # the signals each error column is the larger of, named as the traces name them
    assert written["judged"] == {"tau": ["coupling.tau1", "coupling.tau2"], "w": ["engine.w", "load.w"]}
    assert "torque: the larger of coupling.tau1 and coupling.tau2, speed: the larger of engine.w and load.w" in \
        (tmp_path / "bench.md").read_text()
    claims = written["claims"]
    # The best master is the one of least (interpolated) time at the target error, read off
    # the claims' own table; jacobi-quadratic reaches the 0.5 % target on this plan.
    at_target = claims["time_at_target_s"]
    assert at_target["jacobi-quadratic"] > 0.0 and math.isfinite(at_target["jacobi-quadratic"])
    reached = {name: t for name, t in at_target.items() if t is not None and name in masters.MASTERS}
    assert claims["best_master"] == min(reached, key=reached.get), (claims["best_master"], at_target)
    if reached.get("jacobi"):
        assert claims["speedup_over_baseline"] == pytest.approx(reached["jacobi"] / reached[claims["best_master"]])
    assert math.isfinite(result["floor_per_step_s"]) and result["floor_per_step_s"] > 0
    assert "At an RMS torque error" in (tmp_path / "bench.md").read_text()
    # Where the time goes: every master case is split, the parts adding up to its time;
    # a jacobi step makes 11 FMI calls (3 steps, 3 reads, 3 sets - one per target - and
    # the shafts' accelerations read again), the floor's calls
    assert result["hollow_floor_per_step_s"] > 0
    # (a split that cannot be - a share below zero on a busy machine - is left out, with why;
    # so is the split of a run time that is no result on a busy machine, which says why in
    # `unreliable`)
    for r in rows[:-1]:
        if r["split_unreliable"]:
            assert r["crossing_s"] == "" and ("machine too noisy" in r["split_unreliable"]
                                              or "not the machine's noise" in r["split_unreliable"]), r
            continue
        if r["unreliable"]:
            assert r["crossing_s"] == "" and r["slave_s"] == "" and r["master_s"] == "", r
            continue
        parts = [float(r[f"{part}_s"]) for part in ("crossing", "slave", "master")]
        assert parts[0] > 0 and min(parts) >= 0 and sum(parts) == pytest.approx(float(r["wall_median_s"])), r
    assert [float(r["calls_per_step"]) for r in jacobi] == [11.0, 11.0]
    # the step against the do-nothing floor: timed side by side, round by round
    rounds = result["rounds"]
    key = bench.case_key("master", "jacobi", 1e-3, None)
    per_step = rounds["walls"][key][0] / float(jacobi[1]["steps"])
    step = claims["baseline_step"]
    assert step["ratio"]["ratios"] == pytest.approx([per_step / rounds["hollow_floor"][0]])
    assert step["ratio"]["single_run"] and "a single run" in (tmp_path / "bench.md").read_text()
    # the bound a master that cost nothing would meet: the floor plus our slaves' own work
    if "slave_per_step_s" in step:
        slave_per_step = float(jacobi[1]["slave_s"]) / float(jacobi[1]["steps"])
        assert step["slave_per_step_s"] == pytest.approx(slave_per_step)
        assert step["bound_without_master"] == pytest.approx(1.0 + float(jacobi[1]["slave_s"]) / float(jacobi[1]["crossing_s"]))
        assert "even a master that cost nothing" in (tmp_path / "bench.md").read_text() or step.get("unreliable")
    assert json.loads((tmp_path / "bench.json").read_text())["machine"]["cpus"] >= 1
    assert "## Where the time goes" in (tmp_path / "bench.md").read_text()
    # the report names the floor each overhead is against
    own = claims["overhead_above_own_calls"]
    if own:
        assert "above the floor of each run's own FMI calls (a run over a replay" in \
            (tmp_path / "bench.md").read_text()
        assert any(line.startswith("  above the floor of its own FMI calls (the run's calls replayed alone, in "
                                   "turns of 25 steps with the run): ")
                   for line in bench.summary_lines(result))
    # the FMI 2.0 and FMI 3.0 editions, side by side under the baseline at the scene's step
    editions = json.loads((tmp_path / "bench.json").read_text())["fmi_editions"]
    assert (editions["master"], editions["step"], editions["steps"]) == ("jacobi", 1e-3, 300)
    assert editions["run"]["ratio"]["ratios"] == pytest.approx([editions["run"]["fmi3_s"][0] /
                                                                editions["run"]["fmi2_s"][0]])
    assert "## FMI 2.0 and FMI 3.0 editions" in (tmp_path / "bench.md").read_text()
    assert any(line.startswith("  FMI 3.0 / FMI 2.0 editions: floor ") for line in bench.summary_lines(result))


def test_the_time_split_prices_each_call_and_leaves_the_rest_to_the_master():
    # synthetic prices [s a call]: our FMUs and their do-nothing twins
    ours = {"shaft": {"get": 6e-6, "set": 5e-6, "step": 20e-6, "state": 30e-6}, "coupling": {"get": 9e-6, "step": 4e-6}}
    hollow = {"shaft": {"get": 3e-6, "set": 3e-6, "step": 3e-6, "state": 10e-6}, "coupling": {"get": 3e-6, "step": 3e-6}}
    calls = {"shaft": {"get": 200, "set": 100, "step": 100, "state": 0}, "coupling": {"get": 100, "step": 100}}
    split = bench.time_split(0.01, calls, ours, hollow)
    crossing = 200 * 3e-6 + 100 * 3e-6 + 100 * 3e-6 + 100 * 3e-6 + 100 * 3e-6        # 1.8 ms
    slave = 200 * 3e-6 + 100 * 2e-6 + 100 * 17e-6 + 100 * 6e-6 + 100 * 1e-6          # 3.2 ms
    assert split == pytest.approx({"crossing": crossing, "slave": slave, "master": 0.01 - crossing - slave})
    assert split["master"] == pytest.approx(5.0e-3)
    # a kind of call with no price (states of a coupling that cannot roll back): no split
    assert bench.time_split(0.01, {"coupling": {"state": 3}}, ours, hollow) is None


def test_bench_plan_refuses_unknown_masters():
    spec = scene.load("kavz685")
    spec.bench = {"steps": {"no-such-master": [1e-3]}}
    with pytest.raises(ValueError, match="no-such-master"):
        bench.plan(spec)


def test_the_unsplit_solutions_record_on_the_model_exchange_masters_grid():
    """The price of the FMU boundary is a ratio of like with like: where the plan names the
    grid the Model Exchange master records on, the monolithic solutions record on it too
    (not on a fine scene step, whose points CVODE would pay for); elsewhere the scene's step."""
    spec = scene.load("kavz685_stiff")
    assert spec.experiment.step < 2e-3
    assert bench.plan(spec)["monolithic_step"] == bench.plan(spec)["output_steps"]["me-cvode"] == 2e-3
    spec.bench = {"steps": {"jacobi": [1e-4]}, "output_steps": {"adaptive": 1e-3}}
    assert bench.plan(spec)["monolithic_step"] == spec.experiment.step


def test_bench_records_failed_cases_goes_on_and_resumes(tmp_path, fmu_dir, monkeypatch):
    """A diverging case and a case that raises are recorded with their diagnosis, the
    others complete; a second run takes every case from the case log."""
    spec = scene.load("kavz685_stiff").with_overrides(["experiment.stop=0.2", "experiment.transient=0.05"])
    spec.bench = {"steps": {"jacobi": [1e-3], "trapezoidal-newton": [2e-3]}, "monolithic_rtol": [1e-6],
                  "target_error": 1e-2}

    def broken(*args, **kwargs):
        raise FloatingPointError("the monolithic solver blew up")

    monkeypatch.setattr(bench.timing, "run_monolithic", broken)
    _fewer_timed_steps(monkeypatch)
    first = bench.bench(spec, repeats=1, fmu_dir=fmu_dir, peers=False, out=tmp_path)
    by_engine = {c.engine: c for c in first["cases"]}
    # the divergence guard stops it at the physical speed bound, naming variable and time
    assert "diverged: engine.w" in by_engine["jacobi"].failure and "t = 0.028 s" in by_engine["jacobi"].failure
    assert by_engine["monolithic"].failure.startswith("FloatingPointError: the monolithic solver blew up (at ")
    assert by_engine["trapezoidal-newton"].stable and by_engine["trapezoidal-newton"].energy_residual < 1e-5
    bench.write(tmp_path, first)
    assert "FloatingPointError" in (tmp_path / "bench.md").read_text()

    calls = []
    monkeypatch.setattr(bench.timing, "simulate", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(bench.floors, "call_floor", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(bench.floors, "call_prices", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(bench.timing, "run_monolithic", lambda *a, **k: calls.append(a))
    lines = []
    again = bench.bench(spec, repeats=1, fmu_dir=fmu_dir, peers=False, out=tmp_path, progress=lines.append)
    assert calls == []
    # three cases, the two floors (our FMUs', the do-nothing twins') and the FMI editions'
    # comparison; no case reaches the target, so no headline is measured side by side
    assert lines[0].startswith("resuming: 6 case(s) already in")
    assert [bench.table_row(c) for c in again["cases"]] == [bench.table_row(c) for c in first["cases"]]
    assert again["floor_per_step_s"] == first["floor_per_step_s"]
    assert again["fmi_editions"] == first["fmi_editions"] and first["fmi_editions"]["run"]["fmi3"]["n"] == 1

    # A changed plan keeps the cases it shares; a fresh run recomputes them all.
    monkeypatch.undo()
    _fewer_timed_steps(monkeypatch)
    spec.bench["steps"]["trapezoidal-newton"] = [2e-3, 4e-3]
    spec.bench["monolithic_rtol"] = []
    grown = bench.bench(spec, repeats=1, fmu_dir=fmu_dir, peers=False, out=tmp_path, resume=False,
                        fmi_editions=False)
    assert grown["fmi_editions"] is None and "FMI 2.0 and FMI 3.0" not in bench.markdown(grown, [])
    assert [c.step for c in grown["cases"] if c.engine == "trapezoidal-newton"] == [2e-3, 4e-3]
    assert (tmp_path / "cases.old1.jsonl").exists()


def test_the_do_nothing_twin_has_the_fmus_variables_and_steps(tmp_path, fmu_dir):
    from fmpy import read_model_description, simulate_fmu

    from harness.studies.bench import do_nothing_twins

    from harness.description.fmu_description import read_description, time_derivatives

    shaft = do_nothing_twins.build_twin(fmu_dir / "LoadShaft.fmu", tmp_path / "LoadShaft.fmu")
    # the time-derivative relations too (tau_rate of tau among them): an extrapolating master
    # sends a twin what it sends ours
    ours, theirs = (time_derivatives(read_description(p)) for p in (fmu_dir / "LoadShaft.fmu", shaft))
    assert theirs == ours and ours.get("tau_rate") == "tau"
    twin = do_nothing_twins.build_twin(fmu_dir / "LeverCoupling.fmu", tmp_path / "LeverCoupling.fmu")
    ours, theirs = (read_model_description(str(p)) for p in (fmu_dir / "LeverCoupling.fmu", twin))
    same = ("name", "valueReference", "type", "causality", "variability")
    assert [[getattr(v, a) for a in same] for v in theirs.modelVariables] == \
           [[getattr(v, a) for a in same] for v in ours.modelVariables]
    # the units too: a scene's "15 deg" is judged against the twin's unit as against ours
    assert [v.unit for v in theirs.modelVariables] == \
           [v.unit or (v.declaredType.unit if v.declaredType else None) if v.type == "Real" else None
            for v in ours.modelVariables]
    assert {u.variable.name: [d.name for d in u.dependencies] for u in theirs.outputs} == \
           {u.variable.name: [d.name for d in u.dependencies] for u in ours.outputs}
    # it steps, with parameters and inputs set, and its outputs stay what they were: it does nothing
    result = simulate_fmu(str(twin), stop_time=0.01, output_interval=1e-3, fmi_type="CoSimulation",
                          start_values={"stiffness": 1000.0, "transfer_mode": "elastic", "phi1": 0.3},
                          output=["tau1", "phi1"])
    assert len(result) == 11 and (result["tau1"] == 0.0).all() and (result["phi1"] == 0.3).all()
    # its state keeps nothing (pythonfmu's own reads every variable), so that a state call's
    # price is the crossing's alone: serialised, our native entry's header (build/shim:
    # SERIAL_HEADER, 32 bytes) and the empty state; a round trip is accepted
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave

    unzipped = extract(str(twin))
    slave = FMU2Slave(guid=theirs.guid, unzipDirectory=unzipped, modelIdentifier=theirs.coSimulation.modelIdentifier)
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        state = slave.getFMUState()
        serialized = bytes(slave.serializeFMUState(state))
        assert serialized.startswith(b"LVRSHIM\0") and serialized[32:] == b"{}"
        slave.setFMUState(state)
        slave.freeFMUState(state)
        slave.terminate()
    finally:
        slave.freeInstance()


@pytest.mark.parametrize("measure", ["call_floor", "call_prices", "floors_side_by_side", "prices_side_by_side"])
def test_the_floor_loops_carry_the_values_so_the_models_run_the_scenes_motion(monkeypatch, measure):
    # The floor's calls must move the scene as a master would: without the propagation's
    # copies the shafts got their start torques for ever, the load shaft ran away and its
    # speed-dependent substeps priced a step that no master makes.  Side by side (the FMI
    # 2.0 and 3.0 editions taking turns every 700 steps) each system makes every step.
    from harness.engine.system import System
    seen = []
    free = System.free

    def noting(system):
        seen.append({"engine": system.value("engine", "w"), "load": system.value("load", "w"),
                     "time": system.components["engine"].time})
        free(system)

    monkeypatch.setattr(System, "free", noting)
    kavz = scene.load("kavz685")
    both = [kavz, kavz.with_overrides(["experiment.fmi=3"])]
    if measure == "call_floor":
        assert bench.call_floor(kavz, n_steps=3000) > 0
    elif measure == "call_prices":
        bench.call_prices(kavz, n_steps=3000)
    elif measure == "floors_side_by_side":
        assert min(bench.floors.floors_side_by_side(both, 3000, chunk=700)) > 0
    else:
        prices = bench.floors.prices_side_by_side(both, n_steps=3000, chunk=700)
        assert [set(p) for p in prices] == [{"engine", "load", "coupling"}] * 2
        assert [set(p["engine"]) for p in prices] == [{"get", "set", "step", "state"}] * 2
    assert len(seen) == (2 if measure.endswith("side_by_side") else 1)
    # after 3 s the driveline turns at its steady 36-38 rad/s (the scene's run: 36.66 mean)
    for s in seen:
        assert 35.0 < s["engine"] < 39.0 and 35.0 < s["load"] < 39.0 and s["time"] == pytest.approx(3.0), s


def test_the_floor_step_makes_the_calls_of_a_jacobi_step(fmu_dir):
    # The floor is what a master that does nothing else pays: the engine's own step of the
    # calls, the very calls a jacobi step makes (a step, a read and a set where a jacobi
    # step makes one), not a loop of the benchmark's own.
    from harness.description.plan import recorded_names
    from harness.engine.run import simulate
    from harness.engine.system import System
    kavz = scene.load("kavz685").with_overrides(["experiment.stop=0.05", "experiment.transient=0.01"])
    run = simulate(kavz, "jacobi", 1e-3, fmu_dir)
    per_step = {name: {kind: count / run.counters["steps"] for kind, count in kinds.items()}
                for name, kinds in run.counters["calls_by_kind"].items()}
    system = System(kavz, fmu_dir, record=recorded_names(kavz))
    try:
        system.initialize()
        before = system.calls_by_kind()
        for k in range(10):
            system.floor_step(k * 1e-3, 1e-3)
        after = system.calls_by_kind()
    finally:
        system.free()
    assert {name: {kind: (after[name][kind] - before[name][kind]) / 10 for kind in kinds}
            for name, kinds in after.items()} == per_step



def test_where_the_floors_motion_diverges_it_starts_again_and_never_calls_a_failed_fmu(monkeypatch):
    # Bare jacobi steps of 2 ms on the stiff scene run away within a few dozen steps and the
    # engine refuses the torque it is sent: FMI allows no further step after that error.  The
    # floor sees the refusal, puts every component back to its initial state and carries on.
    from harness.engine.component import Component
    from harness.engine.system import System
    refused, restored, states = [], [], []
    fail, restore, free = Component.fail, Component.restore_state, System.free

    def noting_failure(component, call, status):
        refused.append(call)
        fail(component, call, status)

    def noting_restore(component, state, time):
        restored.append(component.name)
        restore(component, state, time)

    def noting(system):
        states.extend(c.state for c in system.components.values())
        free(system)

    monkeypatch.setattr(Component, "fail", noting_failure)
    monkeypatch.setattr(Component, "restore_state", noting_restore)
    monkeypatch.setattr(System, "free", noting)
    stiff = scene.load("kavz685_stiff")
    assert bench.call_floor(stiff, n_steps=400, step=2e-3) > 0
    assert refused, "the bare steps were expected to diverge at this step"
    assert len(restored) == 3 * len(refused) and set(states) == {"stepping"}
    # the call prices go through the same step and start again alike
    refused.clear()
    assert all(price > 0 for price in bench.call_prices(stiff, n_steps=400, step=2e-3)["engine"].values())
    assert refused


def test_the_fmi_editions_are_measured_in_turn_round_by_round(fmu_dir, monkeypatch):
    """Each round measures the floor, the call prices and the run with both editions; each
    ratio is FMI 3.0 over FMI 2.0 within a round; both runs computed the same traces."""
    from harness.studies.bench import editions

    monkeypatch.setattr(editions, "FLOOR_STEPS", 200)
    monkeypatch.setattr(editions, "PRICE_STEPS", 100)
    monkeypatch.setattr(editions, "CHUNK", 30)
    kavz = scene.load("kavz685").with_overrides(["experiment.stop=0.05", "experiment.transient=0.01"])
    compared = editions.compare(kavz, "gauss-seidel", 1e-3, 2, fmu_dir)
    assert (compared["master"], compared["steps"], compared["largest_trace_difference"]) == ("gauss-seidel", 50, 0.0)
    figures = [compared["floor"], compared["run"], *(f for kinds in compared["prices"].values() for f in kinds.values())]
    for f in figures:
        assert len(f["fmi2_s"]) == len(f["fmi3_s"]) == 2 and min(f["fmi2_s"] + f["fmi3_s"]) >= 0.0
        assert f["ratio"]["ratios"] == pytest.approx([a / b for a, b in zip(f["fmi3_s"], f["fmi2_s"]) if b > 0])
    assert min(compared["floor"]["fmi2_s"] + compared["floor"]["fmi3_s"]) > 0.0
    # every component's calls, and the states of those that roll back, priced for both
    assert {name: set(kinds) for name, kinds in compared["prices"].items()} == {
        "engine": {"get", "set", "step", "state"}, "load": {"get", "set", "step", "state"},
        "coupling": {"get", "set", "step"}}
    text = "\n".join(editions.markdown(compared))
    assert "| coupling step, a call | " in text and "bit for bit the same" in text


def test_the_fmi_editions_are_not_compared_where_there_is_no_other_edition(tmp_path, fmu_dir):
    from harness.paths import SCENES
    from harness.studies.bench import editions

    assert editions.missing(scene.load("kavz685"), fmu_dir) is None
    text = (SCENES / "kavz685.toml").read_text().replace('fmu = "LeverCoupling"',
                                                               f'fmu = "{fmu_dir / "LeverCoupling.fmu"}"')
    (tmp_path / "user.toml").write_text(text)
    assert "coupling's FMU is a file" in editions.missing(scene.load(tmp_path / "user.toml"), fmu_dir)
    only_fmi2 = tmp_path / "fmus"
    only_fmi2.mkdir()
    for name in ("EngineShaft", "LeverCoupling", "LoadShaft"):
        (only_fmi2 / f"{name}.fmu").write_bytes((fmu_dir / f"{name}.fmu").read_bytes())
    assert "no FMI 3.0 edition of EngineShaft" in editions.missing(scene.load("kavz685"), only_fmi2)
    assert editions.summary_lines({"not_compared": "why"}) == [
        "  FMI 3.0 against FMI 2.0 editions not compared: why"]


def test_a_long_bench_is_estimated_from_each_masters_timed_runs(monkeypatch):
    """Each master timed at two lengths (a fake clock: 0.2 s set-up, 1 ms a step, 3 ms for
    jacobi-quadratic), summed over the plan's cases and repeats, a long run once."""
    from types import SimpleNamespace

    from harness.studies.bench import timing

    spec = scene.load("kavz685")                    # 10 s
    spec.bench = {"steps": {"jacobi": [1e-3, 2e-3], "jacobi-quadratic": [1e-3]}, "peers": {"fmpy": [1e-3]},
                  "repeats_limit_s": 15.0}
    p = bench.plan(spec)
    now = [0.0]

    def simulate(short, name, step, fmu_dir, options=None):
        steps = round((short.experiment.stop - short.experiment.start) / step)
        now[0] += 0.2 + steps * (3e-3 if name == "jacobi-quadratic" else 1e-3)

    monkeypatch.setattr(timing, "simulate", simulate)
    monkeypatch.setattr(timing, "clock", SimpleNamespace(perf_counter=lambda: now[0]))
    floor = 1e-4
    extra = timing.FLOOR_STEPS * floor
    prices = 4 * timing.PRICE_STEPS * floor
    # jacobi 10000 steps: 10.2 s x 3; 5000: 5.2 s x 3; quadratic 30.2 s > the limit: once; the
    # peer as the baseline (jacobi) at 1 ms: 10.2 s x 3; each master's case records its calls
    # in one run more and before each run runs once more side by side with their replay
    # (about two runs' time), the peer not
    expected = (3 * (3 * 10.2 + extra) + 10.2 + 3 * (3 * 5.2 + extra) + 5.2 + (3 * 30.2 + extra) + 30.2
                + 3 * (10.2 + extra) + 4 * prices)
    assert timing.estimated_seconds(spec, p, 3, None, floor) == pytest.approx(expected, rel=1e-9)
    # a short benchmark is not timed at all
    monkeypatch.setattr(timing, "simulate", lambda *a, **k: pytest.fail("timed a short benchmark"))
    assert timing.estimated_seconds(spec, p, 3, None, 1e-9) is None


def test_a_price_sets_aside_the_steps_another_process_interrupted():
    """Ten steps of a set at 1 us and a step at 2 us, and one step whose set took 4 ms (the
    processor given to another process): the set is priced at 1 us, not (10 + 4000) / 11 =
    364.5 us, as the timed runs set such steps aside (``master_time.uninterrupted``); the
    timer's own 0.1 us taken off each."""
    from harness.studies.bench import floors

    loop = floors._PriceLoop.__new__(floors._PriceLoop)
    loop.spent = {"load": {"set": 0.0, "step": 0.0}}
    quiet = [({"load": {"set": 1e-6, "step": 2e-6}}, {"load": {"set": 1, "step": 1}})] * 10
    loop.steps = quiet[:5] + [({"load": {"set": 4e-3, "step": 2e-6}}, {"load": {"set": 1, "step": 1}})] + quiet[5:]
    prices = loop.prices(0.1e-6)
    assert list(prices) == ["load"] and prices["load"] == pytest.approx({"set": 0.9e-6, "step": 1.9e-6})


def test_the_rounds_run_the_headline_ratios_cases_next_to_each_other_forth_and_back(monkeypatch):
    """The fastest master's runs either side of the target come first, the monolithic
    solution's next, the others after; the rounds go forth and back, so the two runs a
    headline ratio divides are neighbours in every round and neither always runs first."""
    from harness.studies.bench import headlines, timing

    spec = scene.load("kavz685")
    p = {"target_error": 1e-3, "baseline": "jacobi"}

    def case(engine, step, wall, error, kind="master"):
        return Case(engine, kind, step, None if kind == "master" else step, wall_times=[wall],
                    errors={"tau_rms": error})
    cases = [case("jacobi", 1e-3, 2.0, 2e-3), case("jacobi", 5e-4, 4.0, 5e-4),
             case("jacobi-linear", 2e-3, 1.0, 2e-3), case("jacobi-linear", 1e-3, 1.5, 8e-4),
             case("jacobi-quadratic", 6e-3, 0.2, 1.5e-3), case("jacobi-quadratic", 5e-3, 0.3, 7e-4),
             case("monolithic", 1e-3, 0.25, 1.1e-3, "monolithic"), case("monolithic", 1e-5, 0.6, 1e-5, "monolithic")]
    chosen = headlines.headline_cases(spec, cases, p)
    assert [(c.engine, c.step) for c in chosen][:4] == [("jacobi-quadratic", 5e-3), ("jacobi-quadratic", 6e-3),
                                                       ("monolithic", 1e-5), ("monolithic", 1e-3)]
    assert {c.engine for c in chosen[4:]} == {"jacobi", "jacobi-linear"}
    order = []
    monkeypatch.setattr(timing, "_rerun", lambda scene_, c, fmu_dir: order.append(c.key) or 1.0)
    rounds = timing.measure_rounds(spec, chosen, 3, None, None)
    keys = [c.key for c in chosen]
    assert order == keys + keys[::-1] + keys
    assert all(len(walls) == 3 for walls in rounds["walls"].values())
