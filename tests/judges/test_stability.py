"""Linear stability analysis of the masters, the stability map's classification and
sweep, and the stability advisor."""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from harness.studies import cases
from harness.engine import masters
from harness.engine import run
from harness.description import scene
from harness.judges import stability
from harness.studies import stability_report, stabilitymap

KAVZ = stability.TwoInertia(0.128, 0.161, 14.06, 715.4, 6.35)
UNDAMPED = stability.TwoInertia(0.128, 0.161, 0.0, 1e5, 0.0)     # zeta = 0 exactly


# -- the model ------------------------------------------------------------------------------------

def test_modal_quantities_of_the_two_inertia_model():
    assert KAVZ.omega_n == pytest.approx(100.16, abs=0.01)
    assert UNDAMPED.zeta == 0.0
    # Lightly damped: the modal damping ratio is that of the exact eigenvalues.
    stiff = KAVZ.with_coupling(1e5, 0.0)
    oscillatory = max(stiff.continuous_eigenvalues(), key=lambda v: v.imag)
    assert stiff.zeta == pytest.approx(-oscillatory.real / abs(oscillatory), rel=0.01)
    assert stiff.omega_n == pytest.approx(abs(oscillatory), rel=0.01)


def test_model_of_scene_reads_its_parameters():
    model = stability.model_of(scene.load("kavz685_stiff"))
    assert (model.drive_inertia, model.driven_inertia, model.engine_slope, model.stiffness, model.damping) == \
        (0.128, 0.161, 14.06, 1e5, 0.0)
    assert model.omega_n == pytest.approx(1184.2, abs=0.1)


# -- the one-step maps --------------------------------------------------------------------------------

def test_zero_order_hold_jacobi_map_is_the_textbook_one():
    """Held torque T = c*theta over the step, each shaft integrated exactly."""
    m, h = UNDAMPED, 2e-4
    c, i1, i2 = m.stiffness, m.drive_inertia, m.driven_inertia
    expected = np.array([[1 - c * h * h / 2 * (1 / i1 + 1 / i2), h, -h],
                         [-c * h / i1, 1.0, 0.0],
                         [c * h / i2, 0.0, 1.0]])
    matrix, names = stability.one_step_map(m, "jacobi", h)
    assert names == ["theta", "w1", "w2"]
    assert np.allclose(matrix, expected, rtol=1e-12, atol=1e-12)


def test_adaptive_masters_are_analysed_as_the_fixed_step_master_they_step_with():
    assert masters.MASTERS["adaptive"].degree == masters.MASTERS["jacobi-quadratic"].degree
    assert issubclass(masters.MASTERS["adaptive"], masters.ExtrapolatingJacobiMaster)
    assert issubclass(masters.MASTERS["adaptive-trapezoidal"], masters.MASTERS["trapezoidal-newton"])
    h = KAVZ.step_for(0.8)
    assert stability.spectral_radius(KAVZ, "adaptive", h) == stability.spectral_radius(KAVZ, "jacobi-quadratic", h)


def test_extrapolating_masters_carry_their_torque_history():
    matrix, names = stability.one_step_map(KAVZ, "jacobi-quadratic", 1e-3)
    assert matrix.shape == (7, 7) and len(names) == 7      # theta, w1, w2 + 2 past points x 2 torques


@pytest.mark.parametrize("name", ["trapezoidal-newton", "implicit-newton"])
def test_iterated_couplings_are_stable_at_any_step_without_damping(name):
    for x in np.geomspace(0.01, 100.0, 13):
        rho = stability.spectral_radius(UNDAMPED, name, UNDAMPED.step_for(x))
        assert rho <= 1.0 + 1e-7, (x, rho)


def _coupling_mode(name, model, h):
    """Moduli of the oscillatory eigenvalues (the complex pair) of the map."""
    values = np.linalg.eigvals(stability.one_step_map(model, name, h)[0])
    return np.abs(values[np.abs(values.imag) > 1e-9])


def test_trapezoidal_coupling_conserves_the_undamped_mode():
    # the spring's energy is passed on exactly: modulus 1, not below (implicit damps it)
    h = UNDAMPED.step_for(0.5)
    assert np.allclose(_coupling_mode("trapezoidal-newton", UNDAMPED, h), 1.0, atol=1e-7)
    assert np.all(_coupling_mode("implicit-newton", UNDAMPED, h) < 0.99)
    assert np.all(_coupling_mode("jacobi", UNDAMPED, h) > 1.01)


def test_zero_order_hold_is_unstable_at_any_step_without_damping_and_stable_with_enough():
    assert stability.stability_edge(UNDAMPED, "jacobi") == stability.EDGE_RANGE[0]
    assert stability.stability_edge(KAVZ, "jacobi") == pytest.approx(2.24, abs=0.01)


def test_fixed_point_masters_fail_where_their_iteration_cannot_converge():
    model = KAVZ.with_coupling(1e5, 0.0)
    limit = stability.fixed_point_limit(masters.MASTERS["implicit-fixed-point"])
    edge = stability.stability_edge(model, "implicit-fixed-point")
    assert stability.iteration_contraction(model, "implicit-fixed-point", model.step_for(0.99 * edge)) < limit
    assert math.isinf(stability.spectral_radius(model, "implicit-fixed-point", model.step_for(1.01 * edge)))


def _replay(model, master, step, n, state, options):
    system = stability.LinearDriveline(model, step)
    system.set_state(*state)
    driver = masters.make(master, system, step, **options)
    out = []
    for k in range(1, n + 1):
        driver.step(t_next=k * step)
        out.append(system.value("coupling", "tau2"))
    return np.array(out)


@pytest.mark.parametrize("name", ["jacobi", "gauss-seidel", "jacobi-quadratic", "jacobi-midpoint",
                                  "trapezoidal-newton", "implicit-fixed-point"])
def test_stand_in_steps_like_the_real_fmus(name):
    """The analysed map is the real master's.  On the FMUs (synchronous transfer,
    constant load: an affine system) two runs from different starts differ by what the
    stand-in makes of the difference of the starts, step for step, start-up steps
    included (the difference cancels the affine parts: the operating point, and
    Gauss-Seidel's torque bias c*w*h)."""
    c, b = 1e4, 0.5
    spec = scene.load("kavz685").with_overrides(
        ["coupling.transfer_mode=synchronous", "load.load_kind=constant", f"coupling.stiffness={c}",
         f"coupling.damping={b}", "experiment.transient=0"])
    model = stability.model_of(spec)
    _steps_like_the_fmus(spec, model, name)


@pytest.mark.parametrize("name", ["jacobi", "trapezoidal-newton"])
def test_stand_in_with_a_viscous_load_steps_like_the_real_fmus(name):
    """A load's viscous friction b_v is the one feedback of a load in the linear model:
    the stand-in carries it (the same smooth load of lever.physics.friction)
    and steps like the FMUs, and it damps the coupling mode by b_v (I1/(I1 + I2))^2."""
    c, b, viscous = 1e4, 0.5, 3.0
    spec = scene.load("kavz685").with_overrides(
        ["coupling.transfer_mode=synchronous", "load.load_kind=constant", f"coupling.stiffness={c}",
         f"coupling.damping={b}", "experiment.transient=0", f"load.viscous_damping={viscous}"])
    model = stability.model_of(spec)
    assert model.driven_slope == viscous
    share = 0.128 / (0.128 + 0.161)
    without = stability.TwoInertia(0.128, 0.161, 14.06, c, b)
    assert model.zeta - without.zeta == pytest.approx(viscous * share ** 2 / (2 * math.sqrt(c * 0.161 * share)),
                                                      rel=1e-12)
    # the continuous model's least damped pair has that damping ratio (to the modal approximation)
    pair = max(stability.TwoInertia.continuous_eigenvalues(model), key=lambda z: abs(z.imag))
    assert -pair.real / abs(pair) == pytest.approx(model.zeta, rel=0.02)
    _steps_like_the_fmus(spec, model, name)


def test_predicted_growth_rate_matches_the_real_run():
    """Above its edge, zero-order hold grows on the full KAVZ scene (kinematic transfer,
    random load) at the rate the spectral radius of the linear map predicts."""
    spec = scene.load("kavz685").with_overrides(["coupling.stiffness=1e5", "coupling.damping=0"])
    model = stability.model_of(spec)
    edge = stability.stability_edge(model, "jacobi")
    plan = stabilitymap.Plan([1e5], [0.0], [], ["jacobi"])
    below = stabilitymap.run_case(spec, stabilitymap.Case("jacobi", 1e5, 0.0, 0.9 * edge, 600), plan)
    assert below["class"] == "stable", below
    x = 1.3 * edge
    rho = stability.spectral_radius(model, "jacobi", model.step_for(x))
    steps = math.ceil(math.log(30.0) / (0.75 * math.log(rho)))
    above = stabilitymap.run_case(spec, stabilitymap.Case("jacobi", 1e5, 0.0, x, steps), plan)
    assert above["class"] != "stable" and above["growth"] > 5.0, above
    observed_rate = math.log(above["growth"]) / (0.75 * steps)
    assert observed_rate == pytest.approx(math.log(rho), rel=0.2)


def test_midpoint_edge_with_the_accelerations_of_the_current_torques():
    """jacobi-midpoint predicts mid-step states from the shafts' accelerations, which the
    master reads from its buffers (state of the map).  Read after the step's torques are
    written, they make the undamped edge the midpoint rule's h*omega_n = 2 (when they were
    read a step late it was 1.64), and runs agree on both sides of it."""
    spec = scene.load("kavz685").with_overrides(["coupling.stiffness=1e5", "coupling.damping=0"])
    model = stability.model_of(spec)
    _, names = stability.one_step_map(model, "jacobi-midpoint", 1e-4)
    assert names[3:] == ["engine.a", "load.a"]
    edge = stability.stability_edge(model, "jacobi-midpoint")
    assert 1.95 < edge < 2.1
    plan = stabilitymap.Plan([1e5], [0.0], [], ["jacobi-midpoint"])
    classes = [stabilitymap.run_case(spec, stabilitymap.Case("jacobi-midpoint", 1e5, 0.0, f * edge, 600), plan)["class"]
               for f in (0.9, 1.1)]
    assert classes == ["stable", "divergent"]


# -- classification -----------------------------------------------------------------------------------

def test_amplitude_growth_of_decaying_and_growing_oscillations():
    t = np.linspace(0.0, 1.0, 801)
    assert stabilitymap.amplitude_growth(np.exp(-3 * t) * np.sin(200 * t)) < 0.2
    assert stabilitymap.amplitude_growth(100 + np.exp(5 * t) * np.sin(200 * t)) > 20
    assert stabilitymap.amplitude_growth(np.r_[np.sin(200 * t), np.nan]) == math.inf
    assert math.isnan(stabilitymap.amplitude_growth(np.ones(3)))


def test_classification_criteria():
    assert stabilitymap.classify(0.5, 1e-4, None)[0] == "stable"
    assert stabilitymap.classify(0.5, 0.05, None)[0] == "energy-drifting"       # steady energy error
    assert stabilitymap.classify(2.0, 1e-4, None)[0] == "energy-drifting"       # growing, not yet far
    assert stabilitymap.classify(50.0, 1e-4, None)[0] == "divergent"
    assert stabilitymap.classify(math.inf, None, None)[0] == "divergent"
    status, why = stabilitymap.classify(0.5, None, "engine: fmi2SetReal returned error at t = 0.1 s")
    assert status == "divergent" and "engine" in why
    assert stabilitymap.unstable({"class": "energy-drifting", "growth": 2.0})
    assert not stabilitymap.unstable({"class": "energy-drifting", "growth": 1.0})    # energy only


# -- the advisor ----------------------------------------------------------------------------------------

def test_advisor_is_silent_on_stable_choices_and_adaptive_masters():
    assert stability.advise(scene.load("kavz685")) == []                      # jacobi-quadratic, 1 ms
    assert stability.advise(scene.load("kavz685_stiff")) == []                # me-cvode
    assert stability.advise(scene.load("kavz685_stiff"), "trapezoidal-newton", 5e-3) == []


@pytest.mark.parametrize("name, step", [("jacobi", 1e-4), ("jacobi-quadratic", 1e-3), ("gauss-seidel", 2e-4),
                                        ("implicit-fixed-point", 2e-3)])
def test_advisor_warns_and_proposes_stable_choices(name, step):
    spec = scene.load("kavz685_stiff")
    findings = stability.advise(spec, name, step)
    assert len(findings) == 1 and name in findings[0] and "outside the predicted stable region" in findings[0]
    assessment = stability.assess(spec, name, step)
    assert not assessment.stable and assessment.proposals
    for master, h in assessment.proposals:
        assert f"{master} at h = {h:.3g} s" in findings[0]
        assert stability.is_stable(stability.spectral_radius(assessment.model, master, h))
    # the same master at a shorter step is among the proposals
    assert any(master == name and h < step for master, h in assessment.proposals)


def test_the_run_advice_warns_and_simulate_leaves_it_to_its_caller():
    spec = scene.load("kavz685_stiff").with_overrides(["experiment.stop=0.005", "experiment.transient=0"])
    warnings = stability.run_advice(spec, "jacobi", 1e-4)
    assert len(warnings) == 1 and "jacobi" in warnings[0]
    result = run.simulate(spec, "jacobi", 1e-4)     # the run goes ahead; simulate analyses nothing
    assert result.ok and result.warnings == []


def test_lever_run_prints_the_advice(lever, tmp_path):
    outcome = lever("run", "kavz685_stiff", "--master", "jacobi", "--step", "1e-4", "--set",
                                        "experiment.stop=0.005", "--set", "experiment.transient=0",
                                        "--no-reference", "--no-plots", "--out", str(tmp_path))
    assert outcome.exit_code == 0, outcome.output
    assert re.search(r"warning: stability: jacobi at h = 0\.0001 s .* Predicted stable: ", outcome.output)


# -- the map ----------------------------------------------------------------------------------------------

ARGS = ["stability", "kavz685", "--stiffness", "1e5", "--damping", "0", "--master", "jacobi",
        "--master", "trapezoidal-newton", "--min-steps", "200", "--no-refine"]


def test_lever_stability_runs_and_resumes(lever, tmp_path):
    first = lever(*ARGS, "--h-omega", "0.05", "--h-omega", "0.5", "--jobs", "1", "--out", tmp_path)
    assert first.exit_code == 0, first.output
    assert "4 cases (0 already done)" in first.output
    png = (tmp_path / "stability_map.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert int.from_bytes(png[16:20], "big") == round(2 * 5.2 * 110)     # a panel a master, none blank beside
    assert len((tmp_path / "stability.csv").read_text().splitlines()) == 1 + 4      # header + the four cases
    log = [json.loads(line) for line in (tmp_path / "cases.jsonl").read_text().splitlines()[1:]]
    classes = {entry["key"].split("|")[0] + "@" + entry["key"].split("|")[3]: entry["result"]["class"] for entry in log}
    assert classes == {"jacobi@0.05": "stable", "jacobi@0.5": "divergent",
                       "trapezoidal-newton@0.05": "stable", "trapezoidal-newton@0.5": "stable"}
    # A denser re-run keeps the finished cases and runs only the new ones (in worker processes).
    second = lever(*ARGS, "--h-omega", "0.05", "--h-omega", "0.5", "--h-omega", "0.2", "--jobs", "2", "--out", tmp_path)
    assert second.exit_code == 0, second.output
    assert "6 cases (4 already done)" in second.output
    assert len((tmp_path / "cases.jsonl").read_text().splitlines()) == 1 + 6
    quiet = lever(*ARGS, "--h-omega", "0.05", "--h-omega", "0.5", "--h-omega", "0.2", "--no-progress",
                  "--out", tmp_path)
    assert quiet.exit_code == 0, quiet.output
    assert "already done" not in quiet.output and "written:" in quiet.output
    text = (tmp_path / "stability.md").read_text()
    assert "| jacobi | 1e+05 | 0 | 0.0258 | S | E | X |" in text or "| jacobi | 1e+05 | 0 | 0.0258 | S | X | X |" in text
    assert "trapezoidal-newton: predicted stable at every swept step; observed stable" in text


def test_a_case_that_raises_is_recorded_and_the_sweep_goes_on(tmp_path, monkeypatch):
    spec = scene.load("kavz685")
    plan = stabilitymap.Plan([1e5], [0.0], [0.05, 0.1], ["jacobi"], min_steps=100, refine=False)
    real = stabilitymap.run_case

    def flaky(scene_, case, plan_, fmu_dir=None):
        if case.h_omega == 0.1:
            raise RuntimeError("instantiation refused")
        return real(scene_, case, plan_)

    monkeypatch.setattr(stabilitymap, "run_case", flaky)
    result = stabilitymap.sweep(spec, plan, tmp_path)
    statuses = {case.h_omega: r.get("status") for case, r in result.results.items()}
    assert statuses == {0.05: "ok", 0.1: cases.FAILED}
    stability_report.write(tmp_path, result, plots=False)
    text = (tmp_path / "stability.md").read_text()
    assert "Cases that raised" in text and "instantiation refused" in text
    # a re-run keeps the failed case (it does not retry a recorded failure)
    again = stabilitymap.sweep(spec, plan, tmp_path)
    assert again.reused == 2


def _steps_like_the_fmus(spec, model, name):
    """The stand-in's replay of a small deviation (drive angle +0.002 rad, driven speed
    +0.5 rad/s) against the same deviation between two runs of the real FMUs, 60 steps at
    h*omega_n = 0.4: the driven torques agree to 1e-6 of the deviation's size."""
    step, n = model.step_for(0.4), 60
    options = {"tolerance": 1e-12} if "tolerance" in masters.MASTERS[name].options else {}
    spec = spec.with_overrides([f"experiment.stop={n * step!r}"])
    runs = [run.simulate(spec.with_overrides(extra), name, step, options=options)
            for extra in ([], ["engine.phi_start=0.002", "load.w_start=39.5"])]
    assert all(r.ok for r in runs), [r.failure for r in runs]
    real = runs[1].traces["coupling.tau2"][1:] - runs[0].traces["coupling.tau2"][1:]
    linear = _replay(model, name, step, n, (0.002, 0.0, 0.0, 0.5), options)
    assert np.max(np.abs(linear)) > 10.0                  # the difference is not nothing
    assert np.max(np.abs(real - linear)) < 1e-6 * np.max(np.abs(linear))
