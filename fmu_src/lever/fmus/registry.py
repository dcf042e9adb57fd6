"""Our FMUs, each declared once: the build (build/fmus.py), the tests, the stand-alone
reference traces (``harness.formats.reference_traces``) and the bad-input corpus
(``harness.formats.badinputs``) take their list from ``MODELS``.

Adding an FMU: its adapter class (named as the FMU) in a module of this package, its line
here, and its stand-alone reference case in harness/formats/reference_traces.py, made with
``lever reference --update <name>`` (or here, the reason why it has none).

Standard library only, and no adapter imported when this module loads: the build reads
it from the sources by its path, before it stages the package.
"""
from __future__ import annotations

import importlib
from typing import NamedTuple


class FmuModel(NamedTuple):
    #: the model identifier: the FMU's file name and its adapter class's name
    name: str
    #: the module of ``lever.fmus`` that defines the adapter class
    module: str
    #: why the model has no stand-alone reference (resources/reference/<name>/, ``lever
    #: validate <name>``); empty: it has one (``harness.formats.reference_traces.FMU_CASES``)
    no_reference: str = ""

    def adapter(self) -> type:
        """The adapter class (imports pythonfmu)."""
        return getattr(importlib.import_module(f"lever.fmus.{self.module}"), self.name)


MODELS = (
    FmuModel("LeverCoupling", "coupling"),
    FmuModel("EngineShaft", "shafts"),
    FmuModel("LoadShaft", "shafts"),
    FmuModel("FreewheelRectifier", "freewheel", no_reference=(
        "it is driven by its own rocker (parameters) and its response has gap and stick/slip events "
        "that only the monolithic solver locates: its stand-alone reference is the scene "
        "freewheel_rectifier's (this FMU alone, its output shaft unloaded), `lever validate "
        "freewheel_rectifier`")),
    FmuModel("MisalignmentSource", "sources"),
)

#: the model identifiers, in the build's order
NAMES = tuple(m.name for m in MODELS)


def model(name: str) -> FmuModel:
    """The declaration of the FMU ``name`` (KeyError: no FMU of that name)."""
    for m in MODELS:
        if m.name == name:
            return m
    raise KeyError(f"no FMU named {name!r}; the FMUs are {', '.join(NAMES)}")
