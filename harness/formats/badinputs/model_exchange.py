"""The FMI 2.0 Model Exchange cases: every Model Exchange call and the standard's state
machine, run through fmpy's ``FMU2Model`` (ctypes where its wrappers would not pass a call)."""
from __future__ import annotations

import math
from pathlib import Path

from harness.formats.badinputs.common import (free_instance, judge_after_refusal, judge_log, DECLARED, FMI2_ERROR, FMI2_OK,
                                              FMI2_WARNING, LOG, Case, Outcome, c_array, instance_numbers,
                                              listen, model_description, settle, status_of)
from harness.formats.badinputs.co_simulation import Slave
from harness.paths import FMUS


# -- Model Exchange: the calls and the state machine ------------------------------------------------------

#: the Model Exchange phases a case starts from: ``event`` after fmi2ExitInitializationMode,
#: ``continuous`` after the event iteration and fmi2EnterContinuousTimeMode, ``terminated``
#: after fmi2Terminate from there
ME_PHASES = ("instantiated", "initialization", "event", "continuous", "terminated")
#: the native entry's own value references (lever.fmus.me_channel.CHANNEL)
CHANNEL = 0x40000000
#: the Model Exchange functions that take an array of the states' or indicators' size
ME_ARRAYS = {"fmi2GetDerivatives": "nx", "fmi2GetContinuousStates": "nx", "fmi2SetContinuousStates": "nx",
             "fmi2GetEventIndicators": "nz", "fmi2GetNominalsOfContinuousStates": "nx"}
#: every Model Exchange function of FMI 2.0 (besides those common to both interfaces)
ME_FUNCTIONS = ("fmi2EnterEventMode", "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode",
                "fmi2CompletedIntegratorStep", "fmi2SetTime", *ME_ARRAYS)
#: the sizes of each FMU's Model Exchange interface (its model description says them:
#: ``test_model_exchange.py`` checks them there)
ME_SIZES = {"LeverCoupling": (0, 0), "EngineShaft": (4, 1), "LoadShaft": (3, 1), "FreewheelRectifier": (11, 8),
            "MisalignmentSource": (0, 0)}


def _me(fmu, category, label, phase, what, expect, *args) -> Case:
    return Case(fmu, category, label, phase, ("call", "me", (what, *args)), expect, interface="ModelExchange")


def cases() -> list[Case]:
    cases = []
    for fmu in DECLARED:
        nx, nz = ME_SIZES[fmu]
        parameters, inputs = DECLARED[fmu]
        order = "out-of-order ME call"
        # each Model Exchange function in a state the standard's table does not allow it in
        wrong_states = [
            ("fmi2GetDerivatives", "instantiated"), ("fmi2GetDerivatives", "initialization"),
            ("fmi2SetContinuousStates", "initialization"), ("fmi2SetContinuousStates", "event"),
            ("fmi2SetContinuousStates", "terminated"),
            ("fmi2NewDiscreteStates", "continuous"), ("fmi2NewDiscreteStates", "initialization"),
            ("fmi2EnterContinuousTimeMode", "continuous"), ("fmi2EnterContinuousTimeMode", "initialization"),
            ("fmi2EnterEventMode", "instantiated"), ("fmi2EnterEventMode", "initialization"),
            ("fmi2EnterEventMode", "terminated"),
            ("fmi2CompletedIntegratorStep", "event"), ("fmi2CompletedIntegratorStep", "initialization"),
            ("fmi2SetTime", "instantiated"), ("fmi2SetTime", "initialization"), ("fmi2SetTime", "terminated"),
            ("fmi2GetEventIndicators", "instantiated"), ("fmi2GetContinuousStates", "instantiated"),
            ("fmi2GetNominalsOfContinuousStates", "initialization"),
            ("fmi2GetDirectionalDerivative", "instantiated"),
            ("fmi2ExitInitializationMode", "continuous"), ("fmi2EnterInitializationMode", "event"),
            ("fmi2SetupExperiment", "continuous"),
        ]
        for function, phase in wrong_states:
            cases.append(_me(fmu, order, f"{function} in {phase} (Model Exchange)", phase, function,
                             (function, "not allowed in state")))
        # the Co-Simulation functions on a Model Exchange instance
        for function in ("fmi2DoStep", "fmi2GetFMUstate", "fmi2GetRealStatus", "fmi2SetRealInputDerivatives"):
            why = "FMU state functions" if "FMUstate" in function else "a Co-Simulation function"
            cases.append(_me(fmu, order, f"{function} on a Model Exchange instance", "continuous", function,
                             (function, "Model Exchange interface", why)))
        # the Model Exchange functions on a Co-Simulation instance
        for function in ME_FUNCTIONS:
            cases.append(Case(fmu, order, f"{function} on a Co-Simulation instance", "stepping",
                              ("call", "me", (function,)), (function, "Model Exchange function", "fmi2CoSimulation"),
                              interface="CoSimulation"))
        # arrays of another size than the model's, and NULL arrays
        for function, size in ME_ARRAYS.items():
            n = nx if size == "nx" else nz
            what = "states" if function.endswith("States") and "Nominals" not in function else {
                "fmi2GetDerivatives": "derivatives", "fmi2GetEventIndicators": "event indicators",
                "fmi2GetNominalsOfContinuousStates": "nominals"}[function]
            for delta in ((1, -1) if n else (1,)):
                cases.append(_me(fmu, "wrong ME size", f"{function} with {n + delta} {what} ({n} declared)",
                                 "continuous", function, (function, f"{n + delta} {what} given", f"has {n}"),
                                 "size", n + delta))
            if n:
                cases.append(_me(fmu, "wrong ME size", f"{function} with a NULL array", "continuous", function,
                                 (function, "NULL"), "null", n))
        cases.append(_me(fmu, "wrong ME size", "fmi2NewDiscreteStates with a NULL fmi2EventInfo", "event",
                         "fmi2NewDiscreteStates", ("fmi2NewDiscreteStates", "NULL"), "null"))
        cases.append(_me(fmu, "wrong ME size", "fmi2CompletedIntegratorStep with NULL flags", "continuous",
                         "fmi2CompletedIntegratorStep", ("fmi2CompletedIntegratorStep", "NULL"), "null"))
        # states and times that are not finite
        for k, value in ((0, math.nan), (nx - 1, math.inf), (nx // 2, -math.inf)) if nx else ():
            cases.append(_me(fmu, "non-finite ME state", f"fmi2SetContinuousStates with x[{k}] = {value}",
                             "continuous", "fmi2SetContinuousStates", ("fmi2SetContinuousStates", f"x[{k}]",
                                                                       "not finite"), "value", k, value))
        for value in (math.nan, math.inf, -math.inf):
            cases.append(_me(fmu, "non-finite ME state", f"fmi2SetTime({value})", "continuous", "fmi2SetTime",
                             ("fmi2SetTime", "not finite"), "value", 0, value))
        # directional derivatives with references that are no known or unknown
        unknown = ("fmi2GetDirectionalDerivative", "value reference")
        for label, kind in (("an unknown value reference as the known", "known-unknown"),
                            ("an unknown value reference as the unknown", "unknown-unknown"),
                            ("a native entry's reference as the known", "known-channel"),
                            ("an output as the known", "known-output")):
            cases.append(_me(fmu, "bad directional derivative", f"fmi2GetDirectionalDerivative with {label}",
                             "continuous", "fmi2GetDirectionalDerivative", unknown, kind))
        if inputs:
            cases += [
                _me(fmu, "bad directional derivative", "fmi2GetDirectionalDerivative with an input as the unknown",
                    "continuous", "fmi2GetDirectionalDerivative", unknown, "unknown-input"),
                _me(fmu, "bad directional derivative", "fmi2GetDirectionalDerivative with a NaN seed",
                    "continuous", "fmi2GetDirectionalDerivative", ("fmi2GetDirectionalDerivative", "not finite"),
                    "nan-seed"),
            ]
        # the native entry's channel is not the host's
        cases += [
            _me(fmu, "bad directional derivative", "fmi2GetReal of a native entry's reference", "continuous",
                "fmi2GetReal", ("fmi2GetReal", "value reference", "no variable"), "channel"),
            _me(fmu, "bad directional derivative", "fmi2SetReal of a native entry's reference", "continuous",
                "fmi2SetReal", ("fmi2SetReal", "value reference", "no variable"), "channel"),
        ]
    return cases





class _Model:
    """One instance of a built FMU for a Model Exchange case: fmpy's ``FMU2Model`` (or
    ``FMU2Slave`` for the Model Exchange calls on a Co-Simulation instance), its own log."""

    def __init__(self, fmu: str, fmu_dir: Path, interface: str):
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from harness.engine.component import log_callbacks
        from harness.engine.component import unzipped as extracted

        path = Path(fmu_dir) / f"{fmu}.fmu"
        self.md, unzipped = model_description(path), extracted(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.nx, self.nz = self.md.numberOfContinuousStates, self.md.numberOfEventIndicators
        self.me = interface == "ModelExchange"
        self.instance = f"corpus-me-{fmu}-{next(instance_numbers)}"
        self.log = LOG.setdefault(self.instance, [])
        kind = FMU2Model if self.me else FMU2Slave
        identifier = (self.md.modelExchange if self.me else self.md.coSimulation).modelIdentifier
        self.fmu = kind(guid=self.md.guid, unzipDirectory=unzipped, modelIdentifier=identifier,
                        instanceName=self.instance)
        self.fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
        self.phase = "instantiated"
        self.time = 0.0

    def call(self, function: str, *args) -> int:
        return status_of(self.fmu, function, *args)

    def raw(self, function: str, argtypes, *args) -> int:
        """A function called straight from the library (one fmpy does not wrap for this
        interface, or with arguments its wrapper would not pass)."""
        import ctypes
        entry = getattr(self.fmu.dll, function)
        entry.argtypes, entry.restype = [ctypes.c_void_p, *argtypes], ctypes.c_int
        return entry(self.fmu.component, *args)

    def advance(self, phase: str) -> int:
        worst = FMI2_OK
        if not self.me:
            return Slave.advance(self, phase)     # Co-Simulation: as the other cases
        steps = ME_PHASES.index(phase)
        if steps >= 1:
            worst = max(worst, self.call("setupExperiment", None, 0.0, None), self.call("enterInitializationMode"))
        if steps >= 2:
            worst = max(worst, self.call("exitInitializationMode"))
        if steps >= 3:
            worst = max(worst, self._event_iteration(), self.call("enterContinuousTimeMode"))
        if steps >= 4:
            worst = max(worst, self.call("terminate"))
        self.phase = phase
        return worst

    def _event_iteration(self) -> int:
        return settle(self.fmu.newDiscreteStates)

    def states(self) -> list | None:
        if not self.me or self.phase == "instantiated" or not self.nx:
            return None
        x = c_array(self.nx)
        return list(x)[: self.nx] if self.call("getContinuousStates", x, self.nx) <= FMI2_WARNING else None

    def reals(self) -> dict:
        names = [n for n, v in self.variables.items() if v.type == "Real"]
        return dict(zip(names, self.fmu.getReal([self.variables[n].valueReference for n in names])))

    def usable(self) -> str | None:
        """A legal round from the case's phase on: on to continuous-time mode, a step of
        continuous-time calls (Co-Simulation: a step); None when it works, else why not."""
        if not self.me:
            return None if Slave.step_ok(self) else f"the instance did not step on: {self.log[-1:]}"
        if self.phase == "terminated":
            dx = c_array(self.nx)
            ok = self.call("getDerivatives", dx, self.nx) <= FMI2_WARNING
            return None if ok else f"fmi2GetDerivatives after fmi2Terminate failed: {self.log[-1:]}"
        rest = ME_PHASES[ME_PHASES.index(self.phase) + 1: ME_PHASES.index("continuous") + 1]
        for phase in rest:
            status = {"initialization": lambda: max(self.call("setupExperiment", None, 0.0, None),
                                                    self.call("enterInitializationMode")),
                      "event": lambda: self.call("exitInitializationMode"),
                      "continuous": lambda: max(self._event_iteration(), self.call("enterContinuousTimeMode"))}[phase]()
            if status > FMI2_WARNING:
                return f"going on to {phase} failed: {self.log[-1:]}"
        x, dx, z = c_array(self.nx), c_array(self.nx), c_array(self.nz)
        statuses = [self.call("setTime", 1e-3), self.call("getContinuousStates", x, self.nx),
                    self.call("setContinuousStates", x, self.nx), self.call("getDerivatives", dx, self.nx),
                    self.call("getEventIndicators", z, self.nz)]
        outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output"]
        values = self.fmu.getReal(outputs)
        if max(statuses) > FMI2_WARNING or not all(math.isfinite(v) for v in list(dx)[: self.nx] + values):
            return f"a continuous-time round after the refusal failed: {self.log[-1:]}"
        if self.fmu.completedIntegratorStep() != (False, False):
            return "fmi2CompletedIntegratorStep asked for an event or the end"
        return None

    def free(self) -> list[str]:
        if not self.me or self.phase in ("event", "continuous"):
            self.call("terminate")
        return free_instance(self.fmu)


def _act_me(model: _Model, case: Case) -> int:
    import ctypes

    function, *args = case.action[2]
    kind = args[0] if args else None
    dbl, size_t, ptr = ctypes.c_double, ctypes.c_size_t, ctypes.c_void_p
    n = {"nx": model.nx, "nz": model.nz}
    if function in ME_ARRAYS:
        count = args[1] if kind in ("size", "null") else n[ME_ARRAYS[function]]
        array = None if kind == "null" else c_array(max(count, n[ME_ARRAYS[function]]))
        if kind == "value":
            model.call("getContinuousStates", array, model.nx)
            array[args[1]] = args[2]
        return model.raw(function, [ptr, size_t], array, count)
    if function == "fmi2SetTime":
        return model.raw(function, [dbl], args[2] if kind == "value" else 0.5)
    if function == "fmi2NewDiscreteStates":
        from fmpy.fmi2 import fmi2EventInfo
        return model.raw(function, [ptr], None if kind == "null" else ctypes.byref(fmi2EventInfo()))
    if function == "fmi2CompletedIntegratorStep":
        flag = ctypes.c_int()
        return model.raw(function, [ctypes.c_int, ptr, ptr], 1, None if kind == "null" else ctypes.byref(flag),
                         None if kind == "null" else ctypes.byref(flag))
    if function in ("fmi2EnterEventMode", "fmi2EnterContinuousTimeMode", "fmi2ExitInitializationMode",
                    "fmi2EnterInitializationMode"):
        return model.raw(function, [])
    if function == "fmi2SetupExperiment":
        return model.raw(function, [ctypes.c_int, dbl, dbl, ctypes.c_int, dbl], 0, 0.0, 0.0, 0, 0.0)
    if function == "fmi2DoStep":
        return model.raw(function, [dbl, dbl, ctypes.c_int], model.time, 1e-3, 1)
    if function == "fmi2GetFMUstate":
        return model.raw(function, [ptr], ctypes.byref(ctypes.c_void_p()))
    if function == "fmi2GetRealStatus":
        return model.raw(function, [ctypes.c_int, ptr], 2, ctypes.byref(dbl()))
    if function == "fmi2SetRealInputDerivatives":
        vr, order, value = (ctypes.c_uint * 1)(0), (ctypes.c_int * 1)(1), (dbl * 1)(0.0)
        return model.raw(function, [ptr, size_t, ptr, ptr], vr, 1, order, value)
    if function in ("fmi2GetReal", "fmi2SetReal"):
        vr, value = (ctypes.c_uint * 1)(CHANNEL + (1 << 20)), (dbl * 1)(0.0)
        return model.raw(function, [ptr, size_t, ptr], vr, 1, value)
    if function == "fmi2GetDirectionalDerivative":
        variables = model.md.modelVariables
        outputs = [v.valueReference for v in variables if v.causality == "output"]
        inputs = [v.valueReference for v in variables if v.causality == "input"]
        knowns = inputs + [u.variable.derivative.valueReference for u in model.md.derivatives]
        missing = max(v.valueReference for v in variables) + 1000
        unknown, known, seed = outputs[0], (knowns or [missing])[0], 1.0
        if kind == "known-unknown":
            known = missing
        elif kind == "unknown-unknown":
            unknown = missing
        elif kind == "known-channel":
            known = CHANNEL
        elif kind == "known-output":       # an output that is no state (a state is a known)
            states = {u.variable.derivative.valueReference for u in model.md.derivatives}
            known = next(vr for vr in outputs if vr not in states)
        elif kind == "unknown-input":
            unknown = inputs[0]
        elif kind == "nan-seed":
            seed = math.nan
        out = (dbl * 1)()
        return model.raw(function, [ptr, size_t, ptr, size_t, ptr, ptr], (ctypes.c_uint * 1)(unknown), 1,
                         (ctypes.c_uint * 1)(known), 1, (dbl * 1)(seed), out)
    raise ValueError(f"unknown Model Exchange action {function}")


def run_case(case: Case, fmu_dir: Path = FMUS) -> Outcome:
    listen()
    outcome = Outcome(case)
    model = _Model(case.fmu, fmu_dir, case.interface)
    try:
        if model.advance(case.phase) > FMI2_WARNING:
            outcome.problems.append(f"reaching phase {case.phase} failed: {model.log[-1:]}")
        everything, states = model.reals(), model.states()
        seen = len(model.log)
        status = _act_me(model, case)
        outcome.status = status
        logged = model.log[seen:]
        if status != FMI2_ERROR:
            outcome.problems.append(f"status {status}, expected fmi2Error")
        judge_log(outcome, logged, case)
        judge_after_refusal(outcome, model, everything, states)
    except Exception as error:  # noqa: BLE001 - a case that breaks the runner is a failed case
        outcome.problems.append(f"the importer saw an exception: {error!r}")
    finally:
        outcome.problems += model.free()
        LOG.pop(model.instance, None)
    return outcome


