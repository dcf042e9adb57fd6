"""Determinism: the same scene, seed and master give bit-identical traces across runs,
and across a save/restore of every FMU's state (serialised to bytes) in the middle of
a run - into the same instances or into fresh ones."""
from __future__ import annotations

import numpy as np
import pytest

from harness.engine import masters
from harness.description import scene
from harness.description.plan import recorded_names
from harness.engine.run import simulate
from harness.engine.system import System

SHORT = ["experiment.stop=0.4", "experiment.transient=0.1"]


@pytest.mark.parametrize("master", ["jacobi", "gauss-seidel", "jacobi-quadratic", "jacobi-midpoint",
                                    "trapezoidal-newton", "adaptive"])
def test_same_scene_seed_and_master_give_identical_traces(fmu_dir, master):
    spec = scene.load("kavz685").with_overrides(SHORT + ["load.seed=7"])
    first, second = simulate(spec, master, 2e-3, fmu_dir), simulate(spec, master, 2e-3, fmu_dir)
    assert first.ok and second.ok
    assert np.array_equal(first.times, second.times)
    assert all(np.array_equal(first.traces[n], second.traces[n]) for n in first.traces)
    assert first.counters["fmu_calls"] == second.counters["fmu_calls"]


def test_another_seed_gives_another_load(fmu_dir):
    runs = [simulate(scene.load("kavz685").with_overrides(SHORT + [f"load.seed={s}"]), "jacobi", 2e-3, fmu_dir)
            for s in (7, 8)]
    assert not np.array_equal(runs[0].traces["load.load_torque"], runs[1].traces["load.load_torque"])


def _stepper(spec, fmu_dir, master):
    system = System(spec, fmu_dir, record=recorded_names(spec))
    system.initialize()
    return system, masters.make(master, system, spec.experiment.step)


def _advance(system, driver, n, h, names):
    rows = []
    for _ in range(n):
        driver.step(t_next=round((driver.t + h) / h) * h)
        rows.append([system.value(*name.split(".")) for name in names])
    return np.array(rows)


def _serialised(system) -> dict[str, bytes]:
    out = {}
    for name, c in system.components.items():
        state = c.fmu.getFMUstate()
        out[name] = bytes(c.fmu.serializeFMUstate(state))
        c.fmu.freeFMUstate(state)
    return out


def _restore(system, saved: dict[str, bytes], t: float):
    for name, data in saved.items():
        c = system.components[name]
        state = c.fmu.deSerializeFMUstate(data)
        c.restore_state(state, t)
        c.fmu.freeFMUstate(state)


def _resume(system, driver, saved, t_mid, h, names):
    """Restore the serialised states at ``t_mid`` and step on as far as the first run went."""
    _restore(system, saved, t_mid)
    driver.t = t_mid
    return _advance(system, driver, 150, h, names)


@pytest.mark.parametrize("name,master", [("kavz685", "jacobi"), ("kavz685", "gauss-seidel"),
                                         ("kavz685_runup_rest", "jacobi")])
def test_serialised_state_restored_mid_run_continues_bit_identically(fmu_dir, name, master):
    """Masters without memory of their own: the FMUs' states are the whole state - the
    lagged engine torque of kavz685_runup_rest's engine included."""
    spec = scene.load(name).with_overrides(["experiment.stop=1", "experiment.transient=0.1",
                                                 "experiment.step=0.001", "load.seed=3"])
    h = spec.experiment.step
    names = recorded_names(spec)
    system, driver = _stepper(spec, fmu_dir, master)
    try:
        _advance(system, driver, 150, h, names)
        saved, t_mid = _serialised(system), driver.t
        reference = _advance(system, driver, 150, h, names)
        # Back to the middle in the same instances.
        again = _resume(system, driver, saved, t_mid, h, names)
    finally:
        system.free()
    assert np.array_equal(again, reference)
    # Into fresh instances (another System), as a saved run would be resumed.
    fresh, driver = _stepper(spec, fmu_dir, master)
    try:
        resumed = _resume(fresh, driver, saved, t_mid, h, names)
    finally:
        fresh.free()
    assert np.array_equal(resumed, reference)
    assert np.all(np.isfinite(reference)) and len(np.unique(reference[:, 0])) > 100
