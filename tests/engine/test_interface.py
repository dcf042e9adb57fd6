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


def test_a_component_loads_fmpys_own_prototypes_once(fmu_dir):
    """The C functions' prototypes worked out once a process are fmpy's own, function by
    function, and the loaded instance is fmpy's FMU2Slave (fmpy's simulate_fmu tells the
    interface by the exact class)."""
    from pathlib import Path
    from fmpy.fmi2 import FMU2Slave

    first, second = (Component(f"shaft{k}", Path(fmu_dir) / "EngineShaft.fmu") for k in range(2))
    try:
        own = FMU2Slave(guid=first.description.guid, unzipDirectory=first.unzipped_dir,
                        modelIdentifier=first.description.coSimulation.modelIdentifier)
        for component in (first, second):
            assert type(component.fmu) is FMU2Slave
            assert component.fmu._functions.keys() == own._functions.keys()
            for name, function in own._functions.items():
                mine = component.fmu._functions[name]
                assert (mine.argnames, mine.argtypes, mine.restype) == \
                    (function.argnames, function.argtypes, function.restype), name
    finally:
        first.free()
        second.free()
