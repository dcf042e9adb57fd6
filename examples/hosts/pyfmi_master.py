"""KAVZ-685 in PyFMI's co-simulation Master (FMI 2.0 Co-Simulation).

Run with a Python that has PyFMI (PYFMI_PYTHON), `lever` on PATH (or LEVER naming it):
    $PYFMI_PYTHON examples/hosts/pyfmi_master.py RESULT.csv
    lever validate --result RESULT.csv kavz685
"""
import csv
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from pyfmi import load_fmu
from pyfmi.master import Master

# Master sets each FMU's inputs from the others' outputs of the step before (the coupling's
# torques reach the shafts one step late): at the scene's 1 ms that lag fails the verdict
STEP = 1e-4
STOP = 10.0
RECORD = {"engine": ["w", "a", "engine_torque"], "load": ["w", "a", "load_torque"],
          "coupling": ["tau1", "tau2", "U12", "theta"]}

out = Path(sys.argv[1]).resolve()
with tempfile.TemporaryDirectory() as tmp:
    os.chdir(tmp)  # PyFMI writes a log and a result file per FMU into the current folder
    # the export's FMUs start at the scene's values: nothing needs setting
    subprocess.run([os.environ.get("LEVER", "lever"), "export-ssp", "kavz685", "--out", "kavz685.ssp"],
                   check=True, stdout=subprocess.DEVNULL)
    zipfile.ZipFile("kavz685.ssp").extractall(members=[f"resources/{m}.fmu" for m in
                                                       ("EngineShaft", "LeverCoupling", "LoadShaft")])
    engine, coupling, load = (load_fmu(f"resources/{m}.fmu", kind="CS")
                              for m in ("EngineShaft", "LeverCoupling", "LoadShaft"))
    connections = [(engine, "phi", coupling, "phi1"), (engine, "w", coupling, "w1"),
                   (load, "phi", coupling, "phi2"), (load, "w", coupling, "w2"),
                   (coupling, "tau1", engine, "tau"), (coupling, "tau2", load, "tau")]
    master = Master([engine, coupling, load], connections)
    options = master.simulate_options()
    options["step_size"] = STEP
    # store only what is written below (PyFMI stores every variable by default)
    options["filter"] = {engine: RECORD["engine"], coupling: RECORD["coupling"], load: RECORD["load"]}
    result = master.simulate(final_time=STOP, options=options)
    models = {"engine": engine, "coupling": coupling, "load": load}
    columns = {"time": result[engine]["time"]}
    columns.update({f"{name}.{v}": result[models[name]][v] for name, variables in RECORD.items() for v in variables})

with open(out, "w", newline="") as f:
    writer = csv.writer(f)
    writer.writerow(columns)
    writer.writerows(zip(*columns.values()))
