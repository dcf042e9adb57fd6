"""FMI: a variable without a ``unit`` has an unknown unit, not unit 1.  A connection with
such a side is made and named once as not checked for dimension; only two declared units
of different dimensions refuse it."""
from __future__ import annotations

from types import SimpleNamespace

from harness.description import scene as scenes
from harness.description import units


def _variable(name, causality, unit=None, type_unit=None):
    declared = SimpleNamespace(unit=type_unit) if type_unit is not None else None
    return SimpleNamespace(name=name, causality=causality, type="Real", unit=unit, declaredType=declared,
                           derivative=None)


def _scene_and_descriptions(load_unit, coupling_unit="rad", type_unit=None):
    scene = SimpleNamespace(components={"coupling": scenes.ComponentSpec("C"), "load": scenes.ComponentSpec("L")},
                            connections=[scenes.parse_connection("load.phi -> coupling.phi2")])
    descriptions = {"C": SimpleNamespace(modelVariables=[_variable("phi2", "input", coupling_unit)]),
                    "L": SimpleNamespace(modelVariables=[_variable("phi", "output", load_unit, type_unit)])}
    return scene, descriptions


def _findings(scene, descriptions):
    variables = {n: {v.name: v for v in descriptions[c.fmu].modelVariables} for n, c in scene.components.items()}
    return scenes.connection_findings(scene.connections[0], variables)


def test_a_side_without_a_unit_is_connected_and_named_as_unchecked():
    scene, descriptions = _scene_and_descriptions(load_unit=None)
    assert _findings(scene, descriptions) == []
    unchecked = scenes.unchecked_connections(scene, descriptions)
    assert unchecked == ["load.phi -> coupling.phi2 (load.phi declares no unit)"]
    assert "1 connection not checked for dimension" in scenes.unchecked_message(unchecked)


def test_declared_units_of_different_dimensions_are_still_refused():
    scene, descriptions = _scene_and_descriptions(load_unit="1")        # "1" declared: dimensionless
    [finding] = _findings(scene, descriptions)
    assert "different quantity" in finding and "(1, dimensionless)" in finding
    assert scenes.unchecked_connections(scene, descriptions) == []


def test_a_unit_from_the_declared_type_counts_as_declared():
    scene, descriptions = _scene_and_descriptions(load_unit=None, type_unit="deg")
    assert units.declared_unit(descriptions["L"].modelVariables[0]) == "deg"
    assert _findings(scene, descriptions) == [] and scenes.unchecked_connections(scene, descriptions) == []
    scene, descriptions = _scene_and_descriptions(load_unit=None, type_unit="N.m")
    assert "different quantity" in _findings(scene, descriptions)[0]
