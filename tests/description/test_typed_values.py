"""One typed value setter (harness.description.typed_values): every type set and written
the same way by the harness, the peers and the exported files."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from types import SimpleNamespace

import pytest

from harness.description import typed_values


def _var(kind, vr=7, **extra):
    return SimpleNamespace(type=kind, valueReference=vr, description="a test variable", min=None, max=None,
                           **extra)


class _Slave:
    """What fmpy's FMU2Slave offers a setter: one call per FMI type."""

    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        if name.startswith("set"):
            return lambda vrs, values: self.calls.append((name, vrs, values))
        raise AttributeError(name)


@pytest.mark.parametrize("kind, value, call, sent", [
    ("Real", "715.4", "setReal", 715.4), ("Integer", 3.0, "setInteger", 3), ("Enumeration", 2, "setInteger", 2),
    ("Boolean", 1, "setBoolean", True), ("String", "scaled", "setString", "scaled")])
def test_each_type_is_set_with_its_fmi_call(kind, value, call, sent):
    slave = _Slave()
    typed_values.set_on(slave, _var(kind), value, "c.p")
    assert slave.calls == [(call, [7], [sent])] and type(slave.calls[0][2][0]) is type(sent)


def test_a_fraction_for_an_integer_is_refused_not_rounded():
    with pytest.raises(ValueError, match=r"^c\.n is an integer, got 2\.5$"):
        typed_values.set_on(_Slave(), _var("Integer"), 2.5, "c.n")
    with pytest.raises(ValueError, match="is an integer"):
        typed_values.literal(_var("Enumeration"), 2.5, "c.n")


@pytest.mark.parametrize("kind, value, element, text", [
    ("Real", 0.1, "Real", "0.1"), ("Integer", 4, "Integer", "4"), ("Enumeration", 2, "Integer", "2"),
    ("Boolean", True, "Boolean", "true"), ("Boolean", False, "Boolean", "false"), ("String", "a b", "String", "a b")])
def test_literals_are_the_xml_types_and_read_back(kind, value, element, text):
    assert typed_values.literal(_var(kind), value, "c.p") == (element, text)
    assert typed_values.parse_literal(kind, text) == value


@pytest.mark.parametrize("kind, text", [("Real", "seven"), ("Real", "nan"), ("Real", "inf"), ("Integer", "1.5"),
                                        ("Boolean", "True"), ("Boolean", "yes")])
def test_malformed_literals_are_refused(kind, text):
    with pytest.raises(ValueError):
        typed_values.parse_literal(kind, text)


def test_a_boolean_parameter_is_written_as_xs_boolean_in_the_osp_file(monkeypatch):
    """No FMU of ours has a Boolean parameter: a model description with one, as another FMU's,
    goes into the OspSystemStructure.xml as xs:boolean ("true"), not Python's "True"."""
    from harness.description import scene as scenes
    from harness.formats import osp

    md = SimpleNamespace(modelVariables=[_var("Boolean", name="enabled", causality="parameter", unit=None),
                                         _var("Enumeration", vr=8, name="mode", causality="parameter", unit=None)])
    monkeypatch.setattr("harness.description.plan.descriptions_for", lambda scene, fmu_dir: {"Other": md})
    monkeypatch.setattr(osp, "scene_groups", lambda scene, fmu_dir: {})
    monkeypatch.setattr(osp, "group_connections", lambda scene, groups: ([], []))
    spec = scenes.Scene(name="other", description="", components={"x": scenes.ComponentSpec("Other", {
        "enabled": True, "mode": 2})}, connections=[], experiment=scenes.Experiment(stop=1.0, step=0.1, master="jacobi",
                                                                                   transient=0.0),
        record=[], features=set())
    root = ET.fromstring(osp.system_structure(spec))
    values = {v.get("variable"): (v[0].tag.rsplit("}", 1)[-1], v[0].get("value"))
              for v in root.iter("{http://opensimulationplatform.com/MSMI/OSPSystemStructure}InitialValue")}
    assert values == {"enabled": ("Boolean", "true"), "mode": ("Integer", "2")}
