"""FMU instances are freed completely: after a thousand and more instantiate/free cycles
no file handle, temporary directory or loaded library copy is left behind, and the
process's memory has not grown with them."""
from __future__ import annotations

import os
import tempfile

import fmpy
from fmpy.fmi2 import FMU2Slave

from harness.engine import component
from harness.engine.component import Component
from harness.engine.traces import resident_bytes


def open_files() -> int:
    return len(os.listdir("/proc/self/fd"))


def library_mappings() -> int:
    with open("/proc/self/maps") as f:
        return sum("pythonfmu-export" in line or "EngineShaft.so" in line for line in f)


def test_thousands_of_instances_leave_nothing_behind(fmu_dir, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))       # count only our temporary directories
    component.remove_extractions()
    path = fmu_dir / "EngineShaft.fmu"                               # the cheapest FMU to instantiate
    md = fmpy.read_model_description(str(path))

    def harness_cycle():
        c = Component("engine", path)
        c.initialize(0.0, 1.0)
        c.exit_initialization()
        c.do_step(0.0, 1e-3)
        c.free()

    def fmpy_cycle(n):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=component.unzipped(path),
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"cycle{n}")
        fmu.instantiate(callbacks=component.log_callbacks())
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1e-3)
        fmu.terminate()
        fmu.freeInstance()

    for n in range(20):                                               # warm up: imports, caches
        harness_cycle()
        fmpy_cycle(n)
    before = open_files(), len(os.listdir(tmp_path)), library_mappings(), resident_bytes()
    for n in range(1000):
        fmpy_cycle(n)
    for _ in range(500):
        harness_cycle()
    after = open_files(), len(os.listdir(tmp_path)), library_mappings(), resident_bytes()
    assert after[:3] == before[:3], (before, after)
    assert before[1] == 1 and before[2] > 0                           # one extraction, its library mapped
    assert after[3] - before[3] < 10 * 2 ** 20, f"memory grew by {(after[3] - before[3]) / 2 ** 20:.1f} MB"
    component.remove_extractions()
    assert os.listdir(tmp_path) == []
