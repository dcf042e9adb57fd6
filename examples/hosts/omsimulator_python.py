"""KAVZ-685 in OMSimulator's Python package (OMSimulatorPython): the archive read by its own
parser, the three FMUs given one CVODE solver (newSolver, setSolver): strongly coupled, their
FMI 2.0 Model Exchange.

Run with a Python that has the package on PYTHONPATH (OMSIMULATOR_PYTHONPATH below), `lever`
on PATH (or LEVER naming it):
    PYTHONPATH=$OMSIMULATOR_PYTHONPATH python examples/hosts/omsimulator_python.py RESULT.csv
    lever validate --result RESULT.csv kavz685
"""
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from OMSimulator import SSP, CRef

# OMSimulator sets the FMUs' inputs from one another's outputs only each STEP (not inside
# CVODE's right-hand side): the coupling's torques are held over it
STEP = 1e-4
TOLERANCE = 1e-7

out = Path(sys.argv[1]).resolve()
out.unlink(missing_ok=True)
with tempfile.TemporaryDirectory() as tmp:
    archive = Path(tmp) / "kavz685.ssp"
    subprocess.run([os.environ.get("LEVER", "lever"), "export-ssp", "kavz685", "--out", str(archive)],
                   check=True, stdout=subprocess.DEVNULL)
    model = SSP(str(archive))
    model.newSolver({"name": "cvode", "method": "cvode", "tolerance": TOLERANCE})
    for component in ("engine", "coupling", "load"):
        model.setSolver(CRef("kavz685", component), "cvode")
    instance = model.instantiate()
    # initial, smallest and largest step: a solver's "stepSize" would fix all three
    instance.setVariableStepSize(1e-6, 1e-12, STEP)
    instance.setResultFile(str(out))
    instance.initialize()
    instance.simulate()
    instance.terminate()
    instance.delete()
if not out.exists():
    sys.exit("OMSimulator wrote no result")
