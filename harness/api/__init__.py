"""The harness from Python: run a scene, validate a result, bench the masters.

What ``lever run``, ``lever validate`` and ``lever bench`` do, as functions that return
their results instead of printing them (the command line calls these)::

    from harness import api

    api.scenes()                         # the committed scenes: name -> description
    run = api.run("kavz685", {"coupling.stiffness": 900}, stop="3 s")
    run                                  # Run(kavz685, master ..., ok, ...): one screen
    run.array(["coupling.tau2"])         # numpy structured array, 'time' first, as fmpy's
    run.summary["statistics"]["coupling.tau2"]   # mean and amplitude after the transient
    api.validate("kavz685", result=run, window=("0 s", "3 s")).passed

Signals are named as the traces name them, ``component.variable`` (``coupling.tau2``),
everywhere: traces, arrays, summary statistics, validation; a short name is taken where
only one signal ends with it (``tau2``).  Times take units as scene overrides do
(``step="1 ms"``), numbers may be numpy scalars.  A dict of overrides keeps its values'
types: a number (a numpy scalar too) is a number, a string is text - a quantity where it
carries its unit (``"20 deg"``), refused for a numeric parameter where it does not
(``"900"``), as in a scene file - and a boolean is no number.  Bad input (an unknown scene,
parameter or master, a value out of its range, an argument of the wrong type) raises
``InputError`` naming the argument as the call wrote it (``rtol='x'``,
``overrides['coupling.stiffness']``; the command line names its options); nothing is
written unless an output folder is given (``out=``).  Notes the command line prints
before a run (the stability advisor, a shortened run's transient, unconnected inputs) go
to ``notify`` (default: Python's ``warnings``, shown at the caller's line) and are kept in
``Run.notes``.
"""
from __future__ import annotations

# the api's parts, one job each: reading the arguments (inputs), the result types (results),
# building the FMUs (building), the cache (caching), the scenes and masters to choose from (choices), a run
# (running), validation (validating), the studies, the exports and the checks
from harness.api.building import NO_COMPILER, BuildError, build, fmu_path
from harness.api.caching import cache
from harness.api.checks import bad_inputs, compliance
from harness.api.choices import check_masters, load, masters, scenes, scenes_list
from harness.api.exports import export
from harness.api.inputs import InputError, Signals, UnknownSignal, parse_window
from harness.api.results import UNTRUSTED, BenchResult, ReferenceCheck, Run, Validation
from harness.api.running import RunNote, run
from harness.api.studies import (StudyInterrupted, bench, engines, fingerprints, hosts, measured, stability_map,
                                 study, sweep, sweep_verdict)
from harness.api.validating import (VERDICTS, fmu_file_model, fmu_start_values, reference_names, references,
                                    validate, validate_each)

__all__ = ["InputError", "UnknownSignal", "BuildError", "StudyInterrupted", "RunNote", "Run", "Validation",
           "BenchResult", "ReferenceCheck", "Signals", "build", "fmu_path", "scenes", "masters", "load", "run",
           "validate",
           "validate_each", "bench", "stability_map", "sweep", "study", "measured", "engines", "hosts", "export",
           "compliance", "references", "fingerprints", "bad_inputs", "scenes_list", "cache"]


def __dir__():
    """``dir(api)``: the public names, not the modules it uses."""
    return sorted(__all__)
