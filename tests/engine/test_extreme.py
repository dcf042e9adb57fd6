"""Divergence handling and the extreme scenes: every extreme scene either runs to the end
with a bounded energy residual (and agrees with the monolithic reference), or stops within
one communication step with a diagnosis naming the component, FMU, variable, time, master
and step - never a hang, a crash or silently wrong numbers.  Runs are kept short."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from harness.engine import guard
from harness.judges import metrics
from harness.judges import monolithic
from harness.engine import run
from harness.description import plan as plans
from harness.description import scene
from lever.physics import component_parameters



def load(name: str, *overrides: str) -> scene.Scene:
    return scene.load(name).with_overrides(list(overrides))


def residual(result) -> float:
    return metrics.energy_balance(result.scene, result.times, result.traces)["residual_relative"]


def rms_errors(result, plan: plans.Plan | None = None) -> dict:
    """The run's errors against the monolithic reference of its scene (or of ``plan``, the
    scene checked: the reference then solves with the physics objects the plan built)."""
    ref = monolithic.solve(plan or result.scene, result.times)
    names = metrics.signals(result.scene)
    errs = metrics.errors(result.times, result.traces, ref.times, ref.traces,
                          [names[k] for k in ("w1", "w2", "tau1", "tau2")], metrics.error_scales(result.scene, ref.traces))
    return {k: errs[names[k]]["rms_relative"] for k in ("w1", "w2", "tau1", "tau2")}


def assert_diagnosed(result, master: str, step: float):
    """Stopped while stepping, with every part of the diagnosis, and within one
    communication step: every recorded row before the last is inside the bounds."""
    assert not result.ok and result.failure_stage == "stepping"
    d = result.diagnosis
    assert d["master"] == master and d["step"] == step
    assert d["component"] in result.scene.components and d["fmu"] == result.scene.components[d["component"]].fmu
    assert d["variable"]
    if d["kind"] == "fmu-error":     # refused inside the step after the last recorded point
        assert result.times[-1] < d["time"] <= result.times[-1] + step * (1 + 1e-9)
    else:
        assert d["time"] == pytest.approx(result.times[-1])
    for text in (d["component"], d["fmu"], d["variable"], master, f"{step:g} s", "t = "):
        assert text in result.failure, (text, result.failure)
    if d["kind"] == "bound":
        name = f"{d['component']}.{d['variable']}"
        assert not abs(result.traces[name][-1]) <= d["bound"]
        for b in guard.bounds(plans.check(result.scene)):
            assert np.all(np.abs(result.traces[b.variable][:-1]) <= b.limit), b.variable
    return d


# --------------------------------------------------------------------------------------
# The bounds and the guard
# --------------------------------------------------------------------------------------


def test_bounds_follow_the_stated_rule():
    spec = scene.load("kavz685")
    found = {b.variable: b.limit for b in guard.bounds(plans.check(spec))}
    speed = 10 * 623.0 / 14.06                   # the no-load speed of the engine line is the largest
    assert found["engine.w"] == pytest.approx(speed) and found["load.w"] == pytest.approx(speed)
    coupling = component_parameters.coupling_from({"misalignment": math.radians(15)})
    ratio = max(coupling.transfer.ratio(2 * math.pi * k / 1024) for k in range(1024))   # the physics takes scalars
    elastic = speed * math.sqrt(715.4 * (0.128 + 0.161))    # V(theta) = kinetic energy at the speed bound
    torque = ratio * (elastic + 6.35 * (1 + ratio) * speed)
    assert found["coupling.tau1"] == pytest.approx(torque) and found["coupling.tau2"] == pytest.approx(torque)
    # a load above the stall torque: the reversed steady speed counts, and the margin is the scene's
    stalled = {b.variable: b.limit for b in guard.bounds(plans.check(load("kavz685_stall", "limits.margin=4")))}
    assert stalled["engine.w"] == pytest.approx(4 * 623.0 / 14.06)
    # K1 = 0: no steady speed, the free acceleration over the run bounds it
    free = {b.variable: b.limit for b in guard.bounds(plans.check(load("kavz685", "engine.torque_slope=0")))}
    assert free["engine.w"] == pytest.approx(10 * (623.0 + 116.3) * 10.0 / (0.128 + 0.161))
    set_ = {b.variable: b.limit for b in guard.bounds(plans.check(load("kavz685", "limits.speed=100", "limits.torque=inf")))}
    assert set_["load.w"] == 100.0 and set_["coupling.tau2"] == math.inf


def test_bad_limits_are_findings():
    findings = scene.validate(load("kavz685", "limits.speed=-1", "limits.speeed=3"), {})
    assert any("limits.speed = -1" in f and "> 0" in f for f in findings)
    assert any("limits.speeed: unknown limit" in f for f in findings)


def test_the_guard_stops_within_one_step_and_keeps_the_traces(tmp_path):
    result = run.simulate(load("kavz685_stiff", "experiment.stop=0.3", "experiment.transient=0"), "jacobi", 5e-4)
    d = assert_diagnosed(result, "jacobi", 5e-4)
    assert d["kind"] == "bound" and d["step_index"] == len(result.times) - 1
    assert 0.01 < d["time"] < 0.3 and len(result.times) > 20


@pytest.mark.parametrize("record", [None, ["coupling.tau2"]])
def test_the_guard_watches_what_a_master_that_exposes_outputs_reads(record):
    # jacobi-midpoint exposes the derivatives of the outputs it extrapolates; when the scene
    # does not record them, that re-plans the system's buffers after the guard was made,
    # and the guard must follow (else the run ends with an FMU refusing a runaway speed).
    import dataclasses

    spec = load("kavz685", "coupling.stiffness=1e5", "coupling.damping=0", "experiment.stop=0.1")
    if record:
        spec = dataclasses.replace(spec, record=record)
    result = run.simulate(spec, "jacobi-midpoint", 4e-3)
    d = result.diagnosis
    assert not result.ok and result.failure_stage == "stepping" and d["kind"] == "bound"
    assert result.failure.startswith("diverged: engine.w = ") and "master jacobi-midpoint" in result.failure
    assert d["time"] == pytest.approx(0.012) == pytest.approx(result.times[-1])


def test_an_fmu_refusal_gives_the_same_diagnosis():
    # Without physical bounds the guard checks finiteness only: the torque grows until the
    # shaft refuses it (its input range), and that refusal is diagnosed like a divergence.
    result = run.simulate(load("kavz685_stiff", "experiment.stop=0.3", "experiment.transient=0",
                               "limits.speed=inf", "limits.torque=inf"), "jacobi", 5e-4)
    d = assert_diagnosed(result, "jacobi", 5e-4)
    # the coupling's torques are written in the scene's connection order: the engine's first
    assert d["kind"] == "fmu-error" and d["variable"] == "tau" and (d["component"], d["fmu"]) == ("engine",
                                                                                                  "EngineShaft")
    assert "'tau' = " in result.failure and "outside its allowed range [-1e+12, 1e+12] N.m" in result.failure


def test_lever_run_exits_nonzero_with_the_diagnosis_and_the_traces(lever, tmp_path):
    out = tmp_path / "diverged"
    done = lever("run", "kavz685_stiff_1e6", "--master", "jacobi", "--step", "1e-4",
                 "--set", "experiment.stop=0.1", "--set", "experiment.transient=0", "--no-plots", "--out", out)
    assert done.exit_code == 1, done.stderr
    assert "diverged:" in done.stderr and ("FMU EngineShaft" in done.stderr or "FMU LoadShaft" in done.stderr)
    assert "master jacobi, step 0.0001 s" in done.stderr and "Traceback" not in done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] is False and summary["diagnosis"]["kind"] == "bound"
    rows = (out / "traces.csv").read_text().splitlines()
    assert len(rows) - 2 == summary["diagnosis"]["step_index"]      # header + the start row


# --------------------------------------------------------------------------------------
# Stiff, undamped couplings
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["kavz685_stiff", "kavz685_stiff_1e6"])
def test_stiff_undamped_coupling_is_stable_with_the_trapezoidal_master(name):
    result = run.simulate(load(name, "experiment.stop=0.3", "experiment.transient=0"), "trapezoidal-newton", 1e-3)
    assert result.ok, result.failure
    assert residual(result) < 1e-6
    errs = rms_errors(result)
    assert errs["w1"] < 1e-2 and errs["w2"] < 1e-2        # the speeds follow; the stiff ringing is not resolved


def test_stiff_1e6_with_zero_order_hold_at_too_large_a_step_stops_with_the_diagnosis():
    result = run.simulate(load("kavz685_stiff_1e6", "experiment.stop=0.1", "experiment.transient=0"), "jacobi", 1e-4)
    d = assert_diagnosed(result, "jacobi", 1e-4)
    assert d["kind"] == "bound" and d["time"] < 0.05


# --------------------------------------------------------------------------------------
# Misalignment: the edge of the defined range, and varying in time
# --------------------------------------------------------------------------------------


def test_misalignment_at_the_edge_runs_and_matches_the_reference():
    result = run.simulate(load("kavz685_misalignment_edge", "experiment.stop=0.5", "experiment.transient=0"))
    assert result.ok, result.failure
    assert np.ptp(result.traces["coupling.U12"]) > 0.2           # +-0.14 at 43.2 deg
    assert residual(result) < 1e-4
    errs = rms_errors(result)
    assert max(errs.values()) < 5e-3, errs


def test_misalignment_beyond_the_edge_is_refused_by_name(lever, tmp_path):
    result = run.simulate(load("kavz685_misalignment_edge", "coupling.misalignment=43.3 deg"))
    assert result.failure_stage == "initialisation"
    assert "parameter 'misalignment'" in result.failure and "45 deg" in result.failure
    done = lever("run", "kavz685_misalignment_edge", "--set", "coupling.misalignment=44 deg",
                 "--out", tmp_path / "refused")
    assert done.exit_code == 2 and "misalignment" in done.stderr and "Traceback" not in done.stderr


def test_time_varying_misalignment_follows_its_source_and_the_reference():
    # The scene's ramp from 15 to 30 deg in 0.5 s instead of its 1 s, then held: the same
    # angles (the coupling builds a transfer function per 0.05 deg it passes, the most of
    # this test's time) in 1000 steps instead of 1500, at twice the rate the coupling holds
    # alpha over a step.  Held long enough before and after for a revolution's ripple.
    spec = load("kavz685_misalignment_ramp", "tilt.table=0:15; 0.3:15; 0.8:30", "experiment.stop=1.0",
                "experiment.transient=0")
    result = run.simulate(spec)
    assert result.ok, result.failure
    alpha = result.traces["tilt.misalignment"]
    t = result.times
    assert alpha[0] == pytest.approx(math.radians(15)) and alpha[-1] == pytest.approx(math.radians(30))
    assert alpha[np.searchsorted(t, 0.55)] == pytest.approx(math.radians(22.5))
    u12 = result.traces["coupling.U12"]
    early, late = u12[(t > 0.1) & (t < 0.3)], u12[t > 0.8]
    assert np.ptp(late) > 1.5 * np.ptp(early)                 # the ripple grows with alpha
    # The balance does not book the work the misalignment drive takes from the coupling,
    # int T_el * dPhi/dalpha * dalpha/dt: the residual is that work.  The coupling family of
    # the scene's plan (the scene's values, the defaults here), which the reference below
    # solves with: the exact transfer functions of its blend (one per 0.05 deg, 300 from 15
    # to 30 deg, milliseconds each) are built once for both.
    plan = plans.check(spec)
    family = plan.driveline.misalignment.get()[1]
    rate = np.gradient(alpha, t)
    power = [715.4 * theta * rate_ * (family.at(a + 1e-5).transfer.position(phi2)
                                      - family.at(a - 1e-5).transfer.position(phi2)) / 2e-5
             for theta, rate_, a, phi2 in zip(result.traces["coupling.theta"], rate, alpha, result.traces["load.phi"])]
    drive_work = float(np.sum(0.5 * (np.array(power[1:]) + power[:-1]) * np.diff(t)))
    balance = metrics.energy_balance(spec, t, result.traces)
    assert 0.1 < drive_work < 1.0
    assert balance["residual_J"] == pytest.approx(drive_work, rel=0.02)
    errs = rms_errors(result, plan)
    assert max(errs.values()) < 1e-4, errs


def test_time_varying_misalignment_past_the_edge_stops_with_the_couplings_refusal():
    spec = load("kavz685_misalignment_ramp", "tilt.table=0:40; 0.2:40; 0.4:46", "experiment.stop=0.5",
                "experiment.transient=0")
    result = run.simulate(spec)
    d = assert_diagnosed(result, "jacobi-quadratic", 1e-3)
    assert d["kind"] == "fmu-error" and d["component"] == "coupling" and d["variable"] == "misalignment"
    crossing = 0.2 + 0.2 * (45 - math.degrees(math.asin(0.03)) - 40) / 6     # alpha + tilt reaches 45 deg
    assert d["time"] == pytest.approx(crossing, abs=2e-3)


def test_the_blended_transfer_function_is_exact_at_nodes_and_close_between():
    family = component_parameters.coupling_family_from({"misalignment": math.radians(15)})
    phi = 2 * np.pi * np.arange(512) / 512
    for degrees in (15.0, 20.0, 20.025, 29.99):
        exact = component_parameters.coupling_from({"misalignment": math.radians(degrees)}).transfer
        blended = family.at(math.radians(degrees)).transfer
        exact_ratio, exact_position = np.vectorize(exact.ratio)(phi), np.vectorize(exact.position)(phi)
        blended_ratio, blended_position = np.vectorize(blended.ratio)(phi), np.vectorize(blended.position)(phi)
        assert np.max(np.abs(exact_ratio - blended_ratio)) < 1e-7
        assert np.max(np.abs(exact_position - blended_position)) < 1e-7
        assert np.mean(blended_ratio) == pytest.approx(1.0, abs=1e-12)
    assert family.at(math.radians(15.0)) is family.start


# --------------------------------------------------------------------------------------
# Stall, step load on a tiny inertia, plateaus
# --------------------------------------------------------------------------------------


def test_load_above_stall_torque_reverses_the_drive_without_nan():
    result = run.simulate(load("kavz685_stall"))
    assert result.ok, result.failure
    w1, w2 = result.traces["engine.w"], result.traces["load.w"]
    assert np.all(np.isfinite(w1)) and np.all(np.isfinite(w2))
    assert w1[0] == 39.0 and w1[-1] == pytest.approx((623.0 - 700.0) / 14.06, abs=0.5)
    assert np.any(w1 > 0) and np.any(w1 < 0)
    assert residual(result) < 1e-5
    assert max(rms_errors(result).values()) < 1e-4


def test_step_load_on_a_tiny_inertia():
    result = run.simulate(load("kavz685_step_tiny_inertia"), "adaptive-trapezoidal")
    assert result.ok, result.failure
    # The trapezoidal rule rings step to step by +-0.3-0.4 N*m at the long steps it ends
    # with (A- but not L-stable): its last sample alone sits anywhere in that band (the last
    # bits of U12 decide where), the mean of the last ten is the load.
    assert np.mean(result.traces["coupling.tau2"][-10:]) == pytest.approx(300.0, rel=1e-4)
    assert residual(result) < 1e-3
    errs = rms_errors(result)
    assert max(errs.values()) < 2e-3, errs
    explicit = run.simulate(load("kavz685_step_tiny_inertia", "experiment.stop=0.1", "experiment.transient=0"),
                            "jacobi-quadratic", 1e-3)
    assert assert_diagnosed(explicit, "jacobi-quadratic", 1e-3)["step_index"] <= 2


def test_plateau_law_is_the_papers_and_the_run_crosses_both_plateaus():
    spec = scene.load("kavz685_plateaus")
    law = component_parameters.coupling_from({k: scene.quantity(v) for k, v in spec.components["coupling"].parameters.items()}).law
    theta = np.linspace(-0.5, 0.5, 2001)
    torque = np.vectorize(law.torque)(theta)     # the physics takes scalars
    assert np.all(np.diff(torque) >= 0) and np.allclose(np.vectorize(law.torque)(-theta), -torque)
    for at, value in ((0.05, 10), (0.1, 16), (0.3, 26.5), (0.44, 37), (0.45, 50)):
        assert law.torque(at) == pytest.approx(value)
    assert law.stiffness_at(0.15) < 10 and law.stiffness_at(0.35) < 10 and law.stiffness_at(0.02) > 150
    result = run.simulate(spec)
    assert result.ok, result.failure
    deflection = result.traces["coupling.theta"]
    peak = int(np.argmax(deflection))
    for part in (deflection[:peak], deflection[peak:]):     # up and down through both plateaus
        assert part.min() < 0.05 and part.max() > 0.41
    # the plateaus are crossed by a jump: little time is spent inside them
    inside = ((deflection > 0.12) & (deflection < 0.18)) | ((deflection > 0.32) & (deflection < 0.38))
    assert inside.mean() < 0.1
    assert residual(result) < 1e-5
    assert max(rms_errors(result).values()) < 1e-3
