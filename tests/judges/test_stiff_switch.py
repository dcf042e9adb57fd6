"""Where the monolithic reference leaves DOP853 for a stiff method (harness/judges/monolithic.py).

The promise: DOP853 is stable for steps up to about 6 / (the fastest decay rate) (its
stability region on the negative real axis, Hairer & Wanner); a scene that would need more
than 100,000 such steps over its span is solved by a stiff method - CVODE's BDF, or Radau
where the load can stick.  The decay is worked out here a second way - the eigenvalues of a
central-difference Jacobian of the driveline's right-hand side, not its analytic one - and
the span set 5 % either side of the switch: the choice, not the wall time, is tested."""
from __future__ import annotations

import numpy as np
import pytest

from lever.physics.driveline import Driveline

from harness.description import scene as scenes
from harness.judges import monolithic

#: a coupling stiff and damped enough that the switch comes within milliseconds
STIFF = ["coupling.stiffness=1e9", "coupling.damping=1e7"]
STABILITY, BUDGET = 6.0, 100_000


def _decay_by_differences(plan, coupling=None) -> float:
    """The fastest decay rate at the start; ``coupling``: another than the scene's own."""
    built = plan.driveline.physics.get()
    (phi1, w1), (phi2, w2) = plan.driveline.start.get()
    driveline = Driveline(built.engine, lambda t: coupling or built.coupling, built.load)
    y0 = np.array([phi1, w1, phi2, w2, 0.0, 0.0, 0.0])
    jac = np.zeros((7, 7))
    for j in range(7):
        h = 1e-6 * max(1.0, abs(y0[j]))
        up, down = y0.copy(), y0.copy()
        up[j] += h
        down[j] -= h
        jac[:, j] = (np.array(driveline.derivatives(0.0, up)) - np.array(driveline.derivatives(0.0, down))) / (2 * h)
    return float(max([-z.real for z in np.linalg.eigvals(jac)] + [0.0]))


@pytest.mark.parametrize("name,stiff", [("kavz685", "CVODE-BDF"), ("kavz685_stall_resistive", "Radau")])
def test_the_switch_comes_where_dop853_would_need_more_than_its_budget(name, stiff, fmu_dir):
    plan = monolithic.planned(scenes.load(name).with_overrides(STIFF))
    decay = _decay_by_differences(plan)
    switch = BUDGET * STABILITY / decay                 # the span at which DOP853 would need BUDGET steps
    for share, expected, t0, n in ((0.95, "DOP853", 0.0, 11), (1.05, stiff, 0.0, 11), (0.95, "DOP853", 0.5, 2),
                                   (1.05, stiff, 0.5, 2)):
        times = np.linspace(t0, t0 + share * switch, n)     # the span counts, not where it starts
        method, note = monolithic.reference_method(plan, times)
        assert method == expected, (share, switch, note)
        if expected == "DOP853":
            assert note == ""
        else:
            said = float(note.split("decays at ")[1].split(" 1/s")[0])
            assert said == pytest.approx(decay, rel=1e-3)
            steps = float(note.split("about ")[1].split(" steps")[0])
            assert steps == pytest.approx(share * BUDGET, rel=1e-2)
    # another method asked for is taken as asked, whatever the stiffness
    assert monolithic.reference_method(plan, np.linspace(0.0, 2 * switch, 3), "RK45") == ("RK45", "")


def test_a_scene_just_past_the_switch_is_solved_by_the_stiff_method(fmu_dir):
    plan = monolithic.planned(scenes.load("kavz685").with_overrides(STIFF))
    times = np.linspace(0.0, 1.05 * BUDGET * STABILITY / _decay_by_differences(plan), 21)
    solution = monolithic.solve(plan, times, use_cache=False)
    assert solution.method.startswith("CVODE-BDF") and "stiff: a mode decays at" in solution.method
    assert np.array_equal(solution.times, times)
    assert np.all(np.isfinite(solution.traces["coupling.tau2"]))


def test_a_driven_misalignment_is_judged_at_its_value_at_the_start(fmu_dir):
    """The coupling's own misalignment parameter (35 deg) is not what it runs at: the source
    drives it from 15 deg, and the decay is the coupling's there."""
    plan = monolithic.planned(scenes.load("kavz685_misalignment_ramp").with_overrides(
        STIFF + ["coupling.misalignment=35 deg"]))
    source, family = plan.driveline.misalignment.get()
    driven = _decay_by_differences(plan, family.at(source.value(0.0)))
    assert abs(driven / _decay_by_differences(plan) - 1) > 5e-3       # the two differ
    method, note = monolithic.reference_method(plan, np.array([0.0, 1.002 * BUDGET * STABILITY / driven]))
    assert method == "CVODE-BDF"
    assert float(note.split("decays at ")[1].split(" 1/s")[0]) == pytest.approx(driven, rel=2e-4)


def test_a_driveline_without_a_decaying_mode_keeps_dop853_whatever_its_span(fmu_dir):
    """No damping anywhere (coupling, engine line, load): no mode decays, so DOP853's
    stability asks nothing of its step, over a million seconds as over one."""
    plan = monolithic.planned(scenes.load("kavz685").with_overrides(
        ["coupling.damping=0", "engine.torque_slope=0", "load.load_kind=constant"]))
    assert _decay_by_differences(plan) < 1e-3
    assert monolithic.reference_method(plan, np.array([0.0, 1e6])) == ("DOP853", "")
