"""A run goes down the layers once: the plan carries the checked physics, and the stability
advice, the reference and the energy balance read it instead of checking the scene's values
again."""
from __future__ import annotations

import collections
import sys

from lever.physics import component_parameters
from lever.physics.parameters import Parameter, check_all

from harness import api
from harness.description import plan as plans, scene as scenes


def _checks_during(action):
    """``action()``'s calls of ``check_all`` (by the declarations checked) and of
    ``Parameter.check`` (by parameter), counted by their code, whoever imported them."""
    by_declared, by_parameter = collections.Counter(), collections.Counter()
    check_all_code, check_code = check_all.__code__, Parameter.check.__code__

    def profile(frame, event, _):
        if event != "call":
            return
        if frame.f_code is check_all_code:
            by_declared[id(frame.f_locals["declared"])] += 1
        elif frame.f_code is check_code:
            by_parameter[id(frame.f_locals["self"])] += 1

    previous = sys.getprofile()
    sys.setprofile(profile)
    try:
        action()
    finally:
        sys.setprofile(previous)
    return by_declared, by_parameter


def test_a_run_checks_each_components_parameters_once():
    quiet = {"plots": False, "notify": lambda *_: None}
    api.run("kavz685", stop=0.2, **quiet)       # warm-up: what a process builds once is not counted
    by_declared, by_parameter = _checks_during(lambda: api.run("kavz685", stop=0.2, **quiet))
    declared = {"engine": component_parameters.ENGINE, "coupling": component_parameters.COUPLING,
                "load": component_parameters.LOAD}
    assert {name: by_declared[id(d)] for name, d in declared.items()} == {name: 1 for name in declared}
    assert sum(by_declared.values()) == 3
    twice = [f"{name}.{p.name}" for name, d in declared.items() for p in d if by_parameter[id(p)] != 1]
    assert twice == []
    assert by_parameter[id(component_parameters.MISALIGNMENT)] == 1


def test_a_scene_changed_after_its_plan_is_planned_anew():
    scene = scenes.load("kavz685")
    first = plans.driveline_of(scene)
    assert plans.driveline_of(scene) is first
    assert plans.check(scene).driveline is first
    scene.components["coupling"].parameters["stiffness"] = 1234.0
    again = plans.driveline_of(scene)
    assert again is not first and again.coupling.get()[0]["stiffness"] == 1234.0
    assert plans.driveline_of(scenes.load("kavz685")) is not again
