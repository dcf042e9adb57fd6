"""KAVZ-685 in PyFMI's CoupledFMUModelME2 (the three FMUs' FMI 2.0 Model Exchange under one
CVODE).

Run with a Python that has PyFMI (PYFMI_PYTHON), `lever` on PATH (or LEVER naming it):
    $PYFMI_PYTHON examples/hosts/pyfmi_coupled_me.py RESULT.csv
    lever validate --result RESULT.csv kavz685
"""
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from pyfmi import CoupledFMUModelME2, load_fmu

STOP = 10.0
# output points: PyFMI's default 500 (a 20 ms grid) cannot follow the torque's ripple
POINTS = 20_000
RTOL = 1e-7
RECORD = ["engine.w", "load.w", "engine.a", "load.a", "coupling.tau1", "coupling.tau2",
          "coupling.U12", "coupling.theta", "engine.engine_torque", "load.load_torque"]

out = Path(sys.argv[1]).resolve()
with tempfile.TemporaryDirectory() as tmp:
    os.chdir(tmp)  # PyFMI writes a log and a result file per FMU into the current folder
    subprocess.run([os.environ.get("LEVER", "lever"), "export-ssp", "kavz685", "--out", "kavz685.ssp"],
                   check=True, stdout=subprocess.DEVNULL)
    fmus = {"engine": "EngineShaft", "coupling": "LeverCoupling", "load": "LoadShaft"}
    zipfile.ZipFile("kavz685.ssp").extractall(members=[f"resources/{fmu}.fmu" for fmu in fmus.values()])
    models = [(name, load_fmu(f"resources/{fmu}.fmu", kind="ME")) for name, fmu in fmus.items()]
    m = dict(models)
    connections = [(m["engine"], "phi", m["coupling"], "phi1"), (m["engine"], "w", m["coupling"], "w1"),
                   (m["load"], "phi", m["coupling"], "phi2"), (m["load"], "w", m["coupling"], "w2"),
                   (m["coupling"], "tau1", m["engine"], "tau"), (m["coupling"], "tau2", m["load"], "tau")]
    coupled = CoupledFMUModelME2(models, connections)
    options = coupled.simulate_options()
    options["ncp"] = POINTS
    options["CVode_options"]["rtol"] = RTOL
    result = coupled.simulate(final_time=STOP, options=options)
    table = np.column_stack([result["time"]] + [result[name] for name in RECORD])

with open(out, "w") as f:      # a file, not a name: numpy resolves a name against the folder just removed
    np.savetxt(f, table, delimiter=",", header=",".join(["time"] + RECORD), comments="")
