"""Build this folder's C FMUs into a folder: ``build(out_dir) -> path of TorqueMonitor.fmu``
(FMI 2.0 co-simulation), ``build_bouncing_ball(out_dir) -> path of BouncingBall.fmu`` (FMI
2.0 Model Exchange).  Needs a C compiler (cc/gcc); the FMI 2.0 headers come with fmpy."""
from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
NAME = "TorqueMonitor"


def build(out_dir: Path) -> Path:
    return _build(out_dir, NAME, "torque_monitor.c", "modelDescription.xml")


def build_bouncing_ball(out_dir: Path) -> Path:
    return _build(out_dir, "BouncingBall", "bouncing_ball.c", "bouncing_ball.xml")


def _build(out_dir: Path, name: str, source: str, description: str) -> Path:
    import fmpy

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    headers = Path(fmpy.__file__).parent / "c-code"
    library = out_dir / f"{name}.so"
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    subprocess.run([compiler, "-shared", "-fPIC", "-O2", "-Wall", "-Werror", "-fvisibility=hidden",
                    f"-I{headers}", str(HERE / source), "-o", str(library), "-lm"], check=True)
    fmu = out_dir / f"{name}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.write(HERE / description, "modelDescription.xml")
        archive.write(library, f"binaries/linux64/{name}.so")
        archive.write(HERE / source, f"sources/{source}")
    library.unlink()
    return fmu
