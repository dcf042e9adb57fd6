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
progress line, "90% complete, simulated 9.000s in T s", scaled to the whole span), the median
[min-max] of ``repeats`` runs.  Every host runs once a round, round after round, and its ratio
to our harness is the median [min-max] of the ratios within each round
(``harness.studies.trust.paired_ratio``); the report states the machine's load average.  A
host whose output shows another experiment (another stop time or number of steps) is refused.

The hosts other than the C importer are peers of ``harness.peers`` (``harness-jacobi`` is its
``lever-jacobi``): each is timed by its own run's wall time.
"""
from __future__ import annotations

import os
import re
import shutil
import statistics
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from .. import peers
from ..peers import BARE_ENVIRONMENT
from . import trust
from ..description import scene as scenes
from ..paths import FMUS, RESULTS, ROOT


def set_up_environment() -> dict:
    """What a non-Python host needed before the FMUs found their Python themselves (and
    still may use): this interpreter's libpython preloaded, its home and site-packages."""
    import sys
    import sysconfig

    library = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    return {**BARE_ENVIRONMENT, "LD_PRELOAD": str(library), "PYTHONHOME": sys.base_prefix,
            "PYTHONPATH": sysconfig.get_paths()["purelib"], "PYTHONNOUSERSITE": "1"}


def write_result_csv(path: Path, times: np.ndarray, traces: dict[str, np.ndarray], names: list[str]) -> Path:
    """A CSV ``lever validate --result`` reads: time, then the named traces."""
    table = np.column_stack([times] + [traces[n] for n in names])
    np.savetxt(path, table, delimiter=",", header=",".join(["time", *names]), comments="", fmt="%.17g")
    return path


C_IMPORTER = ROOT / "tests" / "c_host" / "minimal_importer.c"
#: the FMI 2.0 declarations it shares with the FMUs' native entry (lever_fmi2_abi.h)
C_IMPORTER_INCLUDE = ROOT / "build" / "shim"
#: what the C importer sets and reads in each FMU it steps alone
C_IMPORTER_CASES = {"EngineShaft": ("tau", -100.0, "w"), "LoadShaft": ("tau", 120.0, "w"),
                    "LeverCoupling": ("phi1", 0.1, "tau1"), "MisalignmentSource": (None, None, "misalignment")}


def compile_c_importer(dest: Path) -> Path:
    """Compiles tests/c_host/minimal_importer.c (with build/shim's lever_fmi2_abi.h) to ``dest``
    with ``$CC`` or cc."""
    cc = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if not cc:
        raise RuntimeError("no C compiler (cc) for the C importer")
    dest.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([cc, "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror", "-O2",
                    "-I", str(C_IMPORTER_INCLUDE), "-o", str(dest), str(C_IMPORTER), "-ldl", "-pthread", "-lm"],
                   check=True)
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


class _Peer:
    """A host that is a peer of ``harness.peers``: the wall time of its run and its failure
    (None).  ``scene_record``: it records the scene's list only (not what the scene's
    features add)."""

    def __init__(self, peer: str, scene_record: bool = False):
        self.peer, self.scene_record = peer, scene_record

    def problem(self, scene: scenes.Scene, fmu_dir: Path) -> str | None:
        """What stops the peer from running the scene, said before anything runs."""
        return peers.problem(self.peer, scene, fmu_dir)

    def __call__(self, scene: scenes.Scene, step: float, fmu_dir: Path, scratch: Path,
                 env: dict | None) -> tuple[float, str | None]:
        result = peers.simulate_peer(self.peer, scene, step, fmu_dir,
                                     record=list(scene.record) if self.scene_record else None, environment=env)
        return result.wall_time, result.failure


class _CImporter:
    """Our C importer stepping each of the scene's FMUs alone (see the module docstring):
    the sum of its stepping loops."""

    def problem(self, scene: scenes.Scene, fmu_dir: Path) -> str | None:
        if scene.experiment.fmi != 2:
            return (f"host c-importer times the FMI 2.0 editions' stepping loop only; scene '{scene.name}' runs "
                    f"the FMI {scene.experiment.fmi}.0 editions")
        return None

    def __call__(self, scene: scenes.Scene, step: float, fmu_dir: Path, scratch: Path,
                 env: dict | None) -> tuple[float, None]:
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
                raise RuntimeError(f"the C importer failed on {model} (exit {done.returncode}):\n"
                                   f"{done.stderr[-2000:]}")
            total += float(loop.group(1))
        return total, None


#: each host, in the order a round runs them, and how it is timed: ecos logs the scene's
#: record (its ``--csvConfig``) or, ``ecos-log-all``, every variable
_TIMERS = {"harness-jacobi": _Peer("lever-jacobi"), "libcosim-fixed": _Peer("libcosim-fixed"),
           "ecos": _Peer("ecos", scene_record=True), "ecos-serial": _Peer("ecos-serial", scene_record=True),
           "ecos-log-all": _Peer("ecos-log-all", scene_record=True), "c-importer": _CImporter()}
HOSTS = tuple(_TIMERS)


def problems(scene: scenes.Scene, hosts, fmu_dir: Path = FMUS) -> list[str]:
    """Why any of ``hosts`` cannot run the scene (an FMI version it does not run, ...),
    each said in a sentence before anything runs."""
    return [said for host in hosts if (said := _TIMERS[host].problem(scene, fmu_dir))]


def time_hosts(scene: scenes.Scene, step: float, repeats: int, fmu_dir: Path = FMUS,
               hosts=HOSTS, native_env: dict | None = None, log=print) -> dict:
    """Median [min-max] stepping-loop time of each host over ``repeats`` rounds, and its
    ratio to the first host's (our harness's jacobi by default), round by round.  The hosts that are no Python process
    (ecos, the C importer) run in ``native_env`` (default bare)."""
    times: dict[str, list[float]] = {h: [] for h in hosts}
    load = trust.LoadLog()
    with tempfile.TemporaryDirectory(prefix="lever-hosts-") as scratch:
        scratch = Path(scratch)
        for k in range(repeats):
            load.sample()
            for host in hosts:
                if host not in _TIMERS:
                    raise ValueError(f"unknown host '{host}' (known: {', '.join(HOSTS)})")
                wall, failure = _TIMERS[host](scene, step, fmu_dir, scratch, native_env)
                if failure:
                    raise RuntimeError(f"{host} failed: {failure}")
                times[host].append(wall)
                log(f"  run {k + 1}/{repeats} {host}: {wall:.3f} s")
    load.sample()
    # each round ran every host in turn: the ratio to our harness is taken round by round
    return {"scene": scene.name, "stop": scene.experiment.stop, "step": step, "repeats": repeats,
            "machine": load.summary(),
            "hosts": {h: {"median_s": statistics.median(t), "runs_s": t, **_spread(t),
                          "ratio": trust.paired_ratio(t, times[hosts[0]])["median"],
                          "ratio_spread": trust.paired_ratio(t, times[hosts[0]])} for h, t in times.items()}}


def _spread(runs: list[float]) -> dict:
    s = trust.spread(runs)
    return {"min_s": s["min"], "max_s": s["max"]}


def table(report: dict) -> str:
    lines = [f"{report['scene']}: {report['stop']:g} s at {report['step'] * 1e3:g} ms, "
             f"medians [min-max] of {report['repeats']} runs; each ratio the median [min-max] of the ratios of "
             "runs made in the same round (every host in turn, round after round)",
             "", _machine(report.get("machine")), "",
             f"| host | wall time (median [min-max]) | vs {next(iter(report['hosts']))} |", "|---|---|---|"]
    for host, row in report["hosts"].items():
        wall = trust.spread_text({"median": row["median_s"], "min": row.get("min_s", row["median_s"]),
                                  "max": row.get("max_s", row["median_s"]), "n": len(row.get("runs_s", [1]))})
        ratio = trust.ratio_text(row["ratio_spread"]) if "ratio_spread" in row else f"{row['ratio']:.2f}x"
        lines.append(f"| {host} | {wall} | {ratio} |")
    return "\n".join(lines) + "\n"


def _machine(machine: dict | None) -> str:
    if not machine or machine.get("load_max") is None:
        return "Machine load not known."
    return (f"Machine: {machine['cpus']} CPUs, one-minute load average {machine['load_min']:.2f}-"
            f"{machine['load_max']:.2f} during the runs.")


def default_out(scene: scenes.Scene) -> Path:
    return RESULTS / "hosts" / scene.name
