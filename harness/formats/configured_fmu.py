"""An FMU configured with start values: a copy of one of our FMUs whose parameters and
inputs start at the values given, for an engine that sets nothing itself (fmpy.ssp without a
parameter set, OMSimulator, which drops String parameter bindings).

Three parts of the copy say the same values (docs/fmus.md, "Configured start values"):

* the model description's ``start`` of each variable (FMI 2.0 ``start`` attribute, FMI 3.0
  ``start`` or, for a String, ``<Start value=...>``): what the FMU has after instantiation;
* ``resources/lever_start_values.json``, which the FMU takes them from when it is
  instantiated (only FMUs whose ``lever-cosim`` annotation names it can be configured);
* a new GUID (FMI 2.0 ``guid``; FMI 3.0 ``instantiationToken``), also in
  ``resources/lever_shim.cfg``, the one the FMU accepts: FMI makes the GUID the fingerprint
  of the model description the implementation belongs to, and this is another description.
  It is derived from the original GUID and the values, so that the same configuration
  always gets the same GUID and an importer cannot pair the configured description with the
  unconfigured FMU (or the other way round).

Everything else is copied byte for byte.
"""
from __future__ import annotations

import json
import os
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

from lever.fmus.model_description import START_VALUES_RESOURCE

from harness.description import typed_values
from harness.description.fmu_description import lever_annotations, read_description

#: the shim's configuration, which holds the GUID the FMU accepts (build/shim)
SHIM_CONFIG = "resources/lever_shim.cfg"


def can_carry_values(fmu: Path | str) -> bool:
    """Whether ``fmu`` takes configured start values (its annotation names the resource)."""
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
        names = set(z.namelist())
    declared = any(e.get("startValues") == f"resources/{START_VALUES_RESOURCE}" for e in lever_annotations(root))
    return declared and SHIM_CONFIG in names


def configured_guid(guid: str, values: dict[str, Any]) -> str:
    """The GUID of ``guid``'s FMU configured with ``values``."""
    try:
        namespace = uuid.UUID(guid.strip("{}"))
    except ValueError:      # an FMI 3.0 token need not be a UUID: one of its own text
        namespace = uuid.uuid5(uuid.NAMESPACE_OID, guid)
    return str(uuid.uuid5(namespace, json.dumps(values, sort_keys=True)))


def configure(fmu: Path | str, values: dict[str, Any], dest: Path | str) -> Path:
    """Write ``fmu`` configured to start at ``values`` ({variable: value in the variable's
    unit}, parameters and inputs) to ``dest``; return ``dest``.  A ``ValueError`` names a
    value that is not one of the FMU's parameters or inputs, or does not fit its type."""
    fmu, dest = Path(fmu), Path(dest)
    if not can_carry_values(fmu):
        raise ValueError(f"{fmu.name} does not take configured start values (no lever-cosim annotation naming "
                         f"resources/{START_VALUES_RESOURCE})")
    variables = {v.name: v for v in read_description(fmu).modelVariables}
    texts, typed = {}, {}
    for name, value in values.items():
        var = variables.get(name)
        if var is None or var.causality not in ("parameter", "input"):
            raise ValueError(f"{fmu.name}: '{name}' is no parameter or input; only those take start values")
        kind, text = typed_values.literal(var, value, name)
        texts[name], typed[name] = text, typed_values.parse_literal(kind, text)
    member = f"resources/{START_VALUES_RESOURCE}"
    with zipfile.ZipFile(fmu) as src:
        if member in src.namelist():       # configured before: its values and these
            typed = {**json.loads(src.read(member)), **typed}
        root = ET.fromstring(src.read("modelDescription.xml"))
        fmi3 = root.get("fmiVersion", "").startswith("3")
        token = "instantiationToken" if fmi3 else "guid"
        guid = configured_guid(root.get(token), typed)
        root.set(token, guid)
        _set_starts(root, texts, fmi3)
        config = "".join(f"guid={guid}\n" if line.startswith("guid=") else line
                         for line in src.read(SHIM_CONFIG).decode("utf-8").splitlines(keepends=True))
        replaced = {"modelDescription.xml": ET.tostring(root, encoding="utf-8", xml_declaration=True),
                    SHIM_CONFIG: config.encode("utf-8")}
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=dest.name + ".", suffix=".tmp", dir=dest.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        try:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
                for info in src.infolist():
                    if info.filename != member:
                        out.writestr(info, replaced.get(info.filename) or src.read(info))
                resource = zipfile.ZipInfo(member, date_time=info.date_time)
                resource.compress_type = zipfile.ZIP_DEFLATED
                resource.external_attr = 0o644 << 16
                out.writestr(resource, json.dumps(typed, indent=1, sort_keys=True) + "\n")
            os.replace(tmp, dest)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    return dest


def _set_starts(root: ET.Element, texts: dict[str, str], fmi3: bool) -> None:
    variables = root.find("ModelVariables")
    for element in variables:
        text = texts.get(element.get("name"))
        if text is None:
            continue
        if not fmi3:                       # <ScalarVariable><Real start=.../></ScalarVariable>
            element[0].set("start", text)
        elif element.tag == "String":      # FMI 3.0: <String><Start value=.../></String>
            for start in element.findall("Start"):
                element.remove(start)
            ET.SubElement(element, "Start", {"value": text})
        else:
            element.set("start", text)
