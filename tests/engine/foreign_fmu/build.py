"""Build the TorqueMonitor FMU (C, FMI 2.0 co-simulation) from this folder's sources into
a folder: ``build(out_dir) -> path of TorqueMonitor.fmu``.  Needs a C compiler (cc/gcc);
the FMI 2.0 headers come with fmpy."""
from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
NAME = "TorqueMonitor"


def build(out_dir: Path) -> Path:
    import fmpy

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    headers = Path(fmpy.__file__).parent / "c-code"
    library = out_dir / f"{NAME}.so"
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    subprocess.run([compiler, "-shared", "-fPIC", "-O2", "-Wall", "-Werror", "-fvisibility=hidden",
                    f"-I{headers}", str(HERE / "torque_monitor.c"), "-o", str(library), "-lm"], check=True)
    fmu = out_dir / f"{NAME}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.write(HERE / "modelDescription.xml", "modelDescription.xml")
        archive.write(library, f"binaries/linux64/{NAME}.so")
        archive.write(HERE / "torque_monitor.c", f"sources/torque_monitor.c")
    library.unlink()
    return fmu
