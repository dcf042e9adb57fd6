"""FMI 3.0 Co-Simulation FMUs as components, and the choice between the editions.

``open_component`` reads the FMU's model description and makes the component its
``fmiVersion`` calls for: a ``Component`` (FMI 2.0, fmpy's ``FMU2Slave``) or a
``Component3`` (FMI 3.0, fmpy's ``FMU3Slave``).  Masters and the system see the same
interface (``harness.engine.interface.CoSimComponent``): ``Component3`` offers the raw
calls with FMI 2.0's signatures, translated to fmi3GetFloat64/fmi3SetFloat64 (which take
the number of values once more) and fmi3DoStep (whose out-arguments are checked after
every step), and names every refused call by its FMI 3.0 name.

An instance is made with Event Mode and early return off, as lever's masters offer
neither: a step that asks for Event Mode, ends the simulation or returns early ends the
run with an error saying so (``StepRequest``), never a silently short or skipped step.
"""
from __future__ import annotations

import ctypes
import itertools
from pathlib import Path

from fmpy.fmi3 import FMU3Slave, fmi3IntermediateUpdateCallback, fmi3LogMessageCallback

from harness.description import typed_values
from harness.description.fmu_description import read_description
from harness.engine import component as fmi2
from harness.engine.component import (INITIALIZATION, STEPPING, Component, FmuCallError, FmuUnusable,
                                     library_problem, step_call)
from harness.engine.interface import RawCalls

#: the FMI 2.0 names the system and the masters give the calls they make -> FMI 3.0's
FMI3_NAMES = {"fmi2GetReal": "fmi3GetFloat64", "fmi2SetReal": "fmi3SetFloat64", "fmi2DoStep": "fmi3DoStep",
              "fmi2GetFMUstate": "fmi3GetFMUState", "fmi2SetFMUstate": "fmi3SetFMUState",
              "fmi2FreeFMUstate": "fmi3FreeFMUState"}

# FMI 3.0's log callback has no variadic arguments and no instance name, only the
# instance environment the importer gave: each instance gets a number as its environment,
# and one callback for the process routes by it to what routes FMI 2.0 messages.
_environments: dict[int, str] = {}
_numbers = itertools.count(1)


def _log(environment, status, category, message):
    name = _environments.get(environment or 0, "")
    fmi2.dispatch_message(name, status, category, message)


# module globals: alive as long as the process, as the FMUs' pointers to them must be
_log_callback = fmi3LogMessageCallback(_log)
_no_intermediate_update = fmi3IntermediateUpdateCallback()


class UnsupportedFmu(ValueError):
    """An FMU the co-simulation masters cannot run (no Co-Simulation interface, FMI 1.0)."""


class StepRequest(FmuCallError):
    """fmi3DoStep returned OK or Warning but asked for what lever's masters do not do:
    Event Mode (``eventHandlingNeeded``), the end of the simulation
    (``terminateSimulation``) or a step cut short (``earlyReturn``, not allowed at
    instantiation)."""

    def __init__(self, component: str, call: str, status: int, time: float, request: str, last_time: float):
        self.component, self.call, self.status, self.time = component, call, status, time
        self.messages, self.request, self.last_successful_time = [], request, last_time
        RuntimeError.__init__(self, f"{component}: {call} set {request} at t = {time:.6g} s "
                                    f"(lastSuccessfulTime = {last_time:.9g} s): {_REQUESTS[request]}")


_REQUESTS = {
    "terminateSimulation": "the FMU ends the simulation, so the run ends here",
    "eventHandlingNeeded": "the FMU asks for Event Mode, which lever's co-simulation masters do not use "
                           "(instantiated with eventModeUsed = false)",
    "earlyReturn": "the FMU returned before the step's end, which the instance was not allowed to "
                   "(earlyReturnAllowed = false); the step is not complete",
}


def open_component(name: str, fmu_path: Path | str, logging_on: bool = False) -> Component:
    """The component for the FMU file ``fmu_path``: FMI 2.0 or 3.0 Co-Simulation, as its
    model description says; ``UnsupportedFmu`` for another version or an FMU without
    Co-Simulation."""
    description = read_description(fmu_path)
    if description.coSimulation is None:
        raise UnsupportedFmu(f"{name}: {Path(fmu_path).name} (FMI {description.fmiVersion}) has no Co-Simulation "
                             "interface; lever's co-simulation masters step FMUs with doStep")
    if description.fmiVersion == "2.0":
        return Component(name, fmu_path, logging_on)
    if description.fmiVersion.startswith("3."):
        return Component3(name, fmu_path, logging_on, description)
    raise UnsupportedFmu(f"{name}: {Path(fmu_path).name} is FMI {description.fmiVersion}; lever runs FMI 2.0 "
                         "and 3.0 FMUs")


class Component3(Component):
    """An instantiated FMI 3.0 Co-Simulation FMU (see the module docstring)."""

    def __init__(self, name: str, fmu_path: Path | str, logging_on: bool = False, description=None):
        self._open(name, fmu_path, description)
        self._environment = next(_numbers)
        _environments[self._environment] = self.instance_name
        fmi2.route_messages(self.instance_name, self.messages)
        self._freed = True      # until instantiated: ``free`` has nothing to end
        try:
            self.fmu = FMU3Slave(guid=self.description.guid, unzipDirectory=self._unzipped,
                                 modelIdentifier=self.description.coSimulation.modelIdentifier,
                                 instanceName=self.instance_name)
        except Exception as error:  # noqa: BLE001 - fmpy raises a plain Exception for a missing binary
            self._unroute()
            raise library_problem(name, self.fmu_path, error) from None
        resources = str(Path(self._unzipped) / "resources") + "/"
        empty = (ctypes.c_uint32 * 0)()
        self.fmu.component = self.fmu.fmi3InstantiateCoSimulation(
            self.instance_name.encode("utf-8"), self.description.guid.encode("utf-8"), resources.encode("utf-8"),
            False, logging_on, False, False, empty, 0, ctypes.c_void_p(self._environment), _log_callback,
            _no_intermediate_update)
        if not self.fmu.component:
            messages = [m for m in self.messages if not m.startswith("[ok]")][-5:]
            self._unroute()
            self.fmu.freeLibrary()
            raise FmuUnusable(name, f"{self.fmu_path.name} refused to instantiate (fmi3InstantiateCoSimulation "
                                    "returned NULL)", messages, call="fmi3InstantiateCoSimulation")
        self._freed = False
        self.state = fmi2.INSTANTIATED
        functions = self.fmu._functions
        get, set_ = fmi2.unconverted(functions["fmi3GetFloat64"]), fmi2.unconverted(functions["fmi3SetFloat64"])
        step = functions["fmi3DoStep"]
        flags = self._flags = (ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool())
        last = self._last_time = ctypes.c_double()
        out = (*(ctypes.byref(flag) for flag in flags), ctypes.byref(last))

        # fmi3GetFloat64/fmi3SetFloat64 take the number of values after the values: one
        # per value reference, as every variable the system exchanges is a scalar.
        def get_real(handle, vrs, n, values):
            return get(handle, vrs, n, values, n)

        def set_real(handle, vrs, n, values):
            return set_(handle, vrs, n, values, n)

        def do_step(handle, t, h, no_set_prior_state):
            status = step(handle, t, h, no_set_prior_state, *out)
            if status <= 1 and (flags[0].value or flags[1].value or flags[2].value):
                self._step_request(t, h, status)
            return status

        self.raw = RawCalls(ctypes.c_void_p(self.fmu.component), get_real, set_real, do_step, ctypes.c_size_t)
        self._get_state = functions["fmi3GetFMUState"]
        self._set_state = functions["fmi3SetFMUState"]
        self._free_state = functions["fmi3FreeFMUState"]

    def _step_request(self, t: float, h: float, status: int):
        """Raise ``StepRequest`` for the first flag fmi3DoStep set (terminateSimulation
        before eventHandlingNeeded before earlyReturn)."""
        events, terminate, early = (flag.value for flag in self._flags)
        request = "terminateSimulation" if terminate else "eventHandlingNeeded" if events else "earlyReturn"
        if early:
            self.time = self._last_time.value
        self.messages.clear()
        raise StepRequest(self.name, step_call(t, h).replace("fmi2", "fmi3"), status, t, request,
                          self._last_time.value)

    def fail(self, call: str, status: int):
        """As ``Component.fail``, the call named by its FMI 3.0 name."""
        for old, new in FMI3_NAMES.items():
            if call.startswith(old):
                call = new + call[len(old):]
                break
        super().fail(call, status)

    # -- set-up ------------------------------------------------------------------------------
    def set_parameters(self, values: dict):
        for name, value in values.items():
            var = self.variable(name)
            self._checked(typed_values.call_text(var, name, value, fmi3=True), typed_values.set_on, self.fmu, var,
                          value, f"{self.name}.{name}")

    def initialize(self, start: float, stop: float | None):
        self.time = start
        self._checked("fmi3EnterInitializationMode", self.fmu.enterInitializationMode, None, start, stop)
        self.state = INITIALIZATION

    def exit_initialization(self):
        self._checked("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)
        self.state = STEPPING

    # -- tear-down ---------------------------------------------------------------------------
    def _unroute(self):
        fmi2.unroute(self.instance_name)
        _environments.pop(self._environment, None)

    def free(self):
        """As ``Component.free`` (FMI 3.0 allows the same calls in the same states)."""
        try:
            super().free()
        finally:
            _environments.pop(self._environment, None)
