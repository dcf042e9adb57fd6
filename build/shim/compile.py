"""Build the FMUs' native entry (the shim) and splice it into pythonfmu FMUs.

``lever_fmi2_shim.c`` sits in front of pythonfmu 0.7.0's export library: it finds a
Python for the FMU, checks the resource location, GUID and the FMI 2.0 state machine,
keeps one Python thread state per host thread and mends pythonfmu's status handling;
see that file for the details.  ``wrap_fmu`` installs the shim under the FMU's model
identifier, moves the pythonfmu library next to it as ``pythonfmu-export.so`` (the
name the shim loads) and writes ``resources/lever_shim.cfg``: the FMU's GUID and the
Python it was built with (the second place the shim looks for one).
"""

from __future__ import annotations

import os
import shlex
import shutil
import site
import subprocess
import sys
import sysconfig
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

SHIM_SOURCE = Path(__file__).with_name("lever_fmi2_shim.c")
#: the FMI 3.0 entry: a layer on the FMI 2.0 entry (see that file and build/fmi3.py)
SHIM3_SOURCE = Path(__file__).with_name("lever_fmi3_shim.c")

# Must match INNER_LIBRARY_NAME and CONFIG_NAME in lever_fmi2_shim.c.
INNER_LIBRARY_NAME = "pythonfmu-export.so"
CONFIG_NAME = "resources/lever_shim.cfg"
PLATFORM_DIR = "binaries/linux64"

# -z nodelete: the shim registers a thread-exit destructor, so it must stay loaded
# after an importer's dlclose.
CFLAGS = ["-shared", "-fPIC", "-O2", "-std=c99", "-fvisibility=hidden",
          "-Wall", "-Wextra", "-Werror", "-Wl,-z,nodelete"]


def compile_shim(dest: Path, source: Path = SHIM_SOURCE) -> Path:
    """Compile the shim (``source``: the FMI 2.0 entry, or ``SHIM3_SOURCE``) into the shared
    library ``dest`` and return its path.

    Uses ``$CC`` (which may carry extra flags, e.g. ``"gcc -m64"``) or ``cc``.
    Raises RuntimeError with the compiler's output if compilation fails.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    cc = shlex.split(os.environ.get("CC") or "cc")
    cmd = [*cc, *CFLAGS, "-o", str(dest), str(source), "-ldl", "-lpthread", "-lm"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as exc:  # compiler not installed
        raise RuntimeError(f"cannot run {cc[0]!r}: {exc}") from exc
    if proc.returncode != 0:
        raise RuntimeError(
            f"compiling {Path(source).name} failed ({shlex.join(cmd)}):\n"
            f"{proc.stderr}{proc.stdout}")
    return dest


def _identity(fmu: zipfile.ZipFile) -> tuple[str, str]:
    """(modelIdentifier, guid) from the FMU's modelDescription.xml."""
    root = ET.fromstring(fmu.read("modelDescription.xml"))
    cs = root.find("CoSimulation")
    if cs is None or not cs.get("modelIdentifier"):
        raise ValueError("modelDescription.xml has no CoSimulation modelIdentifier")
    if not root.get("guid"):
        raise ValueError("modelDescription.xml has no guid")
    return cs.get("modelIdentifier"), root.get("guid")


def build_python() -> dict:
    """The Python running this build, as the shim's config names it: its shared library
    (absent for a statically linked interpreter), its prefix and, for a virtual
    environment, its site-packages (where the model's requirements are installed)."""
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    library = None
    for name in (sysconfig.get_config_var("INSTSONAME"), sysconfig.get_config_var("LDLIBRARY")):
        if name and ".so" in name and os.path.exists(os.path.join(libdir, name)):
            library = os.path.join(libdir, name)
            break
    paths = site.getsitepackages() if sys.prefix != sys.base_prefix else []
    return {"library": library, "home": sys.base_prefix, "paths": paths}


def shim_config(guid: str, python: dict, channel: bool = False) -> str:
    """The text of resources/lever_shim.cfg (lines key=value, read by the shim); ``channel``:
    the model answers the shim's channel (``lever.fmus.me_channel``, every model of ours),
    so a Co-Simulation instance gets the point block too."""
    for value in [guid, python["home"], *python["paths"], python["library"] or ""]:
        if "\n" in value or "\r" in value:
            raise ValueError(f"cannot write a line break into {CONFIG_NAME}: {value!r}")
    lines = ["# Written by build/shim/compile.py: this FMU's GUID and the Python it was built with.",
             f"guid={guid}"]
    if python["library"]:
        lines += [f"python_library={python['library']}", f"python_home={python['home']}"]
        lines += [f"python_path={p}" for p in python["paths"]]
    if channel:
        lines.append("channel=1")
    return "\n".join(lines) + "\n"


def _renamed(info: zipfile.ZipInfo, name: str) -> zipfile.ZipInfo:
    """A copy of ``info`` (date, permissions, compression) under a new name."""
    new = zipfile.ZipInfo(name, date_time=info.date_time)
    new.compress_type = info.compress_type
    new.external_attr = info.external_attr
    new.create_system = info.create_system
    return new


def wrap_fmu(fmu_path: Path, shim_so: Path, channel: bool = False) -> None:
    """Put the shim in front of the pythonfmu library of ``fmu_path``, in place.

    ``binaries/linux64/<modelIdentifier>.so`` becomes
    ``binaries/linux64/pythonfmu-export.so`` and the shim takes its name;
    ``resources/lever_shim.cfg`` is added (see ``shim_config``, which ``channel`` goes to).
    Every other member (other platforms included) is copied unchanged.  The
    new archive is written to a temporary file and atomically renamed over
    the original, so a failure never leaves a half-written FMU.
    """
    fmu_path = Path(fmu_path)
    shim_bytes = Path(shim_so).read_bytes()

    with zipfile.ZipFile(fmu_path) as src:
        ident, guid = _identity(src)
        target = f"{PLATFORM_DIR}/{ident}.so"
        inner = f"{PLATFORM_DIR}/{INNER_LIBRARY_NAME}"
        names = src.namelist()
        if target not in names:
            raise ValueError(f"{fmu_path} has no {target}")
        if inner in names:
            raise ValueError(f"{fmu_path} already contains {inner} (wrapped twice?)")
        config = shim_config(guid, build_python(), channel)

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
                dst.writestr(_renamed(src.getinfo("modelDescription.xml"), CONFIG_NAME), config)
            shutil.copymode(fmu_path, tmp)  # mkstemp creates 0600
            os.replace(tmp, fmu_path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
