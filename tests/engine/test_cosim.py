"""Co-simulation of scenes with the built FMUs: steady state, convergence to the monolithic
reference, determinism, the KAVZ-685 acceptance numbers, and the ``lever run`` command."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from harness.judges import metrics
from harness.judges import monolithic
from harness.judges import solution
from harness.engine import run
from harness.description import scene


# Short, smooth runs: constant load, no start-up transient excluded from statistics.
SHORT = ["experiment.stop=1", "experiment.transient=0"]
SMOOTH = SHORT + ["load.load_kind=constant"]


def kavz(*overrides: str) -> scene.Scene:
    return scene.load("kavz685").with_overrides(list(overrides))


# --------------------------------------------------------------------------------------
# Physics of the whole driveline
# --------------------------------------------------------------------------------------


def test_synchronous_steady_state_is_the_analytic_one():
    spec = kavz("coupling.transfer_mode=synchronous", "load.load_kind=constant", "experiment.stop=3",
                "load.random_amplitude=0")
    result = run.simulate(spec)
    assert result.ok, result.failure
    M1, K1, Mm = 623.0, 14.06, 107.5
    w = (M1 - Mm) / K1
    traces = result.traces
    assert result.times[-1] == pytest.approx(3.0, abs=1e-12)
    assert traces["engine.w"][-1] == pytest.approx(w, rel=1e-6)
    assert traces["load.w"][-1] == pytest.approx(w, rel=1e-6)
    assert traces["coupling.tau2"][-1] == pytest.approx(Mm, rel=1e-6)
    assert traces["coupling.tau1"][-1] == pytest.approx(-Mm, rel=1e-6)
    assert traces["engine.engine_torque"][-1] == pytest.approx(Mm, rel=1e-6)
    assert abs(traces["engine.a"][-1]) < 1e-4 and abs(traces["load.a"][-1]) < 1e-4
    # Static deflection of the linear spring carries the load.
    assert traces["coupling.theta"][-1] == pytest.approx(Mm / 715.4, rel=1e-6)
    assert np.all(traces["coupling.U12"] == 1.0)
    # The reference reaches the same state.
    ref = monolithic.solve(spec, result.times, use_cache=False)
    assert ref.traces["engine.w"][-1] == pytest.approx(w, rel=1e-6)
    assert ref.traces["coupling.tau2"][-1] == pytest.approx(Mm, rel=1e-6)


@pytest.mark.parametrize("overrides", [SHORT + ["experiment.stop=2"], SMOOTH,
                                       SHORT + ["coupling.transfer_mode=scaled", "coupling.misalignment=25 deg"],
                                       SHORT + ["coupling.elastic_table=0.05:10; 0.1:16; 0.2:16.5; 0.3:26.5; 0.45:50",
                                                "load.mean_torque=20", "load.random_amplitude=5"]])
def test_reference_energy_balance_is_exact(overrides):
    spec = kavz(*overrides)
    times = np.linspace(spec.experiment.start, spec.experiment.stop, 1001)
    ref = monolithic.solve(spec, times, use_cache=False)
    assert np.array_equal(ref.times, times)
    balance = metrics.energy_balance(spec, ref.times, ref.traces, ref.traces["coupling.dissipated_energy"])
    assert balance["residual_relative"] < 1e-8, balance
    assert balance["work_in_J"] > 100.0 and balance["dissipated_J"] > 0.0


CONVERGENCE_STEPS = (2e-3, 1e-3, 5e-4)


@pytest.mark.parametrize("master", ["jacobi", "gauss-seidel"])
def test_masters_converge_to_the_reference_at_first_order(master):
    spec = kavz(*SMOOTH)
    names = ["engine.w", "coupling.tau2"]
    errors = {name: [] for name in names}
    for h in CONVERGENCE_STEPS:
        result = run.simulate(spec, master=master, step=h)
        assert result.ok, result.failure
        assert result.master == master and result.step == h
        ref = monolithic.solve(spec, result.times, use_cache=False)
        found = metrics.errors(result.times, result.traces, ref.times, ref.traces, names,
                               metrics.error_scales(spec, ref.traces))
        for name in names:
            errors[name].append(found[name]["rms"])
    for name, e in errors.items():
        assert e[0] > e[1] > e[2] > 0.0, (name, e)
        orders = [math.log2(e[k] / e[k + 1]) for k in range(len(e) - 1)]
        assert all(0.8 <= p <= 1.3 for p in orders), (name, orders)


def test_reference_cache_returns_what_was_solved(tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path))
    spec = kavz(*SHORT)
    times = np.linspace(0.0, 1.0, 201)
    fresh = monolithic.solve(spec, times, use_cache=False)
    first = monolithic.solve(spec, times)
    second = monolithic.solve(spec, times)
    assert second.info.get("cached") and not first.info.get("cached")
    for name, values in fresh.traces.items():
        assert np.array_equal(first.traces[name], values) and np.array_equal(second.traces[name], values), name
    # another scene, another entry
    other = monolithic.solve(spec.with_overrides(["load.mean_torque=150"]), times)
    assert not other.info.get("cached")


def test_reference_cache_distinguishes_time_grids_of_the_same_length(tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path))
    spec = kavz(*SHORT)
    grid_a = np.array([0.0, 0.3, 0.6, 0.9, 1.0])   # what --step 0.3 records
    grid_b = np.linspace(0.0, 1.0, 5)              # what --step 0.25 records
    monolithic.solve(spec, grid_a)
    again = monolithic.solve(spec, grid_b)
    assert np.array_equal(again.times, grid_b)


def test_reference_cache_keys_hold_the_wiring_and_the_simd_level(monkeypatch):
    """A cached reference is another scene's unless everything it depends on is in its key:
    the scene's connections (the same components wired otherwise) and numpy's SIMD dispatch
    in use (the tests' dispatch pass must solve at its own level, not read the full level's
    last bits); the code that plans and solves it: tests/judges/test_cache.py."""
    import dataclasses

    spec = scene.load("kavz685_misalignment_ramp")
    times = np.linspace(0.0, 1.0, 5)
    key = solution.cache_key(spec, times, 1e-10, 1e-10, "DOP853")
    assert key == solution.cache_key(spec, times, 1e-10, 1e-10, "DOP853")
    unwired = dataclasses.replace(spec, connections=[c for c in spec.connections if c.target != "coupling"
                                                     or c.input != "misalignment"])
    assert len(unwired.connections) == len(spec.connections) - 1
    assert solution.cache_key(unwired, times, 1e-10, 1e-10, "DOP853") != key
    monkeypatch.setattr(solution, "simd_in_use", lambda: "SSE42")
    assert solution.cache_key(spec, times, 1e-10, 1e-10, "DOP853") != key


def test_same_seed_same_traces_other_seed_other_traces():
    spec = kavz(*SHORT)
    a = run.simulate(spec)
    b = run.simulate(spec)
    c = run.simulate(spec.with_overrides(["load.seed=2"]))
    assert a.ok and b.ok and c.ok
    assert np.array_equal(a.times, b.times)
    assert set(a.traces) == set(b.traces)
    for name in a.traces:
        assert np.array_equal(a.traces[name], b.traces[name]), name
    assert np.array_equal(a.times, c.times)
    assert not np.array_equal(a.traces["load.load_torque"], c.traces["load.load_torque"])
    assert not np.array_equal(a.traces["engine.w"], c.traces["engine.w"])


def test_masters_step_the_same_system_differently():
    # Jacobi and Gauss-Seidel are different schemes: same start, different traces.
    spec = kavz(*SMOOTH)
    j = run.simulate(spec, master="jacobi", step=1e-3)
    g = run.simulate(spec, master="gauss-seidel", step=1e-3)
    assert np.array_equal(j.times, g.times)
    assert j.traces["engine.w"][0] == g.traces["engine.w"][0] == 39.0
    assert not np.array_equal(j.traces["engine.w"], g.traces["engine.w"])


def test_unknown_master_is_refused_by_simulate():
    with pytest.raises(ValueError, match="master"):
        run.simulate(kavz(*SHORT), master="newton")


# The KAVZ-685 scene as shipped (jacobi-quadratic, 1 ms, 10 s, the spectrum load: shaft order
# and 415-425 rad/s) against the monolithic reference, measured with that load (this test's
# own computation, run once on the shared 2-core machine, the pinned numpy/scipy): RMS
# errors relative to the scale (the mean transmitted torque, the mean speed) of tau1 6.98e-6,
# tau2 6.98e-6, w1 1.62e-6, w2 1.35e-6; co-simulation energy residual 1.98e-8 of the engine's
# work; the reference's own 1.01e-12.  Each bound is 3x the measured figure: a change that
# costs an order of accuracy (jacobi-quadratic at order 2: about 10x at this step) or an energy
# term fails.
KAVZ_MEASURED = {"coupling.tau1": 6.98e-6, "coupling.tau2": 6.98e-6, "engine.w": 1.62e-6, "load.w": 1.35e-6}
KAVZ_ENERGY_RESIDUAL = 1.98e-8
KAVZ_REFERENCE_RESIDUAL = 1.01e-12


@pytest.mark.oracle
def test_kavz685_default_scene_meets_its_accuracy_targets():
    spec = scene.load("kavz685")
    result = run.simulate(spec)
    assert result.ok, result.failure
    assert result.master == spec.experiment.master == "jacobi-quadratic"
    assert result.times[-1] == pytest.approx(spec.experiment.stop)
    ref = monolithic.solve(spec, result.times, use_cache=False)
    found = metrics.errors(result.times, result.traces, ref.times, ref.traces, list(KAVZ_MEASURED),
                           metrics.error_scales(spec, ref.traces))
    scale = found["coupling.tau2"]["scale"]
    assert scale == pytest.approx(107.5, rel=0.05)   # the mean transmitted torque
    for name, measured in KAVZ_MEASURED.items():
        assert found[name]["rms_relative"] <= 3.0 * measured, (
            f"KAVZ-685 acceptance: RMS error of {name} {found[name]['rms_relative']:.3g} > 3x the measured "
            f"{measured:.3g}: the master lost accuracy (e.g. jacobi-quadratic extrapolation weights are not quadratic)")
    # The energy balance, rebuilt here from the traces: work in - out - kinetic - elastic -
    # dissipated, the dissipation integrated from b*thetadot^2 with thetadot = w1 - U12*w2.
    tr, t = result.traces, result.times
    b, i1, i2 = 6.35, 0.128, 0.161
    theta_dot = tr["engine.w"] - tr["coupling.U12"] * tr["load.w"]
    dissipated = float(np.sum(np.diff(t) * 0.5 * (b * theta_dot[1:] ** 2 + b * theta_dot[:-1] ** 2)))
    work_in = tr["engine.engine_work"][-1] - tr["engine.engine_work"][0]
    kinetic = 0.5 * i1 * (tr["engine.w"][-1] ** 2 - tr["engine.w"][0] ** 2) + \
        0.5 * i2 * (tr["load.w"][-1] ** 2 - tr["load.w"][0] ** 2)
    elastic = 0.5 * 715.4 * (tr["coupling.theta"][-1] ** 2 - tr["coupling.theta"][0] ** 2)
    by_hand = work_in - (tr["load.load_work"][-1] - tr["load.load_work"][0]) - kinetic - elastic - dissipated
    balance = metrics.energy_balance(spec, result.times, result.traces)
    assert balance["dissipated_J"] == pytest.approx(dissipated, rel=1e-3), (
        f"the co-simulation energy balance counts {balance['dissipated_J']} J dissipated, b*thetadot^2 integrated "
        f"gives {dissipated} J: the energy balance ignores (or miscounts) the dissipation")
    assert abs(by_hand) / work_in <= 3.0 * KAVZ_ENERGY_RESIDUAL, by_hand
    assert balance["residual_relative"] <= 3.0 * KAVZ_ENERGY_RESIDUAL, (
        f"KAVZ-685 acceptance: energy residual {balance['residual_relative']:.3g} > 3x the measured "
        f"{KAVZ_ENERGY_RESIDUAL:.3g}: the co-simulation energy balance misses a term (the dissipation?)")
    reference_balance = metrics.energy_balance(spec, ref.times, ref.traces, ref.traces["coupling.dissipated_energy"])
    assert reference_balance["residual_relative"] <= 3.0 * KAVZ_REFERENCE_RESIDUAL, reference_balance


# --------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------


def test_cli_bad_parameter_exits_2_with_a_message(lever, tmp_path):
    out = tmp_path / "out"
    proc = lever("run", "--set", "engine.inertia=-1", "--no-reference", "--out", str(out))
    assert proc.exit_code == 2, proc.stderr
    text = proc.stdout + proc.stderr
    assert "inertia" in text
    assert "Traceback" not in text
    assert not out.exists()


@pytest.mark.parametrize("args", [["--master", "newton"], ["--step", "-0.001"], ["--set", "nonsense"],
                                  ["--set", "gearbox.ratio=3"], ["--set", "coupling.no_such_parameter=1"],
                                  ["no_such_scene"]])
def test_cli_user_errors_exit_2_without_traceback(lever, tmp_path, args):
    proc = lever("run", *args, "--no-reference", "--out", str(tmp_path / "out"))
    assert proc.exit_code == 2, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stdout + proc.stderr
    assert proc.stderr.strip()
    if args[0] == "--master":
        assert "newton" in proc.stderr and "jacobi" in proc.stderr


@pytest.mark.parametrize("assignment", ["experiment.master=newton", "experiment.stop=abc"])
def test_cli_bad_experiment_override_exits_2(lever, tmp_path, assignment):
    proc = lever("run", "--set", assignment, "--no-reference", "--out", str(tmp_path / "out"))
    assert "Traceback" not in proc.stdout + proc.stderr
    assert proc.exit_code == 2


def test_cli_failing_run_exits_1_and_keeps_the_rows_before_the_failure(lever, tmp_path):
    out = tmp_path / "out"
    proc = lever("run", "--set", "coupling.stiffness=1e9", "--set", "experiment.stop=1",
                 "--set", "experiment.transient=0", "--step", "0.01", "--out", str(out))
    assert proc.exit_code == 1, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stdout + proc.stderr
    assert "error:" in proc.stderr
    assert " t = " in proc.stderr   # says when it failed
    assert "traces.csv" in proc.stderr
    rows = (out / "traces.csv").read_text().splitlines()
    header, data = rows[0].split(","), [r.split(",") for r in rows[1:]]
    assert header[0] == "time" and "engine.w" in header
    assert 1 <= len(data) < 101           # some rows, not the whole run
    times = [float(r[0]) for r in data]
    assert times == pytest.approx([0.01 * k for k in range(len(data))])
    assert all(math.isfinite(float(x)) for r in data for x in r)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] is False and summary["failure"]
    failed_at = float(summary["failure"].split(" t = ")[1].split()[0])
    assert times[-1] < failed_at <= times[-1] + 0.01 + 1e-12
    assert "failed" in (out / "report.md").read_text()


def test_cli_short_run_writes_the_results(lever, tmp_path, monkeypatch):
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    result = lever("run", "--set", "experiment.stop=0.5", "--set", "experiment.transient=0.1", "--out", out,
                   "--no-progress")
    assert result.exit_code == 0, result.output
    for name in ("report.md", "summary.json", "traces.csv", "reference.csv", "speeds.png", "torques.png",
                 "accelerations.png", "u12_over_angle.png", "spectrum.png", "vs_reference.png", "revolution.png",
                 "revolutions.png"):
        path = out / name
        assert path.exists() and path.stat().st_size > 0, name
    for png in out.glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] is True and summary["scene"] == "kavz685"
    assert summary["error_vs_reference"]["coupling.tau2"]["rms_relative"] < 1e-2
    assert abs(summary["energy_balance"]["residual_relative"]) < 1e-3
    rows = (out / "traces.csv").read_text().splitlines()
    assert len(rows) == 1 + 501    # header + 0 ... 0.5 s at the scene's 1e-3 s
    assert "report.md" in result.output
    report = (out / "report.md").read_text()
    assert "kavz685" in report and "Energy balance" in report


def test_cli_no_plots_writes_everything_but_the_plots(lever, tmp_path, monkeypatch):
    """``--no-plots``: the traces, the reference, the summary and the report as always, no
    plot, and the report names only the files written."""
    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    result = lever("run", "--set", "experiment.stop=0.5", "--set", "experiment.transient=0.1", "--no-plots",
                   "--out", out, "--no-progress")
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} - {".lever.lock"} == {"report.md", "summary.json", "traces.csv",
                                                                  "reference.csv"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] is True and summary["files"] == ["reference.csv", "traces.csv", "summary.json", "report.md"]
    assert summary["error_vs_reference"]["coupling.tau2"]["rms_relative"] < 1e-2
    report = (out / "report.md").read_text()
    assert "Traces: reference.csv and traces.csv." in report and ".png" not in report


def test_cli_no_reference_run(lever, tmp_path):
    out = tmp_path / "out"
    # 0.1 s: less than one revolution of the driven shaft, so the plots over its angle are not drawn
    proc = lever("run", "--set", "experiment.stop=0.1", "--set", "experiment.transient=0", "--master", "jacobi",
                 "--step", "1e-3", "--no-reference", "--out", str(out))
    assert proc.exit_code == 0, proc.stderr
    assert {"report.md", "summary.json", "traces.csv", "speeds.png"} <= {p.name for p in out.iterdir()}
    assert not (out / "reference.csv").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["master"] == "jacobi" and summary["step_s"] == 1e-3
    assert "error_vs_reference" not in summary


def test_reference_handles_a_tabulated_engine_characteristic():
    # A scalar-only torque model: the reference must evaluate its traces point by point.
    spec = kavz("engine.characteristic=0:700; 30:300; 40:0", *SMOOTH)
    result = run.simulate(spec)
    assert result.ok, result.failure
    ref = monolithic.solve(spec, result.times, use_cache=False)
    e = metrics.errors(result.times, result.traces, ref.times, ref.traces, ["coupling.tau2"],
                       metrics.error_scales(spec, ref.traces))
    assert e["coupling.tau2"]["rms_relative"] < 5e-3
    assert np.all(np.isfinite(ref.traces["engine.a"]))
