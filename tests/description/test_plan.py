"""A scene checked once (harness.description.plan): the plan holds every finding, the
start values in the FMUs' units and the physics objects, and a run and its reference go
from the plan without coming back to the scene's checks."""
import dataclasses
import math

import numpy as np
import pytest

from harness.description import scene_kinds
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine.run import simulate
from harness.engine.system import SceneInvalid
from harness.judges import monolithic
from lever.physics.parameters import ParameterError


def _short(name: str, *changes: str) -> scenes.Scene:
    return scenes.load(name).with_overrides(["experiment.stop=0.05", *changes])


def test_the_plan_holds_the_findings_the_values_and_the_physics(fmu_dir):
    plan = plans.check(scenes.load("kavz685"), fmu_dir=fmu_dir)
    assert plan.refusals == () and plan.unconnected == () and plan.kind == "driveline"
    # "15 deg" in the scene, radians for the coupling FMU; a string parameter as it is
    assert plan.start_values["coupling"]["misalignment"] == pytest.approx(math.radians(15))
    assert plan.start_values["coupling"]["transfer_mode"] == "kinematic"
    assert set(scene_kinds.energy_variables(plan.scene)) <= set(plan.recorded)
    assert plan.driveline.physics.get().coupling.law.stiffness == pytest.approx(715.4)
    (_, w1), (_, w2) = plan.driveline.start.get()
    assert w1 == w2 == pytest.approx(39.0)         # both shafts at 39 rad/s at t = 0
    # immutable: neither the record nor its tables can be changed
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.refusals = ()
    with pytest.raises(TypeError):
        plan.start_values["coupling"]["stiffness"] = 1.0


def test_overrides_are_applied_once_by_check(fmu_dir):
    base = scenes.load("kavz685")
    plan = plans.check(base, ["coupling.stiffness=900"], fmu_dir=fmu_dir)
    assert plan.scene == base.with_overrides(["coupling.stiffness=900"])
    assert plan.start_values["coupling"]["stiffness"] == 900
    assert base.components["coupling"].parameters["stiffness"] == 715.4      # the loaded scene is kept
    with pytest.raises(scenes.SceneError, match="no component 'coupler'"):
        plans.check(base, ["coupler.stiffness=900"], fmu_dir=fmu_dir)


def test_a_refused_scene_keeps_its_findings_and_the_error_of_its_physics(fmu_dir):
    spec = _short("kavz685", "coupling.stiffness=-1")
    plan = plans.check(spec, fmu_dir=fmu_dir)
    assert list(plan.refusals) == scenes.validate(spec, plans.descriptions_for(spec, fmu_dir))
    assert plan.start_values == {}
    with pytest.raises(SceneInvalid) as refused:
        simulate(plan)
    assert refused.value.findings == list(plan.refusals)
    # the physics' own refusal, raised where the physics is used (the reference)
    with pytest.raises(ParameterError, match="stiffness"):
        monolithic.solve(plan, np.linspace(0, 0.05, 6), use_cache=False)


@pytest.mark.parametrize("name", ["kavz685", "kavz685_misalignment_ramp", "freewheel_rectifier"])
def test_a_run_and_its_reference_go_from_the_plan_alone(name, fmu_dir, monkeypatch):
    spec = _short(name)
    expected = simulate(spec, fmu_dir=fmu_dir)
    expected_reference = monolithic.solve(spec, expected.times, use_cache=False)
    plan = plans.check(spec, fmu_dir=fmu_dir)

    def checked_again(*args, **kwargs):
        raise AssertionError("the scene was checked again after its plan was made")

    for module, name_ in ((scenes, "validate"), (scenes, "unconnected_inputs"), (scenes, "quantity"),
                          (scene_kinds, "physics"), (scene_kinds, "parameters"), (scene_kinds, "driveline_problem"),
                          (scene_kinds, "rectifier_model"), (plans, "check")):
        monkeypatch.setattr(module, name_, checked_again)
    result = simulate(plan)
    assert result.ok, result.failure
    assert np.array_equal(result.times, expected.times)
    assert all(np.array_equal(result.traces[n], expected.traces[n]) for n in expected.traces)
    assert result.unconnected_inputs == expected.unconnected_inputs
    reference = monolithic.solve(plan, result.times, use_cache=False)
    assert reference.traces.keys() == expected_reference.traces.keys()
    assert all(np.array_equal(reference.traces[n], expected_reference.traces[n]) for n in reference.traces)
