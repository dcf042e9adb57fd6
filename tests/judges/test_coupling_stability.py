"""Stability analysis of a scene with our LeverCoupling and a user's own FMU
(harness.judges.coupling_scene, port_probe): the port measured by probe runs against the
FMU's known equations, the advisor and the guard on the user's stiff scene, the map's
agreement, the bench's ladder, and what a scene without the coupling or an FMU that
refuses its probes is told."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from harness import api
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine import guard
from harness.judges import port_probe, stability
from harness.studies import stabilitymap
from harness.studies.bench import schedule

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "user_fmu"
STIFF = ["coupling.stiffness=1e5", "coupling.damping=0"]
#: the user FMU's parameters as examples/user_fmu/user_driveline.toml sets them, and ours
I1, I2, K2, C, B, K1 = 0.128, 0.161, 1.25, 715.4, 6.35, 14.06


def test_the_fit_recovers_a_first_order_port_in_closed_form():
    h, amplitude = 1e-4, 10.0
    for inertia, damping in ((0.3, 2.0), (0.05, 0.0), (1.0, 40.0)):
        t = h * np.arange(201)
        dw = amplitude * t / inertia if damping == 0 else amplitude / damping * (1 - np.exp(-damping * t / inertia))
        j, k, residual = port_probe.fit_first_order(dw, amplitude, h)
        assert j == pytest.approx(inertia, rel=1e-6) and k == pytest.approx(damping, abs=1e-6 * max(1, damping))
        assert residual < 1e-9


def test_a_response_no_shaft_gives_is_refused():
    with pytest.raises(port_probe.ProbeRefused, match="does not answer a torque step as a shaft does"):
        port_probe.fit_first_order(np.zeros(50), 1.0, 1e-3)


@pytest.fixture(scope="module")
def user_scene(tmp_path_factory, user_example) -> Path:
    scene = user_example(tmp_path_factory.mktemp("user_fmu"), 0.2, 0.05)
    text = (EXAMPLE / "user_driveline.toml").read_text()
    (scene.parent / "no_bench.toml").write_text(text[:text.index("[bench]")].replace('"user_driveline"', '"no_bench"'))
    return scene


def test_the_measured_eigenfrequency_is_the_one_of_the_fmus_equations(user_scene, fmu_dir):
    model = stability.model_of(scenes.load(user_scene))
    (side, port), = model.measured
    assert side == "driven" and port.component == "load"
    assert port.inertia == pytest.approx(I2, rel=1e-3) and port.damping == pytest.approx(K2, rel=1e-2)
    # by hand: omega_n = sqrt(c (I1 + I2) / (I1 I2)); the modal damping of the mode shape
    omega = math.sqrt(C * (I1 + I2) / (I1 * I2))
    zeta = (B + K1 * (I2 / (I1 + I2)) ** 2 + K2 * (I1 / (I1 + I2)) ** 2) / (2 * math.sqrt(C * I1 * I2 / (I1 + I2)))
    assert model.omega_n == pytest.approx(omega, rel=0.05)
    assert model.omega_n == pytest.approx(omega, rel=1e-4)      # the FMU is linear and exact: far inside 5 %
    assert model.zeta == pytest.approx(zeta, rel=1e-3)
    assert model.omega_spread < 1e-6 and "load (DrivenShaft.fmu): inertia 0.161" in model.uncertainty()


def test_the_advisor_warns_and_the_stiff_run_ends_diverged_with_its_traces(user_scene, fmu_dir):
    heard = []
    done = api.run(user_scene, STIFF, master="jacobi", step=1e-3, notify=lambda kind, message: heard.append(message))
    warned = [m for m in heard if m.startswith("stability: jacobi at h = 0.001 s")]
    assert len(warned) == 1 and "omega_n = 1184 rad/s" in warned[0] and "predicted stable up to h*omega_n" in warned[0]
    assert done.outcome == "failed" and done.failure.startswith("diverged: engine.w = ")
    assert "exceeds its physical bound 443.1 rad/s" in done.failure
    assert len(done.times) > 10 and np.all(np.isfinite(done.traces["coupling.tau2"]))
    # the scene's own coupling, predicted stable, gets no warning
    assert stability.advise(scenes.load(user_scene), "jacobi", 1e-3) == []


def test_the_guard_bounds_both_coupling_speeds_from_our_engine_line(user_scene, fmu_dir):
    bounds = {b.variable: b for b in guard.bounds(plans.check(scenes.load(user_scene)))}
    assert set(bounds) == {"engine.w", "load.w"}
    assert bounds["load.w"].limit == pytest.approx(10 * 623.0 / 14.06)      # 10 x the engine's no-load speed


def test_the_map_of_the_user_scene_agrees_with_the_observed_classes(user_scene, fmu_dir, tmp_path):
    done = api.stability_map(user_scene, stiffnesses=[1e5], dampings=[0.0, 6.35], h_omegas=[0.05, 0.5, 2.0],
                             masters=["jacobi", "jacobi-linear"], min_steps=200, refine=False, out=tmp_path)
    by_master = done["agreement"]["by_master"]
    assert {m: s["cases"] for m, s in by_master.items()} == {"jacobi": 6, "jacobi-linear": 6}
    assert all(s["agree"] / s["cases"] >= 0.9 for s in by_master.values()), by_master
    text = (tmp_path / "stability.md").read_text()
    assert "Measured, not read from the scene: omega_n +- " in text


def test_the_bench_ladder_of_a_scene_without_bench(user_scene, fmu_dir):
    spec = scenes.load(user_scene.parent / "no_bench.toml")
    p = schedule.plan(spec)
    assert all(len(v) >= 3 for v in (*p["steps"].values(), *p["tolerances"].values()))
    assert set(p["steps"]) | set(p["tolerances"]) | set(p["dropped"]) == set(api.masters())
    assert "offer(s) co-simulation only" in p["dropped"]["me-cvode"]
    stiff = schedule.plan(spec.with_overrides(STIFF), ["jacobi", "adaptive"])
    edge = stability.stability_edge(stability.model_of(spec.with_overrides(STIFF)), "jacobi")
    top = stiff["steps"]["jacobi"][0]
    assert top == pytest.approx(0.8 * edge / 1184.0, rel=0.01) and stiff["steps"]["jacobi"][1] == pytest.approx(top / 2, rel=0.01)
    assert stiff["tolerances"] == {"adaptive": [1e-2, 1e-3, 1e-4]}
    # a master asked for that the scene's [bench] leaves out is said, not dropped silently
    assert "names no steps or tolerances" in schedule.plan(scenes.load(user_scene), ["implicit-newton"])["dropped"][
        "implicit-newton"]


def test_a_scene_without_our_coupling_is_told_what_the_analysis_needs(fmu_dir):
    with pytest.raises(api.InputError, match="Stability analysis needs our LeverCoupling between two shafts"):
        api.stability_map("freewheel_rectifier")


def test_an_fmu_refusing_its_probes_is_named_with_why(user_scene, fmu_dir, monkeypatch):
    def refuse(*args, **kwargs):
        raise RuntimeError("fmi2Instantiate returned fmi2Error")

    monkeypatch.setattr(port_probe, "_speeds", refuse)
    monkeypatch.setattr(port_probe, "_PROBED", {})
    spec = scenes.load(user_scene).with_overrides(["load.inertia=0.2"])
    with pytest.raises(port_probe.ProbeRefused, match=r"load \(FMU DrivenShaft.fmu\) refused the probe runs "
                                                      r"\(RuntimeError: fmi2Instantiate returned fmi2Error\)"):
        stability.model_of(spec)
    said = stability.run_advice(spec, "jacobi", 1e-3)
    assert len(said) == 1 and "no advice for this scene" in said[0] and "DrivenShaft.fmu" in said[0]
    # the map falls back to the observed runs (tests/studies/test_unpredicted_stability_map.py), saying why
    model, why = stabilitymap.linear_model(spec)
    assert model is None and why.startswith("No prediction was made: ") and (
        "load (FMU DrivenShaft.fmu) refused the probe runs (RuntimeError: fmi2Instantiate returned fmi2Error)" in why)


def test_a_long_probe_says_its_estimate_first(user_scene, fmu_dir, monkeypatch):
    monkeypatch.setattr(port_probe, "LONG_PROBE", 0.0)
    monkeypatch.setattr(port_probe, "_PROBED", {})
    heard = []
    stability.model_of(scenes.load(user_scene), say=heard.append)
    assert len(heard) == 1 and heard[0].startswith("probing load (DrivenShaft.fmu): about ")
    assert "(4 runs of 200 steps" in heard[0]
    monkeypatch.setattr(port_probe, "_PROBED", {})       # before a run, too (lever run prints it as a note)
    before_run = []
    assert stability.run_advice(scenes.load(user_scene), "jacobi", 1e-3, say=before_run.append) == []
    assert len(before_run) == 1 and before_run[0].startswith("probing load (DrivenShaft.fmu): about ")


def test_an_fmu_offering_model_exchange_is_linearised_and_predicts_as_our_own(fmu_dir, tmp_path):
    """Our LoadShaft under another file name is a foreign FMU to the analysis: linearised from
    its Model Exchange derivatives, its model and one-step maps are those of kavz685."""
    import dataclasses
    import shutil

    ours = scenes.load("kavz685")
    shutil.copy(fmu_dir / "LoadShaft.fmu", tmp_path / "MyShaft.fmu")
    components = dict(ours.components)
    components["load"] = scenes.ComponentSpec(str(tmp_path / "MyShaft.fmu"), dict(ours.components["load"].parameters))
    theirs = dataclasses.replace(ours, name="kavz685_foreign_load", components=components)
    expected, model = stability.model_of(ours), stability.model_of(theirs)
    (side, port), = model.measured
    assert side == "driven" and port.method == "Model Exchange derivatives"
    assert model.omega_n == pytest.approx(expected.omega_n, rel=1e-9) and model.zeta == pytest.approx(expected.zeta,
                                                                                                     rel=1e-6)
    for master in ("jacobi", "jacobi-linear", "jacobi-midpoint", "trapezoidal-newton"):
        h = expected.step_for(0.5)
        assert stability.spectral_radius(model, master, h) == pytest.approx(
            stability.spectral_radius(expected, master, h), rel=1e-7), master
