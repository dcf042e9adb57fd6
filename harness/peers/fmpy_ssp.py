"""``fmpy-ssp``: fmpy's own multi-FMU stepper, ``fmpy.ssp.simulate_ssp`` (fmpy 0.3.x), on
the scene exported as an SSP archive (``harness.formats.ssp``), as an fmpy user runs an SSP.

``simulate_ssp`` cannot set String parameters (``transfer_mode``, ``load_kind``:
"Unsupported type: String"), ignores the SSD's parameter bindings (only a
``parameter_set`` argument is applied), starts every connected input at 0.0 instead of
propagating the initial outputs, and labels each row with the start time of the step that
produced it.  It is run as `lever export-ssp` prints (``harness.formats.ssp.how_to_run``):
the archive's FMUs start at the scene's values, so ``simulate_ssp`` is called without a
parameter set; where an FMU cannot carry its values, with the archive's qualified set
(``harness.formats.ssp.QUALIFIED_SET``), and a String parameter such an FMU would have to be
set to is refused.  The zero start of the connected inputs stays (the first step sees no
torque); rows are labelled with the end of the step that produced them.  Each component's
outputs are read right after its own ``doStep``, so the coupling's torques lag one step as
under libcosim.  Its wall time includes unpacking and instantiating the FMUs
(``simulate_ssp`` does everything in one call).
"""
from __future__ import annotations

import tempfile
import time as clock
from pathlib import Path

import numpy as np

from harness.engine.run import RunResult
from harness.peers.base import Peer, SceneSetup, first_non_finite


class FmpySsp(Peer):
    name = "fmpy-ssp"
    summary = "fmpy.ssp.simulate_ssp on the scene's SSP export; inputs start at 0, feedthrough outputs lag one step"
    from_first_step = True
    timed = "everything: unpacking, instantiating and stepping the FMUs (simulate_ssp is one call)"
    fmi_limit = ("fmpy 0.3.32's fmpy.ssp makes every FMU that is not FMI 1.0 an FMI 2.0 FMU2Slave (it looks for "
                 "binaries/linux64, which an FMI 3.0 FMU has not)")

    def unavailable(self) -> str | None:
        try:
            from fmpy.ssp.simulation import simulate_ssp  # noqa: F401
        except ImportError as error:
            return f"fmpy.ssp does not import: {error}"
        return None

    def scene_problem(self, setup: SceneSetup) -> str | None:
        from harness.formats import ssp

        carried, _ = ssp.carried_values(setup.scene, {spec.fmu: setup.descriptions[name] for name, spec
                                                      in setup.scene.components.items()}, setup.fmu_dir)
        refused = []
        for comp, values in setup.parameters.items():
            starts = carried.get(setup.scene.components[comp].fmu, {})
            for name, value in values.items():
                var = setup.variables[comp][name]
                start = starts.get(name, var.start or "")
                if var.type == "String" and str(value) != start:
                    refused.append(f"{comp}.{name} = {value!r} (the archive's FMU starts at {start!r})")
        if refused:
            return f"{self.name}: fmpy.ssp cannot set String parameters, and the scene sets " + ", ".join(refused)
        for item in setup.record:
            comp, _, var = item.partition(".")
            if setup.variables[comp][var].causality not in ("input", "output"):
                return (f"{self.name}: fmpy.ssp records connectors only; {item} is a "
                        f"{setup.variables[comp][var].causality}")
        return None

    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        from fmpy.ssp.simulation import simulate_ssp
        from fmpy.ssp.ssd import read_ssv

        from harness.formats import ssp

        scene, e = setup.scene, setup.scene.experiment
        failure = None
        with tempfile.TemporaryDirectory(prefix="lever-fmpy-ssp-") as scratch:
            archive = ssp.export(scene, Path(scratch) / f"{scene.name}.ssp", setup.fmu_dir)
            # as `lever export-ssp` tells an fmpy user to run it: plain where the FMUs carry
            # every value, else with the archive's qualified set, the one form simulate_ssp applies
            _, notes = ssp.how_to_run(scene, archive, setup.fmu_dir)
            values = read_ssv(str(archive), resource=ssp.QUALIFIED_SET) if notes else None
            started = clock.perf_counter()
            try:
                table = simulate_ssp(str(archive), start_time=e.start, stop_time=e.stop, step_size=step,
                                     parameter_set=values)
            except Exception as error:  # noqa: BLE001 - simulate_ssp keeps nothing of a failed run
                table = None
                failure = f"{type(error).__name__}: {error} (peer {self.name}, step {step:g} s)"
            wall = clock.perf_counter() - started
        if table is None:
            return setup.nothing_run(self.name, step, wall, failure, "stepping")
        # Row k holds the values after step k; simulate_ssp labels it with the step's start.
        times = np.asarray(table["time"], dtype=float) + step
        keep = times <= e.stop + 1e-9 * max(1.0, abs(e.stop))
        traces = {item: np.asarray(table[item], dtype=float)[keep] for item in setup.record}
        times = times[keep]
        bad = first_non_finite(times, traces)
        if bad is not None:
            times, traces = times[:bad[0] + 1], {n: v[:bad[0] + 1] for n, v in traces.items()}
            failure = f"{bad[1]} (peer {self.name}, step {step:g} s)"
        return RunResult(scene, self.name, step, times, traces, wall, {"steps": len(times)}, failure,
                         "stepping" if failure else None)
