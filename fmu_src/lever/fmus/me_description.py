"""The model description of an FMU that also runs as Model Exchange: the ModelExchange
element, the states' local variables and their units, the ModelStructure as the union of
the physics' dependencies over the model's structure cases, and the count of live event
indicators."""
from __future__ import annotations

from xml.etree.ElementTree import Element, SubElement

from ..physics.me_base import der
from ..physics.parameters import DISPLAY_UNITS
from .declarations import Output
from .model_description import camel_case, declared_type, define_unit

#: the Integer calculated parameter that says how many event indicators can change sign
#: with the parameters set (the first ones; the others stay positive): a host may leave the
#: rest out of its root finding, each of which costs an evaluation of the model
LIVE_EVENT_INDICATORS = "live_event_indicators"


class ModelExchangeDescription:
    """The model description's Model Exchange parts of a ``ModelExchangeSlave``
    (lever.fmus.model_exchange), whose states and physics they describe."""

    def _structure(self) -> dict:
        """{unknown variable: set of known variables} over ``ME_STRUCTURE_CASES`` (the FMU's
        names: outputs and state derivatives on inputs and states)."""
        saved = dict(self.__dict__)
        union: dict[str, set] = {}
        try:
            for case in self.ME_STRUCTURE_CASES:
                for p in self.PARAMETERS:
                    setattr(self, p.name, case.get(p.name, p.default))
                self._build()
                self._model_stale, self._build_error = False, None
                self._me_model = None
                model = self._me_physics()
                names = {s.physics: s.name for s in self.ME_STATES}
                unknown = {o: o for o in model.OUTPUTS}
                unknown.update({der(s.physics): s.derivative for s in self.ME_STATES})
                for of, wrt in model.dependencies.items():
                    union.setdefault(unknown[of], set()).update(names.get(w, w) for w in wrt)
        finally:
            self.__dict__.clear()
            self.__dict__.update(saved)
        for state in self.ME_STATES:     # an output that is a state is that state
            union.setdefault(state.name, {state.name})
        for name, wrt in self.ME_OUTPUT_DEPENDENCIES.items():
            union.setdefault(name, set()).update(wrt)
        missing = [o.name for o in self.OUTPUTS if o.name not in union]
        if missing:
            raise ValueError(f"{type(self).__name__}: the dependencies of output(s) {', '.join(missing)} are "
                             "not declared (ME_OUTPUT_DEPENDENCIES)")
        return union

    def to_xml(self, model_options=None) -> Element:
        root = super().to_xml(model_options)
        cs = root.find("CoSimulation")
        cs.set("providesDirectionalDerivative", "true")
        me = Element("ModelExchange", {
            "modelIdentifier": cs.get("modelIdentifier"), "needsExecutionTool": "false",
            "completedIntegratorStepNotNeeded": "true", "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "true", "canGetAndSetFMUstate": "false",
            "canSerializeFMUstate": "false", "providesDirectionalDerivative": "true"})
        root.insert(list(root).index(cs), me)
        root.set("numberOfEventIndicators", str(self.ME_EVENT_INDICATORS))

        nodes = root.find("ModelVariables").findall("ScalarVariable")
        index_of = {node.get("name"): i for i, node in enumerate(nodes, start=1)}
        units, types = root.find("UnitDefinitions"), root.find("TypeDefinitions")
        defined = {u.get("name") for u in units}
        typed_as = {t.get("name") for t in types}
        for s in self.ME_STATES:
            for name in (s.name, s.derivative):
                if self._vr_of[name] in self._me_locals:
                    spec = Output(name, s.unit if name == s.name else _rate_unit(s.unit), "")
                    type_name, element, attrs = declared_type(spec)
                    typed = nodes[index_of[name] - 1][0]
                    typed.set("declaredType", type_name)
                    typed.set("unit", spec.unit)
                    if spec.unit in DISPLAY_UNITS:
                        typed.set("displayUnit", DISPLAY_UNITS[spec.unit])
                    if spec.unit not in defined:
                        define_unit(units, spec.unit)
                        defined.add(spec.unit)
                    if type_name not in typed_as:
                        SubElement(SubElement(types, "SimpleType", {"name": type_name}), element, attrs)
                        typed_as.add(type_name)
            nodes[index_of[s.derivative] - 1][0].set("derivative", str(index_of[s.name]))

        structure = self._structure()
        inputs = set(self._input_names)

        def unknown(parent, name, only_inputs=False):
            sources = sorted((index_of[n] for n in structure.get(name, ()) if not only_inputs or n in inputs))
            attrs = {"index": str(index_of[name]), "dependencies": " ".join(map(str, sources))}
            if sources:
                attrs["dependenciesKind"] = " ".join("dependent" for _ in sources)
            SubElement(parent, "Unknown", attrs)

        model_structure = root.find("ModelStructure")
        for child in list(model_structure):
            model_structure.remove(child)
        outputs = SubElement(model_structure, "Outputs")
        for o in self.OUTPUTS:
            unknown(outputs, o.name)
        if self.ME_STATES:
            derivatives = SubElement(model_structure, "Derivatives")
            for s in self.ME_STATES:
                unknown(derivatives, s.derivative)
        # At initialisation the states are unknowns themselves (from the parameters): the
        # initial unknowns' knowns are the inputs.
        initial = SubElement(model_structure, "InitialUnknowns")
        names = {o.name for o in self.OUTPUTS} | {self.vars[vr].name for vr in self._me_locals}
        for name in sorted(names, key=index_of.get):
            unknown(initial, name, only_inputs=True)
        if self._live_vr is not None:
            type_name = camel_case(LIVE_EVENT_INDICATORS)
            nodes[index_of[LIVE_EVENT_INDICATORS] - 1][0].set("declaredType", type_name)
            SubElement(SubElement(types, "SimpleType", {"name": type_name}), "Integer",
                       {"quantity": type_name, "min": "0", "max": str(self.ME_EVENT_INDICATORS)})
            # a calculated parameter is an initial unknown; it depends on the parameters
            # (no dependencies attribute: on every known)
            SubElement(initial, "Unknown", {"index": str(index_of[LIVE_EVENT_INDICATORS])})
        return root


def _rate_unit(unit: str) -> str:
    return {"rad": "rad/s", "rad/s": "rad/s2", "J": "W", "N.m": "N.m/s"}.get(unit, "")
