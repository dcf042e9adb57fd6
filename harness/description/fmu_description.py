"""An FMU's model description as the harness reads it: fmpy's, with the time-derivative
relations the FMU declares (``time_derivatives``).

FMI's ``derivative`` attribute marks state derivatives: importers (FMIL, so OMSimulator and
PyFMI) count a continuous state for each variable that has one.  The other relations our
masters use - an input that is the rate of another input (a shaft's ``tau_rate`` of
``tau``), an output that is the rate of another output (``misalignment_rate``) - our FMUs
declare in their vendor annotation (docs/fmus.md, "Time derivatives").  A foreign FMU's
``derivative`` attributes still count, whatever they are on.
"""
from __future__ import annotations

import hashlib
import threading
import time
import weakref
import xml.etree.ElementTree as ET
from collections import OrderedDict
import zipfile
from pathlib import Path

from fmpy import read_model_description
from lever.fmus.model_description import ANNOTATION_TOOL

#: the relations of each description ``read_description`` read (fmpy's descriptions are
#: slotted attrs classes: nothing can be added to them)
_RELATIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


#: descriptions read, by the digest of their XML (the most recently used last): a run reads
#: each FMU's description several times (the plan, the component, its FMI edition), and a
#: sweep or a stability map makes hundreds of runs - the XML is read each time, parsed once
_PARSED: OrderedDict[bytes, object] = OrderedDict()
_PARSED_KEPT = 64
_PARSED_LOCK = threading.Lock()


#: the digest of the XML of each file read (by the file's path and identity: inode, size,
#: times), so that a file read before is not opened again; only for a file last changed
#: more than ``SETTLED`` seconds before it was read (as git trusts a racily clean index
#: entry): a file changed again within the file system's timestamp granularity may keep
#: its times
_DIGEST_OF_FILE: OrderedDict[tuple, bytes] = OrderedDict()
SETTLED = 2.0


def read_description(path: Path | str):
    """fmpy's model description of the FMU ``path`` (an ``.fmu``, an unpacked FMU's folder
    or its ``modelDescription.xml``), whose ``time_derivatives`` are those of the ``derivative``
    attributes and of our annotation.  The same XML gives the same object (shared: read it,
    never change it); an FMU rebuilt in place is read afresh."""
    path = Path(path)
    identity = _file_identity(path)
    with _PARSED_LOCK:
        key = _DIGEST_OF_FILE.get(identity) if identity is not None else None
        md = _PARSED.get(key) if key is not None else None
        if md is not None:
            _PARSED.move_to_end(key)
            return md
    xml = _description_xml(path)
    key = hashlib.sha256(xml).digest()
    with _PARSED_LOCK:
        md = _PARSED.get(key)
        if md is not None:
            _PARSED.move_to_end(key)
            _remember_file(identity, key)
            return md
    md = read_model_description(str(path))
    _RELATIONS[md] = {**_attributed(md), **annotated_time_derivatives(xml)}
    with _PARSED_LOCK:
        _PARSED[key] = md
        while len(_PARSED) > _PARSED_KEPT:
            _PARSED.popitem(last=False)
        _remember_file(identity, key)
    return md


def _file_identity(path: Path) -> tuple | None:
    """What tells the file holding ``path``'s description from any other or a changed one
    (None: not known, or changed too recently to tell)."""
    try:
        target = path / "modelDescription.xml" if path.is_dir() else path
        st = target.stat()
    except OSError:
        return None
    if not time.time() - max(st.st_mtime, st.st_ctime) > SETTLED:
        return None
    return (str(target.absolute()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _remember_file(identity: tuple | None, key: bytes):
    if identity is not None:
        _DIGEST_OF_FILE[identity] = key
        while len(_DIGEST_OF_FILE) > 4 * _PARSED_KEPT:
            _DIGEST_OF_FILE.popitem(last=False)


def time_derivatives(md) -> dict[str, str]:
    """{variable: the variable it is the time derivative of} of a description
    ``read_description`` read; of another (fmpy's own reader): its ``derivative``
    attributes."""
    relations = _RELATIONS.get(md)
    return dict(relations) if relations is not None else _attributed(md)


def _attributed(md) -> dict[str, str]:
    return {v.name: v.derivative.name for v in md.modelVariables if v.derivative is not None}


def annotated_time_derivatives(xml: bytes) -> dict[str, str]:
    """The relations of our annotation in the model description ``xml`` (FMI 2.0
    ``<VendorAnnotations><Tool>``, FMI 3.0 ``<Annotations><Annotation>``); {} without one."""
    root = ET.fromstring(xml)
    found = {}
    for element in lever_annotations(root):
        found.update({e.get("variable"): e.get("of") for e in element.iterfind("TimeDerivative")})
    return found


def lever_annotations(root: ET.Element) -> list[ET.Element]:
    """The ``<LeverFmu>`` elements of our annotation in the model description ``root`` (FMI
    2.0 or 3.0; none in a foreign FMU's)."""
    return (root.findall(f"VendorAnnotations/Tool[@name='{ANNOTATION_TOOL}']/LeverFmu")
            + root.findall(f"Annotations/Annotation[@type='{ANNOTATION_TOOL}']/LeverFmu"))


def _description_xml(path: Path) -> bytes:
    if path.is_dir():
        return (path / "modelDescription.xml").read_bytes()
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            return z.read("modelDescription.xml")
    return path.read_bytes()
