"""``lever hosts``: our FMUs in hosts we did not write, timed against our harness.

The same scene (KAVZ-685, 10 s at 1 ms by default) in
* ``harness-jacobi`` - our harness, master ``jacobi`` (in this process, fmpy's ctypes calls);
* ``libcosim-fixed`` - OSP libcosim's fixed-step algorithm (libcosimpy, a child process;
  it calls the FMUs from its worker threads);
* ``ecos`` - the C++ engine ecos (PyPI ``ecospy``), its command-line program on our SSP
  export, in a bare environment (``PATH=/usr/bin:/bin`` and the path to PyPI ``tbb``'s
  ``libtbb.so.12`` only: the FMUs find their Python themselves), stepping the FMUs in
  parallel threads as it does by default and logging what our harness records (a
  ``--csvConfig`` of the scene's record); ``ecos-serial`` the same with ``--noParallel``;
  ``ecos-log-all`` with ecos's default CSV log, every variable of every FMU each step
  (about 60 reads a step, each a Python call: where ecos's time goes by default);
* ``c-importer`` - our minimal C host (tests/c_host), bare environment: it cannot couple
  FMUs, so it steps the scene's three FMUs each alone for the same span (one input set
  once; fmi2DoStep and one fmi2GetReal a step: 6 calls a step for the three, against the
  coupled scene's 12), and its time is the sum of the three stepping loops.
Each host's time is its stepping loop as the host reports it (ours and libcosim's: from
applying the parameters to the last communication point; ecos: the time of its last
progress line, "90% complete, simulated 9.000s in T s", scaled to the whole span), the median of ``repeats`` runs, and the ratio
to our harness's median in the same run.

``run_ecos`` and ``ecos_traces`` are also what the tests use to run ecos.
"""
from __future__ import annotations

import csv
import importlib.metadata
import os
import re
import shutil
import statistics
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..formats import peers, ssp
from ..description import scene as scenes
from ..paths import FMUS, RESULTS, ROOT
from ..engine.run import simulate

HOSTS = ("harness-jacobi", "libcosim-fixed", "ecos", "ecos-serial", "ecos-log-all", "c-importer")
#: The environment of a host that is not a Python process and was set up for nothing.
BARE_ENVIRONMENT = {"PATH": "/usr/bin:/bin"}


class EcosUnavailable(RuntimeError):
    pass


def set_up_environment() -> dict:
    """What a non-Python host needed before the FMUs found their Python themselves (and
    still may use): this interpreter's libpython preloaded, its home and site-packages."""
    import sys
    import sysconfig

    library = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    return {**BARE_ENVIRONMENT, "LD_PRELOAD": str(library), "PYTHONHOME": sys.base_prefix,
            "PYTHONPATH": sysconfig.get_paths()["purelib"], "PYTHONNOUSERSITE": "1"}


def ecos_program(cache: Path) -> tuple[Path, Path]:
    """(the ecos executable, the directory of libtbb.so.12) from the installed ``ecospy`` and
    ``tbb`` wheels.  ecospy's wheel ships its program without the executable bit: a copy
    with it is made in ``cache``."""
    try:
        ecos_files = importlib.metadata.distribution("ecospy").files or []
        tbb_files = importlib.metadata.distribution("tbb").files or []
    except importlib.metadata.PackageNotFoundError as missing:
        raise EcosUnavailable(f"{missing.name} is not installed (a test dependency: pip install -e '.[test]')")
    program = next((f for f in ecos_files if f.parts[-2:] == ("binaries", "ecos")), None)
    tbb = next((f for f in tbb_files if f.name == "libtbb.so.12"), None)
    if program is None or tbb is None:
        raise EcosUnavailable("ecospy's binaries/ecos or tbb's libtbb.so.12 is missing from the installed wheels")
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
    if record is not None:
        options += ["--csvConfig", str(_csv_config(record, target.with_name(target.stem + "_CsvConfig.xml")))]
    done = subprocess.run([str(program), "simulate", "--path", str(target), "--stopTime", repr(stop),
                           "--stepSize", repr(step), "--logLevel", "info", *options],
                          env=environment, cwd=target.parent,
                          capture_output=True, text=True, timeout=timeout)
    log = done.stdout + done.stderr
    result = target.with_suffix(".csv")
    if done.returncode != 0 or not result.exists() or "[error]" in log:
        raise RuntimeError(f"ecos failed on {target.name} (exit {done.returncode}):\n{log[-4000:]}")
    # ecos's own progress lines ("90% complete, simulated 9.000s in 4.321s"): the last one,
    # scaled to the whole span (it logs no line at 100 %).
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


def write_result_csv(path: Path, times: np.ndarray, traces: dict[str, np.ndarray], names: list[str]) -> Path:
    """A CSV ``lever validate --result`` reads: time, then the named traces."""
    table = np.column_stack([times] + [traces[n] for n in names])
    np.savetxt(path, table, delimiter=",", header=",".join(["time", *names]), comments="", fmt="%.17g")
    return path


C_IMPORTER = ROOT / "tests" / "c_host" / "minimal_importer.c"
#: what the C importer sets and reads in each FMU it steps alone
C_IMPORTER_CASES = {"EngineShaft": ("tau", -100.0, "w"), "LoadShaft": ("tau", 120.0, "w"),
                    "LeverCoupling": ("phi1", 0.1, "tau1"), "MisalignmentSource": (None, None, "misalignment")}


def compile_c_importer(dest: Path) -> Path:
    """Compiles tests/c_host/minimal_importer.c to ``dest`` with ``$CC`` or cc."""
    cc = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if not cc:
        raise RuntimeError("no C compiler (cc) for the C importer")
    dest.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([cc, "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror", "-O2", "-o",
                    str(dest), str(C_IMPORTER), "-ldl", "-pthread"], check=True)
    return dest


def run_c_importer(program: Path, unzipped: Path, model: str, steps: int, step: float, env: dict,
                   guid: str | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """The C importer on an unzipped FMU: ``C_IMPORTER_CASES[model]``'s input set, ``steps``
    steps of ``step``; what it printed and its exit status."""
    from fmpy import read_model_description

    md = read_model_description(str(unzipped / "modelDescription.xml"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    name_in, value, name_out = C_IMPORTER_CASES[model]
    return subprocess.run([str(program), str(unzipped), md.coSimulation.modelIdentifier, guid or md.guid,
                           str(vr[name_in]) if name_in else "-", repr(value), str(vr[name_out]), repr(step),
                           str(steps)], env=env, capture_output=True, text=True, timeout=timeout)


def _c_importer_time(scene: scenes.Scene, step: float, fmu_dir: Path, scratch: Path, env: dict | None) -> float:
    from fmpy import extract

    program = scratch / "bin" / "minimal_importer"
    if not program.exists():
        compile_c_importer(program)
    steps = round((scene.experiment.stop - scene.experiment.start) / step)
    total = 0.0
    for model in sorted({c.fmu for c in scene.components.values()}):
        unzipped = scratch / "unzipped" / model
        if not unzipped.exists():
            extract(str(fmu_dir / f"{model}.fmu"), str(unzipped))
        done = run_c_importer(program, unzipped, model, steps, step, BARE_ENVIRONMENT if env is None else env,
                              timeout=600)
        loop = re.search(r"^loop_s=([0-9.]+)$", done.stderr, re.M)
        if done.returncode != 0 or not loop:
            raise RuntimeError(f"the C importer failed on {model} (exit {done.returncode}):\n{done.stderr[-2000:]}")
        total += float(loop.group(1))
    return total


def time_hosts(scene: scenes.Scene, step: float, repeats: int, fmu_dir: Path = FMUS,
               hosts=HOSTS, native_env: dict | None = None, log=print) -> dict:
    """Median stepping-loop time of each host over ``repeats`` runs, and its ratio to the
    first host's (our harness's jacobi by default).  The hosts that are no Python process
    (ecos, the C importer) run in ``native_env`` (default bare)."""
    times: dict[str, list[float]] = {h: [] for h in hosts}
    with tempfile.TemporaryDirectory(prefix="lever-hosts-") as scratch:
        scratch = Path(scratch)
        archive = ssp.export(scene, scratch / f"{scene.name}.ssp", fmu_dir) \
            if {"ecos", "ecos-serial", "ecos-log-all"} & set(hosts) else None
        for k in range(repeats):
            for host in hosts:
                if host == "harness-jacobi":
                    result = simulate(scene, "jacobi", step, fmu_dir)
                    ok, wall = result.ok, result.wall_time
                elif host == "libcosim-fixed":
                    result = peers.simulate_peer("libcosim-fixed", scene, step, fmu_dir)
                    ok, wall = result.ok, result.wall_time
                elif host in ("ecos", "ecos-serial", "ecos-log-all"):
                    wall = run_ecos(archive, scene.experiment.stop, step, scratch / "bin", native_env,
                                    parallel=host != "ecos-serial",
                                    record=None if host == "ecos-log-all" else list(scene.record)).wall_time
                    ok = True
                elif host == "c-importer":
                    wall, ok = _c_importer_time(scene, step, fmu_dir, scratch, native_env), True
                else:
                    raise ValueError(f"unknown host '{host}' (known: {', '.join(HOSTS)})")
                if not ok:
                    raise RuntimeError(f"{host} failed: {result.failure}")
                times[host].append(wall)
                log(f"  run {k + 1}/{repeats} {host}: {wall:.3f} s")
    base = statistics.median(times[hosts[0]])
    return {"scene": scene.name, "stop": scene.experiment.stop, "step": step, "repeats": repeats,
            "hosts": {h: {"median_s": statistics.median(t), "runs_s": t,
                          "ratio": statistics.median(t) / base} for h, t in times.items()}}


def table(report: dict) -> str:
    lines = [f"{report['scene']}: {report['stop']:g} s at {report['step'] * 1e3:g} ms, "
             f"medians of {report['repeats']} runs",
             "", "| host | wall time (median) | vs harness-jacobi |", "|---|---|---|"]
    for host, row in report["hosts"].items():
        lines.append(f"| {host} | {row['median_s']:.3f} s | {row['ratio']:.2f}x |")
    return "\n".join(lines) + "\n"


def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "hosts" / scene.name
