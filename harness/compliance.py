"""``lever compliance FMU``: does an FMU file follow the standards and the practice of
modelica/Reference-FMUs?  fmpy's validation plus our own checks, each a pure function
returning findings (empty: nothing to report), fmpy style.

Our checks, on the model description:

* every variable has a description and refers to a type definition (``declaredType``);
* every real variable has a unit (its own or its type's), defined in ``UnitDefinitions``,
  unless its type says it is a ratio;
* parameters and inputs of numeric type have ``min`` and ``max``, and their start values
  lie between them;
* a ``DefaultExperiment`` with start, stop and step; ``LogCategories``;
* state handling: ``canSerializeFMUstate`` only with ``canGetAndSetFMUstate``;

FMI 2.0 and 3.0 model descriptions alike (FMI 3.0's ``Float64``/``Int32`` as ``Real``/``Integer``);

on the archive: ``documentation/_main.html`` (FMI 2.0's documentation entry point; FMI 3.0:
``index.html``); for a
pythonfmu FMU, ``resources/requirements.txt`` (what the importer's Python needs); a binary
for each platform it claims;

and on ``<Model>_OspModelDescription.xml`` next to the FMU, when there is one: each
variable it names exists, a port's torque and angular velocity have opposite causality,
and the variables' units fit their groups (N.m, rad/s, rad).

Whether a declared capability is true (a restored state continues exactly) is a matter
of running the FMU: the tests do that.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

#: OSP-IS variable groups we check: group element -> the unit its variables must have
OSP_GROUP_UNITS = {"Torque": "N.m", "AngularVelocity": "rad/s", "AngularDisplacement": "rad"}
#: types whose real variables may carry no unit
DIMENSIONLESS_QUANTITIES = ("Ratio",)


def check_fmu(path: str | Path) -> list[str]:
    """All findings about the FMU file ``path`` (and its OSP model description next to it)."""
    path = Path(path)
    if not path.is_file():
        return [f"{path}: no such file"]
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            model_description = archive.read("modelDescription.xml")
    except (zipfile.BadZipFile, KeyError) as error:
        return [f"{path.name}: not an FMU archive with a modelDescription.xml ({error})"]
    findings = fmpy_findings(path)
    try:
        root = ET.fromstring(model_description)
    except ET.ParseError as error:
        return findings + [f"modelDescription.xml does not parse: {error}"]
    findings += variable_findings(root)
    findings += experiment_findings(root)
    findings += archive_findings(root, names)
    osp = path.with_name(f"{path.stem}_OspModelDescription.xml")
    if osp.exists():
        findings += osp_findings(root, osp.read_text())
    return findings


def fmpy_findings(path: Path) -> list[str]:
    from fmpy.validation import validate_fmu
    return [f"fmpy: {problem}" for problem in validate_fmu(str(path))]


#: FMI 3.0's variable and type elements under the FMI 2.0 names our checks use
_FMI3_KINDS = {"Float64": "Real", "Float32": "Real", "Int32": "Integer", "Int64": "Integer", "Boolean": "Boolean",
               "String": "String"}


class _Typed:
    """An FMI 3.0 variable or type element seen as FMI 2.0's type element (tag ``Real``...)."""

    def __init__(self, element: ET.Element):
        self.element, self.tag = element, _FMI3_KINDS.get(element.tag.removesuffix("Type"), element.tag)

    def get(self, key, default=None):
        return self.element.get(key, default)


def _is_fmi3(root: ET.Element) -> bool:
    return (root.get("fmiVersion") or "").startswith("3.")


def _types(root: ET.Element) -> dict[str, ET.Element]:
    """Type name -> its type element (``Real``, ``Integer``, ...)."""
    types = {}
    if _is_fmi3(root):
        return {t.get("name"): _Typed(t) for t in root.iterfind("TypeDefinitions/*")}
    for simple in root.iterfind("TypeDefinitions/SimpleType"):
        if len(simple):
            types[simple.get("name")] = simple[0]
    return types


def _variables(root: ET.Element):
    """(variable element, its type element) of every variable, FMI 2.0 or 3.0 (FMI 3.0's
    independent variable, which has no type of its own, left out)."""
    if _is_fmi3(root):
        for var in root.find("ModelVariables") if root.find("ModelVariables") is not None else ():
            if var.get("causality") != "independent":
                yield var, _Typed(var)
        return
    for var in root.iterfind("ModelVariables/ScalarVariable"):
        yield var, var[0] if len(var) else None


def variable_findings(root: ET.Element) -> list[str]:
    findings = []
    types = _types(root)
    units = {u.get("name") for u in root.iterfind("UnitDefinitions/Unit")}
    for var, typed in _variables(root):
        name, causality = var.get("name"), var.get("causality", "local")
        if typed is None:
            findings.append(f"variable '{name}': no type element")
            continue
        if not (var.get("description") or "").strip():
            findings.append(f"variable '{name}': no description")
        declared = typed.get("declaredType")
        base = types.get(declared) if declared else None
        if declared is None:
            findings.append(f"variable '{name}': no declaredType (every variable refers to a type definition)")
        elif base is None:
            findings.append(f"variable '{name}': declaredType '{declared}' is not in TypeDefinitions")
        elif base.tag != typed.tag:
            findings.append(f"variable '{name}': a {typed.tag} of type '{declared}', which is a {base.tag}")

        def attribute(key):
            value = typed.get(key)
            return value if value is not None or base is None else base.get(key)

        if typed.tag == "Real":
            unit = attribute("unit")
            if unit is None:
                quantity = base.get("quantity") if base is not None else None
                if quantity not in DIMENSIONLESS_QUANTITIES:
                    findings.append(f"variable '{name}': a Real without a unit (and its type is not a ratio)")
            elif unit not in units:
                findings.append(f"variable '{name}': unit '{unit}' is not in UnitDefinitions")
        if typed.tag in ("Real", "Integer") and causality in ("parameter", "input"):
            low, high = attribute("min"), attribute("max")
            if low is None or high is None:
                findings.append(f"{causality} '{name}': no {'min' if low is None else 'max'}")
            else:
                start = typed.get("start")
                if start is not None and not float(low) <= float(start) <= float(high):
                    findings.append(f"{causality} '{name}': start {start} outside [{low}, {high}]")
                if not float(low) <= float(high):
                    findings.append(f"{causality} '{name}': min {low} > max {high}")
    return findings


def experiment_findings(root: ET.Element) -> list[str]:
    findings = []
    experiment = root.find("DefaultExperiment")
    if experiment is None:
        findings.append("no DefaultExperiment")
    else:
        for key in ("startTime", "stopTime", "stepSize"):
            value = experiment.get(key)
            if value is None:
                findings.append(f"DefaultExperiment has no {key}")
            elif not math.isfinite(float(value)):
                findings.append(f"DefaultExperiment {key} = {value} is not finite")
        start, stop, step = (experiment.get(k) for k in ("startTime", "stopTime", "stepSize"))
        if None not in (start, stop, step) and not (float(stop) > float(start) and 0 < float(step) <= float(stop)
                                                    - float(start)):
            findings.append(f"DefaultExperiment: expected start < stop and 0 < step <= stop - start "
                            f"(start {start}, stop {stop}, step {step})")
    if not list(root.iterfind("LogCategories/Category")):
        findings.append("no LogCategories")
    cs = root.find("CoSimulation")
    state = "FMUState" if _is_fmi3(root) else "FMUstate"
    if cs is None:
        findings.append("no CoSimulation element")
    elif cs.get(f"canSerialize{state}") == "true" and cs.get(f"canGetAndSet{state}") != "true":
        findings.append(f"canSerialize{state} without canGetAndSet{state}")
    return findings


def archive_findings(root: ET.Element, names: list[str]) -> list[str]:
    findings = []
    entry = "documentation/index.html" if _is_fmi3(root) else "documentation/_main.html"
    if entry not in names:
        findings.append(f"no {entry} (FMI {'3.0' if _is_fmi3(root) else '2.0'}'s documentation entry point)")
    cs = root.find("CoSimulation")
    identifier = cs.get("modelIdentifier") if cs is not None else None
    binaries = [n for n in names if n.startswith("binaries/") and not n.endswith("/")]
    if identifier and not any(Path(n).stem == identifier for n in binaries):
        findings.append(f"no binary named {identifier} in binaries/")
    is_pythonfmu = (root.get("generationTool") or "").startswith("PythonFMU") or "resources/slavemodule.txt" in names
    if is_pythonfmu and "resources/requirements.txt" not in names:
        findings.append("a pythonfmu FMU without resources/requirements.txt (the Python packages the importer "
                        "needs)")
    return findings


def osp_findings(root: ET.Element, osp_text: str) -> list[str]:
    """Findings about an OSP model description, against the FMU's model description."""
    try:
        osp = ET.fromstring(osp_text)
    except ET.ParseError as error:
        return [f"OspModelDescription does not parse: {error}"]
    variables = {v.get("name"): v for v in root.iterfind("ModelVariables/ScalarVariable")}
    types = _types(root)
    findings = []

    def local(tag):
        return tag.rsplit("}", 1)[-1]

    def group_variables(group):
        return [v.get("ref") for v in group if local(v.tag) == "Variable"]

    def causality_of(group):
        return {variables[r].get("causality") for r in group_variables(group) if r in variables}

    groups = next((g for g in osp if local(g.tag) == "VariableGroups"), None)
    if groups is None:
        return ["OspModelDescription: no VariableGroups"]
    for group in groups.iter():
        kind = local(group.tag)
        for ref in group_variables(group):
            var = variables.get(ref)
            if var is None:
                findings.append(f"OspModelDescription {kind} '{group.get('name')}': no variable '{ref}' in the FMU")
                continue
            expected = OSP_GROUP_UNITS.get(kind)
            typed = var[0]
            unit = typed.get("unit") or (types[typed.get("declaredType")].get("unit")
                                         if typed.get("declaredType") in types else None)
            if expected and unit != expected:
                findings.append(f"OspModelDescription {kind} '{group.get('name')}': variable '{ref}' has unit "
                                f"{unit!r}, expected {expected!r}")
        if kind in ("AngularMechanicalPort", "LinearMechanicalPort"):
            parts = [child for child in group]
            if len(parts) != 2:
                findings.append(f"OspModelDescription {kind} '{group.get('name')}': expected an effort and a flow")
                continue
            effort, flow = causality_of(parts[0]), causality_of(parts[1])
            if len(effort) != 1 or len(flow) != 1 or effort == flow or not effort | flow <= {"input", "output"}:
                findings.append(f"OspModelDescription {kind} '{group.get('name')}': effort and flow must have "
                                f"opposite causality (input/output), got {sorted(effort)} and {sorted(flow)}")
    return findings
