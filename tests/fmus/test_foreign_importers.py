"""What importers built on FMIL (PyFMI, OMSimulator) read of our model descriptions, checked
without them: the capability flags they refuse an FMU for, and the continuous states they
count from the ``derivative`` attributes (FMIL counts one state per attribute; FMI defines
the states by ``<ModelStructure><Derivatives>`` / ``<ContinuousStateDerivative>``)."""
from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from harness.description.fmu_description import read_description, time_derivatives
from harness.paths import fmi3_dir
from lever.fmus.registry import NAMES


def _editions(fmu_dir) -> list[tuple[str, Path]]:
    return [(f"{name} FMI {edition}", folder / f"{name}.fmu")
            for edition, folder in (("2.0", Path(fmu_dir)), ("3.0", fmi3_dir(fmu_dir))) for name in NAMES]


def _description(path: Path) -> ET.Element:
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def test_no_interface_needs_an_execution_tool(fmu_dir):
    """FMI: needsExecutionTool="true" says the FMU only talks to a tool that has to be
    started for it; PyFMI refuses such an FMU.  Ours loads its Python runtime itself."""
    for label, path in _editions(fmu_dir):
        root = _description(path)
        interfaces = [root.find(tag) for tag in ("ModelExchange", "CoSimulation")]
        assert all(i is not None for i in interfaces), label
        for interface in interfaces:
            assert interface.get("needsExecutionTool", "false") == "false", (label, interface.tag)


def test_states_counted_from_the_attributes_are_the_declared_states(fmu_dir):
    """The variables with a ``derivative`` attribute are exactly the state derivatives of
    the ModelStructure, in both editions: OMSimulator's Model Exchange failed with '5 states
    given, this model has 3' when inputs carried the attribute."""
    for label, path in _editions(fmu_dir):
        root = _description(path)
        fmi3 = root.get("fmiVersion").startswith("3")
        variables = list(root.find("ModelVariables"))
        if fmi3:
            attributed = {v.get("valueReference") for v in variables if v.get("derivative") is not None}
            declared = {u.get("valueReference") for u in root.iterfind("ModelStructure/ContinuousStateDerivative")}
        else:
            attributed = {str(i) for i, v in enumerate(variables, start=1) if v[0].get("derivative") is not None}
            declared = {u.get("index") for u in root.iterfind("ModelStructure/Derivatives/Unknown")}
        assert attributed == declared, label


@pytest.mark.parametrize("fmu, expected", [
    ("EngineShaft", {"tau_rate": "tau", "tau_accel": "tau_rate", "w": "phi", "a": "w",
                     "der(engine_work)": "engine_work", "der(lagged_torque)": "lagged_torque"}),
    ("LoadShaft", {"tau_rate": "tau", "tau_accel": "tau_rate", "w": "phi", "a": "w", "der(load_work)": "load_work"}),
    ("MisalignmentSource", {"misalignment_rate": "misalignment"}),
    ("LeverCoupling", {}),
])
def test_every_time_derivative_relation_is_read_in_both_editions(fmu_dir, fmu, expected):
    """The relations the masters use (a shaft's torque rate inputs, the source's rate
    output) are read from our annotation, the state derivatives from the attribute."""
    for folder in (Path(fmu_dir), fmi3_dir(fmu_dir)):
        md = read_description(folder / f"{fmu}.fmu")
        assert time_derivatives(md) == expected, folder
