"""The unsplit driveline under SUNDIALS CVODE (harness.judges.cvode): the same right-hand
side as the DOP853 reference, the physics' analytic Jacobian (docs/record/decisions.md)."""
from __future__ import annotations

import numpy as np
import pytest

from harness.description import scene_kinds
from harness.description import scene as scenes
from harness.judges import cvode, metrics, monolithic
from harness.judges.solution import ReferenceUnavailable
from lever.physics import component_parameters
from lever.physics.driveline import Driveline


def torque_error(scene, times, solution, reference):
    e = metrics.driveline_errors(scene, times, solution.traces, reference.times, reference.traces)
    return max(e["coupling.tau1"]["rms_relative"], e["coupling.tau2"]["rms_relative"])


@pytest.mark.parametrize("method", ["CVODE-BDF", "CVODE-Adams"])
def test_cvode_agrees_with_the_dop853_reference(method):
    scene = scenes.load("kavz685")
    times = np.linspace(0.0, 1.0, 1001)
    reference = monolithic.solve(scene, times)                  # DOP853, rtol 1e-10
    solution = monolithic.solve(scene, times, use_cache=False, rtol=1e-9, atol=1e-11, method=method)
    assert solution.method.startswith(method)
    assert torque_error(scene, times, solution, reference) < 1e-6
    for name in ("engine.w", "load.w", "engine.engine_work", "coupling.dissipated_energy"):
        assert np.allclose(solution.traces[name], reference.traces[name], rtol=1e-6, atol=1e-6), name


def stiff_driveline(name):
    scene = scenes.load(name)
    built, roles = scene_kinds.physics(scene), scene_kinds.driveline(scene)
    y0 = (list(component_parameters.start_state(scene_kinds.parameters(scene, roles.engine), component_parameters.ENGINE))
          + list(component_parameters.start_state(scene_kinds.parameters(scene, roles.load), component_parameters.LOAD)) + [0.0] * 3)
    return scene, Driveline(built.engine, lambda t: built.coupling, built.load), y0


def test_the_analytic_jacobian_saves_right_hand_side_evaluations_on_the_stiff_scene():
    """CVODE's difference-quotient Jacobian costs one right-hand side per state each time
    it is formed; the analytic one none, for the same solution."""
    scene, system, y0 = stiff_driveline("kavz685_step_tiny_inertia")
    times = np.linspace(scene.experiment.start, scene.experiment.stop, 101)
    _, y_analytic, analytic = cvode.integrate(system, times, y0, "BDF", 1e-8, 1e-10, 1e-6, analytic_jacobian=True)
    _, y_differences, differences = cvode.integrate(system, times, y0, "BDF", 1e-8, 1e-10, 1e-6,
                                                    analytic_jacobian=False)
    assert analytic["jacobian"] > 0 and differences["jacobian"] > 0
    assert analytic["rhs"] <= 0.95 * differences["rhs"]
    assert np.allclose(y_analytic[1], y_differences[1], rtol=1e-6)


def test_cvode_refuses_a_load_that_sticks():
    scene = scenes.load("kavz685_stall_resistive")
    with pytest.raises(ReferenceUnavailable, match="stick"):
        monolithic.solve(scene, np.linspace(0.0, 0.1, 11), use_cache=False, method="CVODE-BDF")


@pytest.mark.parametrize("method", ["DOP853", "CVODE-Adams"])
def test_the_unsplit_solutions_time_covers_its_recorded_outputs(method, monkeypatch):
    """A master's run time covers reading its recorded outputs at every point; the unsplit
    solution's covers computing them (the benchmark divides one by the other): the shafts'
    accelerations and torques, computed from the solution, made slow here."""
    import time

    scene = scenes.load("kavz685")
    times = np.linspace(0.0, 0.05, 51)
    rates = monolithic._shaft_rates

    def slow(*args):
        time.sleep(0.05)
        return rates(*args)

    monkeypatch.setattr(monolithic, "_shaft_rates", slow)
    solution = monolithic.solve(scene, times, use_cache=False, rtol=1e-6, atol=1e-8, method=method)
    assert solution.wall_time >= 2 * 0.05           # both shafts' rates


# -- the reference of a scene too stiff for DOP853 ----------------------------------------------

STIFF = ["coupling.stiffness=1e9", "coupling.damping=1e7"]


@pytest.mark.parametrize("name,method", [("kavz685", "CVODE-BDF"), ("kavz685_stall_resistive", "Radau")])
def test_a_scene_too_stiff_for_dop853_gets_a_stiff_reference_that_ends(name, method):
    """A 1.4e8 1/s decay would hold DOP853 to about 4.6e6 steps over 0.2 s (it ran for more
    than 300 s): the reference is CVODE's BDF (Radau where the load can stick), says why,
    and agrees with the unsplit CVODE-BDF solution of the same equations."""
    scene = scenes.load(name).with_overrides(STIFF)
    times = np.linspace(0.0, 0.05, 51)
    solution = monolithic.solve(scene, times, use_cache=False)
    assert solution.method.startswith(method) and "stiff: a mode decays at 1.393e+08 1/s" in solution.method
    assert solution.times[-1] == times[-1]
    if method == "Radau":
        bdf = monolithic.solve(scenes.load("kavz685").with_overrides(STIFF), times, use_cache=False)
        assert bdf.method.startswith("CVODE-BDF")
        return
    radau = monolithic.solve(scene, times, use_cache=False, method="Radau")
    for signal in ("engine.w", "load.w", "coupling.tau1"):
        scale = np.ptp(radau.traces[signal]) + 1e-9
        assert np.max(np.abs(solution.traces[signal] - radau.traces[signal])) <= 1e-4 * scale


def test_every_committed_driveline_scene_keeps_dop853():
    """The switch to a stiff method is for scenes DOP853 cannot finish: every committed
    driveline scene's reference stays DOP853's over its whole span (references are cached
    and judged; their traces were checked bit-identical before and after the switch came)."""
    from harness.paths import SCENES

    checked = 0
    for path in sorted(SCENES.glob("*.toml")):
        plan = monolithic.planned(scenes.load(path.stem))
        if plan.kind != "driveline" or plan.driveline_problem:
            continue
        e = plan.scene.experiment
        times = np.array([e.start, e.stop])
        assert monolithic.reference_method(plan, times) == ("DOP853", ""), path.stem
        checked += 1
    assert checked >= 12
