"""A Model Exchange host as C hosts with SUNDIALS CVODE write it (Reference-FMUs' ``fmusim
--solver cvode`` is the model): the FMU's event indicators are CVODE's own root functions,
and after an event CVODE is re-initialised only where the event update says the states
changed (``valuesOfContinuousStatesChanged``); otherwise it carries on from its own
history, and CVODE's check for a root at and just after its restart point (``cvRcheck2``)
stops the run where an indicator is still exactly zero there ("Root found at and very near
t").  That is the check an FMU's indicators must pass: a mode entered never starts at a
zero indicator.

``run(fmu, fmi=2|3, ...)`` drives one FMU alone through fmpy's raw calls (FMI 2.0 or 3.0),
its inputs held at their start values, and returns the outputs every ``step`` from 0 and at
``stop`` itself, and what the run took; a failure of CVODE or of a call raises ``HostFailure`` with CVODE's message
and the time.
"""
from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.description import typed_values
from harness.engine.component import unzipped as extracted


class HostFailure(RuntimeError):
    """The host could not go on (CVODE's message, or an FMI call's status)."""


@dataclass
class HostRun:
    times: np.ndarray
    outputs: dict                   #: variable name -> values at ``times``
    events: int = 0                 #: state events CVODE's root finding located
    restarts: int = 0               #: CVodeReInit after an event that changed the states
    t_end: float = 0.0
    log: list = field(default_factory=list)   #: (time, the event indicators at the root CVODE located)
    #: (time, indices) of the event indicators exactly zero just after an event was handled:
    #: what the FMU promises never to give (a CVODE that goes on from its history stops there)
    zero_after_event: list = field(default_factory=list)


class _Fmi2:
    def __init__(self, model):
        self.m = model

    def get(self, vrs):
        return list(self.m.getReal(vrs))

    def event_update(self):
        """(more rounds needed, terminate, states changed)."""
        needed, terminate, nominals, values, *_ = self.m.newDiscreteStates()
        return needed, terminate, values or nominals

    def initialise(self, start, stop):
        self.m.setupExperiment(startTime=start, stopTime=stop)
        self.m.enterInitializationMode()

    def derivatives(self, dx, n):
        return self.m.getDerivatives(dx, n)


class _Fmi3(_Fmi2):
    def get(self, vrs):
        return list(self.m.getFloat64(vrs))

    def event_update(self):
        needed, terminate, nominals, values, *_ = self.m.updateDiscreteStates()
        return needed, terminate, values or nominals

    def initialise(self, start, stop):
        self.m.enterInitializationMode(startTime=start, stopTime=stop)

    def derivatives(self, dx, n):
        return self.m.getContinuousStateDerivatives(dx, n)


def run(fmu: Path, fmi: int, start_values: dict, outputs: list, stop: float, step: float,
        rtol: float = 1e-6, atol: float = 1e-8, max_events: int = 100_000) -> HostRun:
    """The FMU ``fmu`` (its FMI ``fmi`` edition) from 0 to ``stop`` through CVODE (BDF) with
    its own root finding, the outputs ``outputs`` recorded every ``step`` (see the module
    docstring)."""
    from fmpy import read_model_description
    from sksundae.cvode import CVODE

    md = read_model_description(str(fmu))
    unzipped = extracted(fmu)
    variables = {v.name: v for v in md.modelVariables}
    if fmi == 2:
        from fmpy.fmi2 import FMU2Model
        raw = FMU2Model(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="host")
        host = _Fmi2(raw)
    else:
        from fmpy.fmi3 import FMU3Model
        raw = FMU3Model(guid=md.instantiationToken, unzipDirectory=unzipped,
                        modelIdentifier=md.modelExchange.modelIdentifier, instanceName="host")
        host = _Fmi3(raw)
    nx, nz = len(md.derivatives), md.numberOfEventIndicators
    out_vrs = [variables[name].valueReference for name in outputs]
    raw.instantiate()
    initialised = False
    try:
        for name, value in start_values.items():
            typed_values.set_on(raw, variables[name], value, name)
        host.initialise(0.0, stop)
        initialised = True
        raw.exitInitializationMode()
        _settle(host, "at its initialisation")
        raw.enterContinuousTimeMode()
        return _integrate(raw, host, nx, nz, out_vrs, outputs, stop, step, rtol, atol, max_events, CVODE)
    finally:
        if initialised:
            with contextlib.suppress(Exception):
                raw.terminate()
        with contextlib.suppress(Exception):
            raw.freeInstance()


def _settle(host, when: str, rounds: int = 100) -> bool:
    """Event-update rounds until the FMU needs no more; whether any changed the states.  A
    host does not loop for ever: an FMU still asking after ``rounds`` rounds is a failure."""
    changed = False
    for _ in range(rounds):
        needed, terminate, states = host.event_update()
        changed = changed or states
        if terminate:
            raise HostFailure(f"the FMU asked to terminate {when}")
        if not needed:
            return changed
    raise HostFailure(f"the FMU still asked for event iterations after {rounds} rounds {when}")


def _integrate(raw, host, nx, nz, out_vrs, outputs, stop, step, rtol, atol, max_events, CVODE) -> HostRun:
    import ctypes

    x = (ctypes.c_double * nx)()
    dx = (ctypes.c_double * nx)()
    z = (ctypes.c_double * max(nz, 1))()

    def at(t, y):
        raw.setTime(t)
        x[:] = list(y)
        raw.setContinuousStates(x, nx)

    def rhs(t, y, yp):
        at(t, y)
        host.derivatives(dx, nx)
        yp[:] = dx[:]

    def roots(t, y, g):
        at(t, y)
        raw.getEventIndicators(z, nz)
        g[:] = z[:nz]
    roots.terminal = [True] * nz
    roots.direction = [0] * nz

    # SUNDIALS prints its warnings to stdout: to stderr, where a host's log goes
    os.environ.setdefault("SUNLOGGER_WARNING_FILENAME", "stderr")
    solver = CVODE(rhs, method="BDF", rtol=rtol, atol=atol, max_num_steps=100_000,
                   **(dict(eventsfn=roots, num_events=nz) if nz else {}))
    raw.getContinuousStates(x, nx)
    solver.init_step(0.0, np.array(x[:]))
    # the last row at ``stop`` itself: k * step overshoots it (0.7 / 0.001 is 699.99..., 700 * 0.001
    # is 0.70000000000000007), and a stop that is no whole number of steps ends on a shorter step
    n_out = max(1, math.ceil(stop / step - 1e-9))
    times = [0.0]
    record = [host.get(out_vrs)]
    run = HostRun(np.empty(0), {})
    t = 0.0
    k = 1
    while k <= n_out:
        target = stop if k == n_out else k * step
        result = solver.step(target, method="normal")
        if not result.success:
            raise HostFailure(f"CVODE stopped after t = {t:.9g} s: {result.message} (status {result.status}; "
                              f"after {run.events} events)")
        t = float(result.t)
        at(t, result.y)
        if result.status == 2:                     # CV_ROOT_RETURN: an indicator reached zero
            run.events += 1
            if run.events > max_events:
                raise HostFailure(f"more than {max_events} events by t = {t:.9g} s")
            raw.getEventIndicators(z, nz)
            run.log.append((t, list(z[:nz])))
            raw.enterEventMode()
            changed = _settle(host, f"at t = {t:.9g} s")
            raw.enterContinuousTimeMode()
            raw.getEventIndicators(z, nz)
            zeros = [i for i in range(nz) if z[i] == 0.0]
            if zeros:
                run.zero_after_event.append((t, zeros))
            if changed:                            # as fmusim: re-initialise only then
                raw.getContinuousStates(x, nx)
                solver.init_step(t, np.array(x[:]))
                run.restarts += 1
        if t >= target:
            times.append(t)
            record.append(host.get(out_vrs))
            k += 1
    values = np.array(record)
    run.times = np.array(times)
    run.outputs = {name: values[:, i] for i, name in enumerate(outputs)}
    run.t_end = t
    return run
