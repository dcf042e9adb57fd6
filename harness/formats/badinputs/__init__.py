"""The bad-input corpus: values and call sequences an importer may throw at our FMUs,
kept as data (a table of cases) and run through the FMI interface of the built FMUs
with fmpy's ``FMU2Slave`` (``lever badinputs``, ``tests/fmus/test_badinputs.py``), and the
Model Exchange interface with its ``FMU2Model``: every Model Exchange function in a state the
standard's table does not allow and on a Co-Simulation instance, the Co-Simulation functions
on a Model Exchange instance, arrays of the wrong size or NULL for every function that takes
one, non-finite states and times, directional derivatives of references that are no known or
unknown; what fmpy's wrappers would not pass (a NULL array, a size other than the model's,
a Co-Simulation function on a Model Exchange instance) is called through ctypes on the same
instance.  Besides fmi2Error and the message, such a case checks that no Real and no state
changed and that a legal round of calls (on to continuous-time mode, fmi2SetTime,
fmi2SetContinuousStates, fmi2GetDerivatives, fmi2GetEventIndicators, the outputs finite,
fmi2CompletedIntegratorStep) works afterwards.

Every case must end the same way: the offending call returns fmi2Error (or fmi2Discard),
the FMU logs a message that names the variable (or the call) and what is allowed, a
refused call changes no variable (every Real is read before and after it), the instance
stays usable where FMI lets it, nothing is ever fatal, and the instance is freed cleanly.

Besides bad values: fmi2Set* on outputs, after fmi2Terminate, with the wrong type or an
unknown value reference, a multi-value call with one bad value (nothing of it applied),
serialized states damaged every way ``STATE_EDITS`` lists (header, length, format,
model, GUID, nesting, content, a native header that disagrees with the model's part),
communication points off by more than rounding, and steps too costly to take (a huge step,
a tiny ``max_substep``).  The importing process - the one running
the corpus - survives all of it.

The FMI 3.0 editions (build/fmus3) get cases of their own (``fmi3.cases``, run with fmpy's
``FMU3Slave``/``FMU3Model``, every call under test through ctypes): the FMI 3.0 state machine
(every Model Exchange function in each state the standard's table does not allow, the
Co-Simulation ones out of order, each interface's functions on the other's instance),
value counts (``nValues``) that differ from the value references, NULL arrays, unknown
value references, ``time`` and event indicators set, types the FMUs have no variable of,
Model Exchange arrays of another size than the model's, NaN and infinity (inputs,
parameters, step sizes and communication points, start time, fmi3SetTime, states), and
serialized states with the FMI 3 header damaged (``STATE3_EDITS``) or the FMI 2 entry's part
inside it damaged as ``STATE_EDITS`` says.  Each must return fmi3Error (never Discard or
Fatal) with a message in FMI 3.0 terms that names the call and what is wrong, change no
Float64 and no state, and leave the instance usable: a step, or a continuous-time round,
after fmi3Reset where it was terminated.

Cases for the declared parameters and inputs are generated from the adapters of every
FMU of ``lever.fmus.registry`` (every real: NaN, +inf, -inf and the nearest values
outside its range; every fixed parameter: a change after initialisation), the rest are
written out by hand.

One module per interface: ``co_simulation`` (FMI 2.0 Co-Simulation), ``model_exchange``
(FMI 2.0 Model Exchange), ``fmi3`` (the FMI 3.0 editions); ``common`` holds the case, its
outcome and the message log they share.
"""
from __future__ import annotations

from pathlib import Path

from harness.formats.badinputs import co_simulation, common, fmi3, model_exchange
from harness.formats.badinputs.common import DECLARED, REFUSED, Case, Outcome
from harness.paths import FMUS

__all__ = ["Case", "Outcome", "DECLARED", "REFUSED", "co_simulation", "common", "corpus", "fmi3", "model_exchange",
           "run", "run_case", "summary"]


def corpus() -> list[Case]:
    return co_simulation.cases() + model_exchange.cases() + fmi3.cases()


def run_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
    if case.action[:2] == ("call", "fmi3"):
        return fmi3.run_case(case, fmu_dir)
    if case.action[:2] == ("call", "me"):
        return model_exchange.run_case(case, fmu_dir)
    return co_simulation.run_case(case, fmu_dir)


def run(fmu_dir: Path = FMUS, cases: list[Case] | None = None) -> list[Outcome]:
    return [run_case(case, fmu_dir) for case in (corpus() if cases is None else cases)]


def summary(outcomes: list[Outcome]) -> str:
    """Counts by FMU and category, and every failed case."""
    passed = sum(o.passed for o in outcomes)
    count = {kind: sum(o.case.interface == kind for o in outcomes)
             for kind in ("CoSimulation", "ModelExchange", "CoSimulation3", "ModelExchange3")}
    fmi3 = count["CoSimulation3"] + count["ModelExchange3"]
    if fmi3 or count["ModelExchange"]:
        through = (f"fmpy's FMU2Slave ({count['CoSimulation']}) and FMU2Model ({count['ModelExchange']}, Model "
                   f"Exchange)")
        if fmi3:
            through += (f", and for the FMI 3.0 editions FMU3Slave ({count['CoSimulation3']}) and FMU3Model "
                        f"({count['ModelExchange3']})")
    else:
        through = "fmpy's FMU2Slave"
    lines = [f"bad-input corpus: {len(outcomes)} cases through {through}, {passed} pass, "
             f"{len(outcomes) - passed} fail"]
    if fmi3:
        lines.append(f"  FMI 3.0 cases: {fmi3} (the corpus {len(outcomes) - fmi3} -> {len(outcomes)} cases with them), "
                     f"{sum(o.passed for o in outcomes if o.case.interface.endswith('3'))} pass")
    table: dict[tuple[str, str], list[int]] = {}
    for o in outcomes:
        cell = table.setdefault((o.case.category, o.case.fmu), [0, 0])
        cell[0] += 1
        cell[1] += o.passed
    fmus = list(dict.fromkeys([*DECLARED, *(o.case.fmu for o in outcomes)]))
    width = max(15, *(len(f) + 2 for f in fmus))
    lines.append(f"  {'category':34s}" + "".join(f"{f:>{width}s}" for f in fmus))
    for category in dict.fromkeys(c for c, _ in table):
        cells = [table.get((category, f)) for f in fmus]
        lines.append(f"  {category:34s}" + "".join(f"{'-' if c is None else f'{c[1]}/{c[0]}':>{width}s}" for c in cells))
    for o in outcomes:
        if not o.passed:
            lines.append(f"FAIL {o.case.name}: " + "; ".join(o.problems))
    return "\n".join(lines)

