"""What an FMU says about itself besides its model description, generated from the same
declarations the adapters make (``PARAMETERS``, ``INPUTS``, ``OUTPUTS``, ``EQUATIONS``,
``PORTS``), never written by hand:

* ``documentation_html``: the FMU's ``documentation/_main.html`` (FMI 2.0 section 2.2.8):
  equations, ports, sign conventions, inputs, outputs, parameter table, host requirements;
* ``osp_model_description``: ``<Model>_OspModelDescription.xml`` (OSP Interface
  Specification 1.0): each flange as an ``AngularMechanicalPort`` (torque and angular
  velocity, opposite causality: a power bond) and an ``AngularDisplacement``, so OSP tools
  connect flange to flange and libcosim's ECCO can form power bonds.
"""
from __future__ import annotations

import html
import math
from xml.etree.ElementTree import Element, SubElement, indent, tostring

from .. import physics
from .model_description import declared_type

OSP_NAMESPACE = "https://open-simulation-platform.com/OspModelDescription/1.0.0"


def _range(p) -> str:
    if p.kind == "string":
        return p.range_text()
    return p.range_text().replace("inf", "&infin;")


def _row(cells) -> str:
    return "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>"


def _table(head, rows) -> str:
    return ("<table>\n<tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>\n"
            + "\n".join(_row(r) for r in rows) + "\n</table>")


def _e(text) -> str:
    return html.escape(str(text), quote=False)


def _unit(spec) -> str:
    return "" if spec.unit in ("", "1") else _e(spec.unit)


def documentation_html(model, requirements: list[str]) -> str:
    """The FMU's documentation page for the slave class ``model``; ``requirements`` are
    the Python packages the importing interpreter needs (``resources/requirements.txt``)."""
    name = model.__name__
    inputs = {p.name: p for p in model.INPUTS}
    out_rows = []
    for o in model.OUTPUTS:
        depends = model.dependencies(o)
        out_rows.append([f"<code>{o.name}</code>", _unit(o), declared_type(o)[0], _e(o.description),
                         f"<code>{o.derivative_of}</code>" if o.derivative_of else "",
                         ", ".join(f"<code>{d}</code>" for d in depends) or "none (no direct feedthrough)"])
    in_rows = [[f"<code>{p.name}</code>", _unit(p), declared_type(p)[0], _e(p.description),
                f"<code>{p.derivative_of}</code>" if p.derivative_of else "", _e(_repr(p.default)), _range(p)]
               for p in inputs.values()]
    par_rows = [[f"<code>{p.name}</code>", p.kind, _unit(p), _e(_repr(p.default)), _range(p), _e(p.description)]
                for p in model.PARAMETERS]
    port_rows = [[f"<code>{port.name}</code>", f"<code>{port.torque}</code> ({_causality(model, port.torque)})",
                  f"<code>{port.angular_velocity}</code> ({_causality(model, port.angular_velocity)})",
                  f"<code>{port.angle}</code> ({_causality(model, port.angle)})", _e(port.description)]
                 for port in model.PORTS]
    experiment = model.default_experiment
    packages = ("on the standard library alone: no third-party package is needed "
                "(<code>resources/requirements.txt</code> lists none)" if not requirements else
                "with the Python packages listed below (also in <code>resources/requirements.txt</code>)")
    sections = [
        f"<h1>{name}</h1>",
        f"<p>{_e(model.DESCRIPTION)}</p>",
        "<p>FMI 2.0 FMU (co-simulation and model exchange) of the lever-cosim project (version "
        f"{_e(model.version)}, license {_e(model.license)}). Default experiment: {experiment.start_time} s to "
        f"{experiment.stop_time} s, communication step {experiment.step_size} s.</p>",
        "<h2>Equations</h2>",
        "<pre>" + "\n".join(_e(line) for line in model.EQUATIONS) + "</pre>",
        "<h2>Sign conventions</h2>",
        "<pre>" + _e((physics.__doc__ or "").strip()) + "</pre>",
        "<h2>Ports</h2>",
        "<p>Rotational flanges; the OSP model description next to the FMU "
        f"(<code>{name}_OspModelDescription.xml</code>) declares each as an <code>AngularMechanicalPort</code> "
        "(torque and angular velocity, a power bond) and an <code>AngularDisplacement</code>.</p>",
        _table(["flange", "torque", "angular velocity", "angle", "description"], port_rows),
        "<h2>Inputs</h2>",
        _table(["name", "unit", "type", "description", "derivative of", "start", "allowed range"], in_rows),
        "<h2>Outputs</h2>",
        _table(["name", "unit", "type", "description", "derivative of", "depends directly on"], out_rows),
        "<h2>Parameters</h2>",
        "<p>Fixed after initialisation. A value outside its range is refused with fmi2Error and a log message "
        "naming the parameter and its range; the instance stays usable.</p>",
        _table(["name", "kind", "unit", "default", "allowed range", "description"], par_rows),
        "<h2>Capabilities</h2>",
        "<ul><li>variable communication step size: yes</li>"
        "<li>get/set and serialise the FMU state: yes (the complete state; a restored state continues "
        "bit-identically)</li>"
        "<li>input derivatives: no (shafts take the torque's rate as the input <code>tau_rate</code>)</li>"
        "<li>several instances per process: yes</li>"
        "<li>model exchange: yes, the same file (get/set of the FMU state in co-simulation only)</li>"
        "<li>directional derivatives: yes, in both interfaces, from the model's analytic partials</li></ul>",
        "<h2>Host requirements</h2>",
        "<p>The model runs in Python inside the importer (pythonfmu 0.7; its Python part is in "
        f"<code>resources/pythonfmu</code>), {packages}. A Python host's own interpreter is used. In any "
        "other host the FMU's native entry finds a CPython 3.9+ shared library itself, in this order: "
        "<code>LEVER_FMU_LIBPYTHON</code> (the library's path; <code>LEVER_FMU_PYTHONHOME</code> for an "
        "unusual layout), the Python the FMU was built with (<code>resources/lever_shim.cfg</code>), a "
        "<code>python3</code> on <code>PATH</code>; it loads it with global symbols and sets the Python "
        "home to match, so neither <code>LD_PRELOAD</code> nor <code>PYTHONHOME</code> is needed. When "
        "none is usable, <code>fmi2Instantiate</code> returns NULL and logs what it tried.</p>",
        *(["<pre>" + "\n".join(_e(r) for r in requirements) + "</pre>"] if requirements else []),
    ]
    style = ("body{font-family:sans-serif;max-width:62em;margin:2em auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #bbb;padding:.2em .5em;vertical-align:top}th{background:#eee}")
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head><meta charset=\"utf-8\"><title>" + name
            + "</title><style>" + style + "</style></head>\n<body>\n" + "\n".join(sections) + "\n</body>\n</html>\n")


def _repr(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    return repr(value) if isinstance(value, str) else str(value)


def _causality(model, variable: str) -> str:
    if any(p.name == variable for p in model.INPUTS):
        return "input"
    if any(o.name == variable for o in model.OUTPUTS):
        return "output"
    raise ValueError(f"{model.__name__}: port variable '{variable}' is neither an input nor an output")


def osp_model_description(model) -> str:
    """``<Model>_OspModelDescription.xml`` for the slave class ``model``."""
    root = Element("OspModelDescription", {"xmlns": OSP_NAMESPACE, "version": "1.0"})
    groups = SubElement(root, "VariableGroups")
    # OSP-IS orders the groups by kind: displacements before ports.
    for port in model.PORTS:
        _causality(model, port.angle)
        SubElement(SubElement(groups, "AngularDisplacement", {"name": f"{port.name}_angle"}), "Variable",
                   {"ref": port.angle})
    for port in model.PORTS:
        torque, speed = _causality(model, port.torque), _causality(model, port.angular_velocity)
        if torque == speed:
            raise ValueError(f"{model.__name__}.{port.name}: torque and angular velocity must have opposite "
                             f"causality (both are {torque}s)")
        bond = SubElement(groups, "AngularMechanicalPort", {"name": port.name})
        SubElement(SubElement(bond, "Torque", {"name": f"{port.name}_torque"}), "Variable", {"ref": port.torque})
        SubElement(SubElement(bond, "AngularVelocity", {"name": f"{port.name}_angular_velocity"}), "Variable",
                   {"ref": port.angular_velocity})
    indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + tostring(root, encoding="unicode") + "\n"
