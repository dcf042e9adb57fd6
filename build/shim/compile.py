"""Build the FMI 2.0 status/logging shim and splice it into pythonfmu FMUs.

pythonfmu 0.7.0's export library turns every Python-side problem into
fmi2Fatal (leaving a dangling instance behind) and drops error messages when
the importer starts with logging off.  ``lever_fmi2_shim.c`` sits in front of
it; see that file for the details.  ``wrap_fmu`` installs the shim under the
FMU's model identifier and moves the pythonfmu library next to it as
``pythonfmu-export.so``, the name the shim loads.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

SHIM_SOURCE = Path(__file__).with_name("lever_fmi2_shim.c")

# Must match INNER_LIBRARY_NAME in lever_fmi2_shim.c.
INNER_LIBRARY_NAME = "pythonfmu-export.so"
PLATFORM_DIR = "binaries/linux64"

CFLAGS = ["-shared", "-fPIC", "-O2", "-std=c99", "-fvisibility=hidden",
          "-Wall", "-Wextra", "-Werror"]


def compile_shim(dest: Path) -> Path:
    """Compile the shim into the shared library ``dest`` and return its path.

    Uses ``$CC`` (which may carry extra flags, e.g. ``"gcc -m64"``) or ``cc``.
    Raises RuntimeError with the compiler's output if compilation fails.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    cc = shlex.split(os.environ.get("CC") or "cc")
    cmd = [*cc, *CFLAGS, "-o", str(dest), str(SHIM_SOURCE), "-ldl"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as exc:  # compiler not installed
        raise RuntimeError(f"cannot run {cc[0]!r}: {exc}") from exc
    if proc.returncode != 0:
        raise RuntimeError(
            f"compiling {SHIM_SOURCE.name} failed ({shlex.join(cmd)}):\n"
            f"{proc.stderr}{proc.stdout}")
    return dest


def _model_identifier(fmu: zipfile.ZipFile) -> str:
    root = ET.fromstring(fmu.read("modelDescription.xml"))
    cs = root.find("CoSimulation")
    if cs is None or not cs.get("modelIdentifier"):
        raise ValueError("modelDescription.xml has no CoSimulation modelIdentifier")
    return cs.get("modelIdentifier")


def _renamed(info: zipfile.ZipInfo, name: str) -> zipfile.ZipInfo:
    """A copy of ``info`` (date, permissions, compression) under a new name."""
    new = zipfile.ZipInfo(name, date_time=info.date_time)
    new.compress_type = info.compress_type
    new.external_attr = info.external_attr
    new.create_system = info.create_system
    return new


def wrap_fmu(fmu_path: Path, shim_so: Path) -> None:
    """Put the shim in front of the pythonfmu library of ``fmu_path``, in place.

    ``binaries/linux64/<modelIdentifier>.so`` becomes
    ``binaries/linux64/pythonfmu-export.so`` and the shim takes its name.
    Every other member (other platforms included) is copied unchanged.  The
    new archive is written to a temporary file and atomically renamed over
    the original, so a failure never leaves a half-written FMU.
    """
    fmu_path = Path(fmu_path)
    shim_bytes = Path(shim_so).read_bytes()

    with zipfile.ZipFile(fmu_path) as src:
        ident = _model_identifier(src)
        target = f"{PLATFORM_DIR}/{ident}.so"
        inner = f"{PLATFORM_DIR}/{INNER_LIBRARY_NAME}"
        names = src.namelist()
        if target not in names:
            raise ValueError(f"{fmu_path} has no {target}")
        if inner in names:
            raise ValueError(f"{fmu_path} already contains {inner} (wrapped twice?)")

        fd, tmp_name = tempfile.mkstemp(prefix=fmu_path.name + ".", suffix=".tmp",
                                        dir=fmu_path.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        try:
            with zipfile.ZipFile(tmp, "w") as dst:
                for info in src.infolist():
                    data = src.read(info)
                    if info.filename == target:
                        dst.writestr(_renamed(info, target), shim_bytes)
                        dst.writestr(_renamed(info, inner), data)
                    else:
                        dst.writestr(info, data)
            shutil.copymode(fmu_path, tmp)  # mkstemp creates 0600
            os.replace(tmp, fmu_path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
