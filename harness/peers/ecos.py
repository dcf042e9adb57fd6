"""ecos (PyPI ``ecospy``), the C++ co-simulation engine, run through its command-line
program on an SSP archive or an FMU (``run_ecos``, ``ecos_traces``), and the peers that run
a scene's SSP export with it (``Ecos``): ``ecos`` steps the FMUs in parallel threads (its
default) and logs what the harness records (a ``--csvConfig``); ``ecos-serial`` steps them
one after the other (``--noParallel``); ``ecos-log-all`` logs with ecos's default CSV log,
every variable of every FMU each step (about 60 reads a step, each a Python call: where
ecos's time goes by default).  Their wall time is ecos's own stepping loop's, from its
progress log.  ecos runs FMI 2.0 and FMI 3.0 Co-Simulation FMUs (it loads each by its
``fmiVersion``).  Its default CSV log reads every Float64 variable of an FMI 3.0 FMU in one
``fmi3GetFloat64`` and does not look at the status: where the FMU refuses that call, every
value it logs is 0 and the run still ends well, so ``ecos-log-all`` first asks each FMI 3.0
FMU of the scene that question itself (``refused_read``) and refuses the scene when one
says no.

The program runs in a bare environment by default (``PATH=/usr/bin:/bin``, and the path to
PyPI ``tbb``'s ``libtbb.so.12``, ecos's own need): our FMUs find their Python themselves.
"""
from __future__ import annotations

import csv
import functools
import importlib.metadata
import math
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.engine.run import RunResult
from harness.formats import ssp
from harness.peers.base import BARE_ENVIRONMENT, Peer, SceneSetup


class EcosUnavailable(RuntimeError):
    pass


def _installed():
    """ecos's program and libtbb.so.12 in the installed ``ecospy`` and ``tbb`` wheels (their
    files' entries); raises ``EcosUnavailable`` saying what is missing."""
    try:
        ecos_files = importlib.metadata.distribution("ecospy").files or []
        tbb_files = importlib.metadata.distribution("tbb").files or []
    except importlib.metadata.PackageNotFoundError as missing:
        raise EcosUnavailable(f"{missing.name} is not installed (a test dependency: pip install -e '.[test]')")
    program = next((f for f in ecos_files if f.parts[-2:] == ("binaries", "ecos")), None)
    tbb = next((f for f in tbb_files if f.name == "libtbb.so.12"), None)
    if program is None or tbb is None:
        raise EcosUnavailable("ecospy's binaries/ecos or tbb's libtbb.so.12 is missing from the installed wheels")
    return program, tbb


def ecos_program(cache: Path) -> tuple[Path, Path]:
    """(the ecos executable, the directory of libtbb.so.12) from the installed ``ecospy`` and
    ``tbb`` wheels.  ecospy's wheel ships its program without the executable bit: a copy
    with it is made in ``cache``."""
    program, tbb = _installed()
    cache.mkdir(parents=True, exist_ok=True)
    executable = cache / "ecos"
    if not executable.exists():
        shutil.copy2(Path(program.locate()), executable)
        executable.chmod(0o755)
    return executable, Path(tbb.locate()).resolve().parent


def _csv_config(record: list[str], path: Path) -> Path:
    """An ecos CSV configuration (its CsvConfig.xsd) logging the ``component.variable`` names."""
    from xml.sax.saxutils import quoteattr

    by_component: dict[str, list[str]] = {}
    for name in record:
        component, variable = name.split(".", 1)
        by_component.setdefault(component, []).append(variable)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<ecos:CsvConfig xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/schema/CsvConfig">',
             "  <ecos:components>"]
    for component, variables in by_component.items():
        lines.append(f"    <ecos:component name={quoteattr(component)}>")
        lines += [f"      <ecos:variable name={quoteattr(v)}/>" for v in variables]
        lines.append("    </ecos:component>")
    lines += ["  </ecos:components>", "</ecos:CsvConfig>"]
    path.write_text("\n".join(lines) + "\n")
    return path


@dataclass
class EcosRun:
    csv: Path
    wall_time: float   # the stepping loop, from ecos's own log
    log: str


def run_ecos(target: Path, stop: float, step: float, cache: Path, env: dict | None = None,
             parallel: bool = True, record: list[str] | None = None, timeout: float = 600) -> EcosRun:
    """Runs ``ecos simulate`` on an SSP archive or an FMU (``target``) from 0 to ``stop`` at
    ``step``, in ``env`` (default: bare), the FMUs stepped in parallel threads or not.  ecos
    writes ``<target stem>.csv`` next to the target: the ``record`` (``component.variable``
    names) or, by default, every variable.  Raises RuntimeError with ecos's output if it
    fails."""
    program, tbb_dir = ecos_program(cache)
    environment = dict(BARE_ENVIRONMENT if env is None else env)
    environment["LD_LIBRARY_PATH"] = str(tbb_dir)   # ecos's own need, not the FMUs'
    options = [] if parallel else ["--noParallel"]
    # ecos adds the step to its time (t += h) and, as its logs show, steps while t + h <= stop: the sum's
    # rounding drops the last step whenever it lands a hair above stop (10 s at 0.5 ms:
    # 19,999 steps).  Half a step beyond stop makes it take every step and no more.
    stop_given = stop + 0.5 * step
    if target.suffix == ".ssp":       # ecos applies only the parameter set it is told to
        options += ["--parameterSet", ssp.PARAMETER_SET]
    if record is not None:
        options += ["--csvConfig", str(_csv_config(record, target.with_name(target.stem + "_CsvConfig.xml")))]
    # ecos unpacks an SSP archive into the temporary directory and leaves it there (a copy of
    # every FMU per run): it takes TMPDIR, so it gets a directory of ours, removed afterwards.
    with tempfile.TemporaryDirectory(prefix="lever-ecos-") as scratch:
        environment["TMPDIR"] = scratch
        done = subprocess.run([str(program), "simulate", "--path", str(target), "--stopTime", repr(stop_given),
                               "--stepSize", repr(step), "--logLevel", "info", *options],
                              env=environment, cwd=target.parent,
                              capture_output=True, text=True, timeout=timeout)
    log = done.stdout + done.stderr
    result = target.with_suffix(".csv")
    if done.returncode != 0 or not result.exists() or "[error]" in log:
        raise RuntimeError(f"ecos failed on {target.name} (exit {done.returncode}):\n{log[-4000:]}")
    # ecos's own progress lines ("90% complete, simulated 9.000s in 4.321s"): the last one,
    # scaled to the whole span (it may log no line at 100 %).
    progress = re.findall(r"simulated ([0-9.]+)s in ([0-9.]+)s", log)
    simulated, took = (float(x) for x in progress[-1]) if progress else (float("nan"), float("nan"))
    wall = took * stop / simulated if simulated > 0 else float("nan")
    return EcosRun(result, wall, log)


def ecos_traces(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(times, {component.variable: values}) of the real columns of an ecos CSV
    (header ``iterations, time, component::variable[REAL], ...``)."""
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    header = [h.strip() for h in rows[0]]
    columns = {}
    for index, name in enumerate(header):
        match = re.fullmatch(r"(\w+)::(\w+)\[REAL\]", name)
        if match:
            columns[f"{match.group(1)}.{match.group(2)}"] = index
    table = [[float(row[i]) for i in [header.index("time"), *columns.values()]] for row in rows[1:] if row]
    data = np.array(table)
    return data[:, 0], {name: data[:, k + 1] for k, name in enumerate(columns)}


def refused_read(fmu: Path) -> str | None:
    """What an FMI 3.0 Co-Simulation instance of ``fmu`` says when every Float64 variable
    is read in one ``fmi3GetFloat64`` after initialisation, as ecos's default CSV log reads
    them after every step; None when it gives them.  Asked once per file and version of it
    in a process."""
    stat = Path(fmu).stat()
    return _refused_read(str(Path(fmu).resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=64)
def _refused_read(path: str, mtime_ns: int, size: int) -> str | None:
    from harness.engine.component import FmuCallError
    from harness.engine.fmi3_component import open_component

    component = open_component("probe", path)
    try:
        component.initialize(0.0, None)
        component.exit_initialization()
        component.get([v.name for v in component.description.modelVariables if v.type == "Float64"])
        return None
    except FmuCallError as refused:
        return "; ".join(refused.messages) or str(refused)
    finally:
        component.free()


class Ecos(Peer):
    """ecos's program on the scene's SSP export, in ``environment`` (default bare): the FMUs
    stepped in parallel threads or one after the other, logging the recorded variables or
    every variable."""

    timed = "ecos's own stepping loop, from its progress log"
    counters = ()
    fmi_versions = ("2", "3")

    def __init__(self, name: str = "ecos", parallel: bool = True, log_all: bool = False):
        self.name, self.parallel, self.log_all = name, parallel, log_all
        self.summary = ("the C++ engine ecos (ecospy's program) on the scene's SSP export, FMUs in "
                        + ("parallel threads" if parallel else "one thread (--noParallel)")
                        + (", logging every variable of every FMU (its default CSV log)" if log_all else ""))

    def unavailable(self) -> str | None:
        try:
            _installed()
        except EcosUnavailable as reason:
            return str(reason)
        return None

    def scene_problem(self, setup: SceneSetup) -> str | None:
        scene = setup.scene
        if scene.experiment.start != 0.0:
            return f"peer '{self.name}' simulates from t = 0 only; scene '{scene.name}' starts at " \
                   f"{scene.experiment.start:g} s"
        if self.log_all:
            for name, md in setup.descriptions.items():
                if md.fmiVersion.startswith("3.") and (said := refused_read(setup.fmu_paths[name])):
                    return (f"peer '{self.name}' logs every Float64 variable of {name} "
                            f"({setup.fmu_paths[name].name}, FMI {md.fmiVersion}) in one fmi3GetFloat64 after "
                            f"each step, and ecos does not check its status: the FMU refuses that call in "
                            f"Co-Simulation ({said}), so ecos would log zeros; peer 'ecos' logs the recorded "
                            "variables")
        return None

    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        scene, names = setup.scene, setup.record
        with tempfile.TemporaryDirectory(prefix="lever-ecos-") as scratch:
            scratch = Path(scratch)
            archive = ssp.export(scene, scratch / f"{scene.name}.ssp", setup.fmu_dir)
            try:
                run = run_ecos(archive, scene.experiment.stop, step, scratch / "bin", environment,
                               parallel=self.parallel, record=None if self.log_all else names)
            except RuntimeError as error:
                return setup.nothing_run(self.name, step, math.nan, str(error), "stepping")
            times, traces = ecos_traces(run.csv)
        missing = [n for n in names if n not in traces]
        if missing:
            raise ValueError(f"peer '{self.name}' logged no {', '.join(missing)}")
        return RunResult(scene, self.name, step, times, {n: traces[n] for n in names}, run.wall_time, {})
