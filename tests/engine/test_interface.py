"""The interface masters see of a component (harness.engine.interface.CoSimComponent):
the FMU components and the stability analysis's linear stand-ins both satisfy it."""
import typing

from harness.description import scene
from harness.engine.component import Component
from harness.engine.interface import CoSimComponent, RawCalls
from harness.engine.system import System
from harness.judges import stability

MEMBERS = [name for name in dir(CoSimComponent) if not name.startswith("_")] + \
    list(typing.get_type_hints(CoSimComponent))


def _satisfies(component):
    missing = [name for name in MEMBERS if not hasattr(component, name)]
    assert missing == [] and isinstance(component, CoSimComponent)
    assert isinstance(component.raw, RawCalls) and all(callable(f) for f in component.raw[1:])


def test_the_fmu_components_satisfy_the_interface(fmu_dir):
    system = System(scene.load("kavz685"), fmu_dir)
    try:
        for component in system.components.values():
            assert isinstance(component, Component)
            _satisfies(component)
    finally:
        system.free()


def test_the_stability_stand_ins_satisfy_the_interface(fmu_dir):
    model = stability.model_of(scene.load("kavz685"))
    for component in stability.LinearDriveline(model, 1e-3, fmu_dir).components.values():
        _satisfies(component)
        assert not isinstance(component, Component)


def test_the_interface_names_what_the_masters_and_the_system_call():
    assert {"raw", "fail", "read", "write", "do_step", "save_state", "restore_state", "free_state",
            "real_buffer", "variable", "vr", "description", "calls", "name", "time", "free"} <= set(MEMBERS)
