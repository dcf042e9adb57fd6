"""Child process of tests/fmus/test_step_watchdog.py: steps each built FMU, for the extremes of
every admitted real parameter, over step sizes from 1e-300 to 1e300, and prints one line
before and one after every fmi2DoStep, so that the parent can tell which call hangs.

Usage: step_watchdog_child.py FMU_DIR: prints ``cases N``, then runs each case whose index
it reads from stdin (one a line) and prints ``case done INDEX`` after it, until stdin ends."""
from __future__ import annotations

import sys
import tempfile
import time

import fmpy
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from harness.engine.component import add_log_listener, log_callbacks
from lever.fmus.registry import NAMES as FMUS

_said: list[str] = []
add_log_listener(lambda name, status, category, text: _said.append(text) if status >= 2 else None)

STEPS = (1e-300, 1e-100, 1e-12, 1e-3, 1e4, 1e9, 1e30, 1e300)
#: where the start matters too (the substeps' resolution of time)
STARTS = (0.0, 1e6)


def cases(fmu_dir):
    out = []
    for fmu in FMUS:
        md = fmpy.read_model_description(f"{fmu_dir}/{fmu}.fmu")
        out.append((fmu, None, None))
        for v in md.modelVariables:
            if v.causality == "parameter" and v.type == "Real":
                for bound in (v.min, v.max):
                    if bound is not None:
                        out.append((fmu, v.name, float(bound)))
    return out


def main(fmu_dir):
    every = cases(fmu_dir)
    print(f"cases {len(every)}", flush=True)
    unzipped, descriptions = {}, {}
    for line in sys.stdin:
        index = int(line)
        fmu, name, value = every[index]
        if fmu not in unzipped:
            descriptions[fmu] = fmpy.read_model_description(f"{fmu_dir}/{fmu}.fmu")
            unzipped[fmu] = fmpy.extract(f"{fmu_dir}/{fmu}.fmu", tempfile.mkdtemp())
        run_case(index, fmu, name, value, unzipped[fmu], descriptions[fmu])
        print(f"case done {index}", flush=True)
    print("all done", flush=True)


def run_case(index, fmu, name, value, unzipped, md):
    """Every step size from the FMU's state after initialisation at each start."""
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    for start in STARTS:
        slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=fmu, instanceName="watchdog")
        slave.instantiate(callbacks=log_callbacks(), loggingOn=False)
        try:
            if name is not None:
                slave.setReal([vrs[name]], [value])
            slave.setupExperiment(startTime=start)
            slave.enterInitializationMode()
            slave.exitInitializationMode()
        except FMICallException:
            print(f"{index} {fmu} {name}={value!r}: refused at initialisation", flush=True)
            slave.freeInstance()
            continue
        _said.clear()
        state = slave.getFMUstate()
        for h in STEPS:
            slave.setFMUstate(state)
            print(f"start {index} {fmu} {name}={value!r} t0={start!r} h={h!r}", flush=True)
            began = time.perf_counter()
            try:
                slave.doStep(currentCommunicationPoint=start, communicationStepSize=h)
                status = 0
            except FMICallException as error:
                status = error.status
            said = " | ".join(_said).replace("\n", " ")
            _said.clear()
            print(f"done {index} {time.perf_counter() - began:.3f} s status {status} {said}", flush=True)
        slave.freeFMUstate(state)
        slave.terminate()
        slave.freeInstance()


if __name__ == "__main__":
    main(sys.argv[1])
