"""Peers: the same scene run by other co-simulation engines, for benchmarks.

Each peer loads the scene's FMUs as they are, applies the scene's parameters and
connections, and returns a ``harness.engine.run.RunResult`` like the harness's own masters:
traces keyed ``component.variable`` (Real variables), one row per communication point
from start to stop, and a failed run keeps the rows recorded before the failure.

* ``fmpy-jacobi`` - the plain baseline: a fixed-step Jacobi loop written on fmpy's
  high-level ``FMU2Slave`` API (``getReal``/``setReal``/``doStep``, one Python call
  each), as an fmpy user would write it.  Same algorithm as the harness's ``jacobi``
  (after every step, outputs are propagated in dependency order, so the coupling's
  torques are those of the shafts' new states) without the harness's raw ctypes calls.
  fmpy's own multi-FMU stepper, ``fmpy.ssp.simulate_ssp`` (fmpy 0.3.x), is the peer
  ``fmpy-ssp`` below, with care: it cannot set String parameters (``transfer_mode``, ``load_kind``: "Unsupported type:
  String"), ignores the SSD's parameter bindings (only a ``parameter_set`` argument is
  applied), starts every connected input at 0.0 instead of propagating the initial
  outputs, and labels each row with the start time of the step that produced it.
* ``fmpy-ssp`` - fmpy's own multi-FMU stepper, ``fmpy.ssp.simulate_ssp``, on the scene
  exported as an SSP archive (``harness.formats.ssp``), as an fmpy user runs an SSP.  Its
  limitations (above) are worked around where that is honest and refused where not: the
  parameters are the archive's qualified set (``harness.formats.ssp.QUALIFIED_SET``) passed
  as its ``parameter_set``; a String parameter that differs from the FMU's default is refused
  (it cannot be set); the zero start of the connected inputs stays (the first step sees
  no torque); rows are labelled with the end of the step that produced them.  Each
  component's outputs are read right after its own ``doStep``, so the coupling's torques
  lag one step as under libcosim.  Its wall time includes unpacking and instantiating
  the FMUs (``simulate_ssp`` does everything in one call).
* ``libcosim-fixed`` - OSP libcosim (PyPI ``libcosimpy``) with its fixed-step
  algorithm.  libcosim reads a slave's outputs right after its ``doStep`` and sets its
  inputs just before the next one, so an output with direct feedthrough (the coupling's
  torques) is computed from the inputs of the step before: the shafts see the torque
  of the states one step older than under the harness's ``jacobi``.
* ``libcosim-ecco`` - libcosim's ECCO algorithm: the same step, with the step size
  controlled by the power residual of power bonds (Sadjina and Pedersen 2020).
  libcosim 0.11 only adapts the step; it applies no energy correction.  The bonds are
  found from the units of the connected variables: a speed (rad/s) one way and a
  torque (N.m) the other way between two components.  Its communication points are
  irregular, and the last one may pass the stop time by less than a step (libcosim does
  not shorten the last step).

* ``ecos`` - the C++ engine ecos (PyPI ``ecospy``, ``harness.formats.ecos``): its
  command-line program on the scene's SSP export in a bare environment, stepping the FMUs
  in parallel threads (its default) and logging what the harness records; its wall time
  is its own stepping loop's (from its progress log).

* ``libcosim-ssp`` - ``libcosim-fixed`` with the scene loaded from its SSP export
  (``CosimExecution.from_ssp_file``: libcosim reads the components, connections and
  parameter sets itself).
* ``libcosim-osp`` - ``libcosim-fixed`` with the scene loaded from an
  ``OspSystemStructure.xml`` whose connections go flange to flange
  (``VariableGroupConnection`` between the FMUs' OSP ports, ``harness.formats.osp``).

ECCO's power bonds come from the OSP model descriptions next to the FMUs (each connected
``AngularMechanicalPort`` pair is a bond); for FMUs without one, from the units.

The libcosim peers run in a child process (see ``_CHILD``).  libcosim steps the FMUs on
a worker thread, and pythonfmu then creates and destroys a Python thread state on every
FMI call (``PyGILState_Ensure`` on a thread Python does not know): part of what
libcosim's wall time measures with these FMUs.

``wall_time`` runs from applying the parameters to the last communication point:
initialisation, stepping and recording; loading and instantiating the FMUs (and
starting the child process) are left out, as ``harness.engine.run.simulate`` times it.
Loading or wiring failures raise (as the harness's instantiation failures do);
failures while initialising or stepping are reported in ``RunResult.failure``.
"""
from __future__ import annotations

import ctypes
import math
import os
import pickle
import signal
import subprocess
import sys
import tempfile
import time as clock
from collections import deque
from pathlib import Path

import numpy as np

from harness.engine import component as harness_component
from harness.description import scene as scenes
from harness.description import typed_values
from harness.description.scene import step_problem
from harness.paths import CODE, FMUS
from harness.engine.run import RunResult, recorded_names
from harness.engine.system import SceneInvalid, dependency_order, descriptions_for, feedthrough_components, fmu_path

PEERS = {
    "fmpy-jacobi": "fixed-step Jacobi on fmpy's FMU2Slave API (getReal/setReal/doStep per call)",
    "fmpy-ssp": "fmpy.ssp.simulate_ssp on the scene's SSP export; inputs start at 0, feedthrough outputs lag one step",
    "libcosim-fixed": "OSP libcosim fixed-step algorithm (libcosimpy); feedthrough outputs lag one step",
    "libcosim-ssp": "OSP libcosim fixed step on the scene's SSP export (CosimExecution.from_ssp_file)",
    "libcosim-osp": "OSP libcosim fixed step on an OspSystemStructure.xml connecting the FMUs' OSP ports",
    "libcosim-ecco": "OSP libcosim ECCO: step size controlled by the power residual at the coupling's bonds",
    "ecos": "the C++ engine ecos (ecospy's program) on the scene's SSP export, FMUs in parallel threads",
}

LIBCOSIMPY_PIN = "libcosimpy==0.0.6"

#: libcosim counts time in nanoseconds.
_NS = 1_000_000_000

#: ECCO's step range relative to the scene's step (its first step is the scene's step).
ECCO_MIN_STEP_RATIO = 0.1
ECCO_MAX_STEP_RATIO = 20.0
#: ECCO's step controller as in libcosim's own ECCO test.  Not libcosimpy's EccoParams
#: defaults: their max_change_rate = 0.2 caps the step's growth factor at 0.2, so the
#: step only ever shrinks (to min_step_size after the second step).
ECCO_CONTROLLER = dict(safety_factor=0.99, min_change_rate=0.2, max_change_rate=1.5, p_gain=0.2, i_gain=0.15)
#: ECCO's absolute (J) and relative tolerance on the energy residual of a step when
#: none is given: libcosimpy's default.
ECCO_TOLERANCE = 1e-4

#: Units that make a power bond: a flow one way, an effort the other way.
FLOW_UNITS = ("rad/s",)
EFFORT_UNITS = ("N.m",)


def available(name: str) -> str | None:
    """None if peer ``name`` can run here, else why not."""
    if name not in PEERS:
        return f"unknown peer '{name}' (known: {', '.join(PEERS)})"
    if name == "fmpy-jacobi":
        return None
    if name == "fmpy-ssp":
        try:
            from fmpy.ssp.simulation import simulate_ssp  # noqa: F401
        except ImportError as error:
            return f"fmpy.ssp does not import: {error}"
        return None
    if name == "ecos":
        from harness.formats import ecos
        return ecos.unavailable()
    try:
        from libcosimpy._internal import libcosimc
        library = libcosimc()
    except ImportError:
        return f"libcosimpy not installed (pip install {LIBCOSIMPY_PIN})"
    except OSError as error:
        return f"libcosimpy is installed but its libcosimc library does not load: {error}"
    if name == "libcosim-ecco":
        try:
            from libcosimpy import CosimAlgorithm as algorithms
        except ImportError:
            algorithms = None
        if not (hasattr(algorithms, "EccoParams") and hasattr(library, "cosim_ecco_add_power_bond")):
            return "this libcosimpy has no ECCO algorithm (CosimAlgorithm.EccoParams, cosim_ecco_add_power_bond)"
    return None


def simulate_peer(name: str, scene: scenes.Scene, step: float, fmu_dir: Path = FMUS,
                  record: list[str] | None = None, tolerance: float | None = None) -> RunResult:
    """Run ``scene`` with peer ``name`` at communication step ``step`` (ECCO: its first
    step), recording ``record`` (default: what the harness records).  ``tolerance`` is
    ECCO's absolute and relative tolerance on the energy residual; the fixed-step peers
    ignore it.  Raises ``ValueError`` for an unknown or unavailable peer or a scene the
    peer cannot run, ``SceneInvalid`` for a scene the FMUs cannot run, and
    ``LibcosimError`` when libcosim cannot load or wire the FMUs."""
    reason = available(name)
    if reason:
        raise ValueError(f"peer '{name}' is not available: {reason}")
    if problem := step_problem(step, "communication step"):
        raise ValueError(problem)
    names = list(recorded_names(scene) if record is None else record)
    setup = _SceneSetup(scene, Path(fmu_dir), names)
    if name == "fmpy-jacobi":
        result = _simulate_fmpy_jacobi(setup, float(step))
    elif name == "fmpy-ssp":
        result = _simulate_fmpy_ssp(setup, float(step))
    elif name == "ecos":
        result = _simulate_ecos(scene, float(step), Path(fmu_dir), names)
    else:
        result = _simulate_libcosim_in_child(setup, float(step), name,
                                             tolerance=ECCO_TOLERANCE if tolerance is None else float(tolerance))
    return refuse_other_experiment(result, name, scene, float(step))


#: peers whose step varies (their number of steps is theirs to choose)
ADAPTIVE_PEERS = ("libcosim-ecco",)
#: peers that record no row at the start time: their first row is after the first step
PEERS_FROM_FIRST_STEP = ("fmpy-ssp",)


def experiment_problem(times, scene: scenes.Scene, step: float, fixed_step: bool = True,
                       from_first_step: bool = False) -> str | None:
    """What a run's communication points ``times`` show of an experiment other than the
    scene's: another start, another stop, another number of steps of ``step`` (a fixed-step
    run).  ``from_first_step``: the run records no row at the start time.  None when it ran
    the scene's experiment."""
    e = scene.experiment
    if len(times) == 0:
        return None
    # the peers write times to six decimals or more; a thousandth of a step tells a missing step
    slack = max(1e-9 * max(1.0, abs(e.stop)), 1e-3 * step)
    wanted = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
    made = len(times) - (0 if from_first_step else 1)
    first = e.start + step if from_first_step else e.start
    problems = []
    if abs(times[0] - first) > slack:
        problems.append(f"started at t = {times[0]:.9g} s, not {e.start:g} s"
                        + (f" + one step ({first:g} s: it records no row at the start)" if from_first_step else ""))
    if fixed_step and made != wanted:
        problems.append(f"made {made} steps of {step:g} s, not the {wanted} from {e.start:g} to {e.stop:g} s")
    if (abs(times[-1] - e.stop) > slack) if fixed_step else (times[-1] < e.stop - slack):
        problems.append(f"stopped at t = {times[-1]:.9g} s, not {e.stop:g} s")
    return "; ".join(problems) or None


def refuse_other_experiment(result: RunResult, name: str, scene: scenes.Scene, step: float) -> RunResult:
    """A peer's run that did not run the scene's experiment (``experiment_problem``) is
    refused: its errors and run time would compare another experiment with ours."""
    if result.ok:
        problem = experiment_problem(result.times, scene, step, fixed_step=name not in ADAPTIVE_PEERS,
                                     from_first_step=name in PEERS_FROM_FIRST_STEP)
        if problem:
            result.failure = f"refused: peer {name} {problem}"
            result.failure_stage = "stepping"
    return result


class _SceneSetup:
    """What every peer needs from the scene: model variables by component, parameter
    values in SI, the components in dependency order, what to record."""

    def __init__(self, scene: scenes.Scene, fmu_dir: Path, record: list[str]):
        descriptions = descriptions_for(scene, fmu_dir)
        findings = scenes.validate(scene, descriptions)
        for item in record:
            comp, _, var = item.partition(".")
            spec = scene.components.get(comp)
            if spec is None:
                findings.append(f"record '{item}': no component '{comp}'")
            elif spec.fmu in descriptions:
                variable = next((v for v in descriptions[spec.fmu].modelVariables if v.name == var), None)
                if variable is None:
                    findings.append(f"record '{item}': {comp} has no variable '{var}'")
                elif variable.type != "Real":
                    findings.append(f"record '{item}': peers record Real variables only, not {variable.type}")
        if findings:
            raise SceneInvalid(scene.name, findings)
        self.scene = scene
        self.fmu_dir = fmu_dir
        self.record = record
        self.fmu_paths = {name: fmu_path(spec.fmu, fmu_dir) for name, spec in scene.components.items()}
        self.descriptions = {name: descriptions[spec.fmu] for name, spec in scene.components.items()}
        self.variables = {name: {v.name: v for v in md.modelVariables} for name, md in self.descriptions.items()}
        self.parameters = {name: {k: scenes.quantity(v, f"{name}.{k}") for k, v in spec.parameters.items()}
                           for name, spec in scene.components.items()}
        # The order the harness propagates in.
        self.order = dependency_order(scene, feedthrough_components(scene, self.descriptions))

    def vr(self, component: str, variable: str) -> int:
        return self.variables[component][variable].valueReference

    def time_grid(self, step: float) -> np.ndarray:
        """The fixed-step communication points, as ``harness.engine.run.simulate`` steps them."""
        e = self.scene.experiment
        n_steps = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
        return np.minimum(e.start + step * np.arange(n_steps + 1), e.stop)

    def power_bonds(self) -> list[tuple[str, str, str, str, str, str]]:
        """``(a, a_effort_input, a_flow_output, b, b_effort_output, b_flow_input)`` for
        each pair of components joined by a flow one way and an effort the other way:
        the connected ports of the OSP model descriptions, or (FMUs without one) a
        flow unit one way and an effort unit back."""
        from harness.formats import osp

        groups = osp.scene_groups(self.scene, self.fmu_dir)
        if any(groups.values()):
            return osp.power_bonds(self.scene, groups)

        def unit(comp, var):
            return self.variables[comp][var].unit

        bonds = []
        for flow in self.scene.connections:
            if unit(flow.source, flow.output) not in FLOW_UNITS:
                continue
            for effort in self.scene.connections:
                if (effort.source, effort.target) == (flow.target, flow.source) \
                        and unit(effort.source, effort.output) in EFFORT_UNITS:
                    bonds.append((flow.source, effort.input, flow.output, flow.target, effort.output, flow.input))
        return bonds


# -- fmpy-jacobi ------------------------------------------------------------------------------

def _simulate_fmpy_jacobi(setup: _SceneSetup, step: float) -> RunResult:
    from fmpy.fmi2 import FMU2Slave

    scene, e = setup.scene, setup.scene.experiment
    grid = setup.time_grid(step)
    # Each component's outputs are read with one getReal per step: the connected ones,
    # then the recorded ones; each connection is one setReal.
    reads = {name: [] for name in setup.order}
    for item in [f"{c.source}.{c.output}" for c in scene.connections] + setup.record:
        comp, _, var = item.partition(".")
        if var not in reads[comp]:
            reads[comp].append(var)
    read_vrs = {name: [setup.vr(name, var) for var in names] for name, names in reads.items()}
    position = {(name, var): i for name, names in reads.items() for i, var in enumerate(names)}
    transfers = {name: [(c.target, setup.vr(c.target, c.input), position[(name, c.output)])
                        for c in scene.connections if c.source == name] for name in setup.order}
    recorded = [(item.partition(".")[0], position[tuple(item.split(".", 1))]) for item in setup.record]

    slaves: dict[str, FMU2Slave] = {}
    unzipped: list[str] = []
    messages: deque[str] = deque(maxlen=5)
    values: dict[str, list[float]] = {}
    rows: list[list[float]] = []
    n_steps = 0
    failure = stage = None
    finished = False       # every step taken: fmi2Terminate allowed (FMI 2.0: not after an error or before stepping)

    def propagate():
        for name in setup.order:
            values[name] = slaves[name].getReal(read_vrs[name]) if read_vrs[name] else []
            for target, vr, i in transfers[name]:
                slaves[target].setReal([vr], [values[name][i]])

    def record_row(t: float):
        row = [values[comp][i] for comp, i in recorded]
        rows.append(row)
        if not all(math.isfinite(x) for x in row):
            bad = [item for item, x in zip(setup.record, row) if not math.isfinite(x)]
            raise FloatingPointError(f"non-finite value of {', '.join(bad)} at t = {t:.6g} s")

    try:
        for name in setup.order:
            md = setup.descriptions[name]
            unzipped.append(harness_component.unzipped(setup.fmu_paths[name]))   # shared: see there
            instance = f"{name}@fmpy-jacobi"
            # The harness's process-wide logger routes messages by instance name: keep
            # this peer's, to say in a failure what the FMU said.
            harness_component.route_messages(instance, messages)
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped[-1],
                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName=instance)
            fmu.instantiate(callbacks=harness_component.log_callbacks())
            slaves[name] = fmu

        started = clock.perf_counter()
        try:
            stage = "initialisation"
            for name, fmu in slaves.items():
                for param, value in setup.parameters[name].items():
                    typed_values.set_on(fmu, setup.variables[name][param], value, f"{name}.{param}")
                fmu.setupExperiment(startTime=e.start, stopTime=e.stop)
                fmu.enterInitializationMode()
            propagate()
            for fmu in slaves.values():
                fmu.exitInitializationMode()
            propagate()
            record_row(grid[0])
            stage = "stepping"
            for n in range(1, len(grid)):
                t, h = grid[n - 1], grid[n] - grid[n - 1]
                for fmu in slaves.values():
                    fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                propagate()
                n_steps += 1
                record_row(grid[n])
            finished = True
        except Exception as error:  # noqa: BLE001 - whatever fails ends the run, keeping its rows
            said = [m for m in messages if not m.startswith("[ok]")]
            failure = (f"{type(error).__name__}: {error}" + ("; FMU said: " + " | ".join(said) if said else "")
                       + f" (peer fmpy-jacobi, step {step:g} s, after {n_steps} steps)")
        wall = clock.perf_counter() - started
    finally:
        for name, fmu in slaves.items():
            if finished:
                try:
                    fmu.terminate()
                except Exception:  # noqa: BLE001 - freeing must go on after a refused terminate
                    pass
            fmu.freeInstance()
        for name in setup.order:
            harness_component.unroute(f"{name}@fmpy-jacobi")
    table = np.array(rows, dtype=float).reshape(len(rows), len(setup.record))
    traces = {item: table[:, k].copy() for k, item in enumerate(setup.record)}
    return RunResult(scene, "fmpy-jacobi", step, grid[:len(rows)].copy(), traces, wall,
                     {"steps": n_steps}, failure, stage if failure else None)


# -- fmpy-ssp ---------------------------------------------------------------------------------

def _simulate_fmpy_ssp(setup: _SceneSetup, step: float) -> RunResult:
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    from harness.formats import ssp

    scene, e = setup.scene, setup.scene.experiment
    refused = []
    for comp, values in setup.parameters.items():
        for name, value in values.items():
            var = setup.variables[comp][name]
            if var.type == "String" and str(value) != (var.start or ""):
                refused.append(f"{comp}.{name} = {value!r} (the FMU's default is {var.start!r})")
    if refused:
        raise ValueError("fmpy-ssp: fmpy.ssp cannot set String parameters, and the scene sets "
                         + ", ".join(refused))
    for item in setup.record:
        comp, _, var = item.partition(".")
        if setup.variables[comp][var].causality not in ("input", "output"):
            raise ValueError(f"fmpy-ssp: fmpy.ssp records connectors only; {item} is a "
                             f"{setup.variables[comp][var].causality}")
    failure = None
    with tempfile.TemporaryDirectory(prefix="lever-fmpy-ssp-") as scratch:
        archive = ssp.export(scene, Path(scratch) / f"{scene.name}.ssp", setup.fmu_dir)
        # as an fmpy user runs our export: the values from its qualified set, the one form
        # simulate_ssp applies
        values = read_ssv(str(archive), resource=ssp.QUALIFIED_SET)
        started = clock.perf_counter()
        try:
            table = simulate_ssp(str(archive), start_time=e.start, stop_time=e.stop, step_size=step,
                                 parameter_set=values)
        except Exception as error:  # noqa: BLE001 - simulate_ssp keeps nothing of a failed run
            table = None
            failure = f"{type(error).__name__}: {error} (peer fmpy-ssp, step {step:g} s)"
        wall = clock.perf_counter() - started
    if table is None:
        return RunResult(scene, "fmpy-ssp", step, np.empty(0), {n: np.empty(0) for n in setup.record}, wall,
                         {}, failure, "stepping")
    # Row k holds the values after step k; simulate_ssp labels it with the step's start.
    times = np.asarray(table["time"], dtype=float) + step
    keep = times <= e.stop + 1e-9 * max(1.0, abs(e.stop))
    traces = {item: np.asarray(table[item], dtype=float)[keep] for item in setup.record}
    times = times[keep]
    bad = _first_non_finite(times, traces)
    if bad is not None:
        times, traces = times[:bad[0] + 1], {n: v[:bad[0] + 1] for n, v in traces.items()}
        failure = f"{bad[1]} (peer fmpy-ssp, step {step:g} s)"
    return RunResult(scene, "fmpy-ssp", step, times, traces, wall, {"steps": len(times)}, failure,
                     "stepping" if failure else None)


# -- libcosim ---------------------------------------------------------------------------------

def _simulate_ecos(scene: scenes.Scene, step: float, fmu_dir: Path, names: list[str]) -> RunResult:
    """ecos's program on the scene's SSP export (``harness.formats.ecos``), in a bare
    environment, logging ``names``; its wall time is its own stepping loop's."""
    from harness.formats import ecos, ssp

    e = scene.experiment
    if e.start != 0.0:
        raise ValueError(f"peer 'ecos' simulates from t = 0 only; scene '{scene.name}' starts at {e.start:g} s")
    with tempfile.TemporaryDirectory(prefix="lever-ecos-") as scratch:
        scratch = Path(scratch)
        archive = ssp.export(scene, scratch / f"{scene.name}.ssp", fmu_dir)
        try:
            run = ecos.run_ecos(archive, e.stop, step, scratch / "bin", record=names)
        except RuntimeError as error:
            return RunResult(scene, "ecos", step, np.empty(0), {n: np.empty(0) for n in names}, math.nan, {},
                             str(error), "stepping")
        times, traces = ecos.ecos_traces(run.csv)
    missing = [n for n in names if n not in traces]
    if missing:
        raise ValueError(f"peer 'ecos' logged no {', '.join(missing)}")
    return RunResult(scene, "ecos", step, times, {n: traces[n] for n in names}, run.wall_time, {})


class LibcosimError(RuntimeError):
    pass


def _check(result, what: str):
    """libcosimpy answers True/False or an index/status that is negative on failure."""
    from libcosimpy._internal import get_last_error_message
    if result is False or (not isinstance(result, bool) and result < 0):
        raise LibcosimError(f"{what}: {get_last_error_message()}")


def _libcosim_preflight(setup: _SceneSetup, peer: str):
    """Raise ``ValueError`` for a scene this libcosim peer cannot run."""
    scene = setup.scene
    if scene.experiment.start != 0.0:
        raise ValueError(f"{peer}: libcosimpy creates executions at t = 0 only; scene {scene.name} starts at "
                         f"{scene.experiment.start} s")
    if peer == "libcosim-ecco" and not setup.power_bonds():
        raise ValueError(f"{peer}: no power bonds in scene {scene.name} (a {'/'.join(FLOW_UNITS)} connection one "
                         f"way and a {'/'.join(EFFORT_UNITS)} connection back between two components)")


# libcosim runs in a child process: libcosim 0.11 lets an exception escape its worker
# threads while initialising (std::terminate: an FMU refusing a parameter aborts the
# whole process), and pythonfmu FMUs can corrupt the heap at interpreter exit.
_CHILD = "import sys; sys.path.insert(0, sys.argv[1]); from harness.formats.peers import _libcosim_child; " \
         "_libcosim_child(sys.argv[2], sys.argv[3])"


def _simulate_libcosim_in_child(setup: _SceneSetup, step: float, peer: str, tolerance: float) -> RunResult:
    _libcosim_preflight(setup, peer)
    with tempfile.TemporaryDirectory(prefix="lever-peer-") as scratch:
        request, answer = Path(scratch) / "request.pickle", Path(scratch) / "answer.pickle"
        request.write_bytes(pickle.dumps(dict(scene=setup.scene, fmu_dir=str(setup.fmu_dir), record=setup.record,
                                              step=step, peer=peer, tolerance=tolerance)))
        # libcosim unpacks the FMUs under TMPDIR: there, they go even if the child aborts.
        child = subprocess.run([sys.executable, "-c", _CHILD, str(CODE), str(request), str(answer)],
                               capture_output=True, text=True, errors="replace",
                               env=dict(os.environ, TMPDIR=scratch))
        outcome = pickle.loads(answer.read_bytes()) if answer.exists() else None
    if outcome is None:
        code = child.returncode
        how = f"exit code {code}"
        if code < 0:
            try:
                how = f"signal {signal.Signals(-code).name}"
            except ValueError:
                how = f"signal {-code}"
        said = [line.strip() for line in child.stderr.splitlines() if line.strip()][-3:]
        # libcosim reports FMU errors while stepping; only initialisation takes the process down.
        return RunResult(setup.scene, peer, step, np.empty(0), {n: np.empty(0) for n in setup.record}, 0.0, {},
                         f"libcosim ended the process ({how}): {' | '.join(said) or 'no message'} "
                         f"(peer {peer}, step {step:g} s, during initialisation)", "initialisation")
    if "exception" in outcome:
        raise LibcosimError(outcome["exception"])
    return RunResult(setup.scene, peer, step, outcome["times"], outcome["traces"], outcome["wall_time"],
                     outcome["counters"], outcome["failure"], outcome["failure_stage"])


def _libcosim_child(request_path: str, answer_path: str):
    """Entry point of the child process: run the request, pickle the outcome, and leave
    without Python's teardown."""
    request = pickle.loads(Path(request_path).read_bytes())
    try:
        setup = _SceneSetup(request["scene"], Path(request["fmu_dir"]), request["record"])
        outcome = _run_libcosim(setup, request["step"], request["peer"], request["tolerance"])
    except Exception as error:  # noqa: BLE001 - the parent raises it
        outcome = {"exception": f"{type(error).__name__}: {error}"}
    Path(answer_path).write_bytes(pickle.dumps(outcome))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _run_libcosim(setup: _SceneSetup, step: float, peer: str, tolerance: float) -> dict:
    """One libcosim run in this process: the fields of a ``RunResult`` as a dict."""
    from libcosimpy.CosimAlgorithm import CosimAlgorithm, EccoParams
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    scene, e = setup.scene, setup.scene.experiment
    _libcosim_preflight(setup, peer)
    ecco = peer == "libcosim-ecco"
    bonds = setup.power_bonds() if ecco else []
    log_output_level(CosimLogLevel.WARNING)   # libcosim logs every FMU load at INFO
    step_ns, stop_ns = round(step * _NS), round(e.stop * _NS)
    algorithm = None
    if ecco:
        params = EccoParams(step_size=step, min_step_size=step * ECCO_MIN_STEP_RATIO,
                            max_step_size=step * ECCO_MAX_STEP_RATIO,
                            abs_tolerance=tolerance, rel_tolerance=tolerance, **ECCO_CONTROLLER)
        algorithm = CosimAlgorithm.create_ecco_algorithm(params)
        execution = CosimExecution.from_algorithm(algorithm)
        most_samples = math.ceil(e.stop / params.min_step_size) + 2
    else:
        most_samples = math.ceil(stop_ns / step_ns) + 2
    from_file = peer in ("libcosim-ssp", "libcosim-osp")
    if not (ecco or from_file):
        execution = CosimExecution.from_step_size(step_ns)

    local_slaves = {}   # the Python wrappers free their C objects when collected
    index = {}
    if from_file:
        # libcosim builds the system itself: components, connections, parameter values.
        execution = _execution_from_file(setup, step, peer)
        for name in scene.components:
            index[name] = execution.slave_index_from_instance_name(name)
            if index[name] is None:
                raise LibcosimError(f"{peer}: libcosim loaded no component '{name}'")
    for name in ([] if from_file else scene.components):
        local_slaves[name] = CosimLocalSlave(fmu_path=str(setup.fmu_paths[name]), instance_name=name)
        if not local_slaves[name].ptr():
            _check(False, f"loading {setup.fmu_paths[name].name} as '{name}'")
        index[name] = execution.add_local_slave(local_slaves[name])
        _check(index[name], f"adding '{name}' to the execution")
    for c in ([] if from_file else scene.connections):
        _check(execution.connect_real_variables(index[c.source], setup.vr(c.source, c.output),
                                                index[c.target], setup.vr(c.target, c.input)), f"connecting {c}")
    for a, a_effort, a_flow, b, b_effort, b_flow in bonds:
        # libcosim multiplies each pair, so the order within a pair does not matter.
        _check(algorithm.add_power_bond(index[a], setup.vr(a, a_flow), setup.vr(a, a_effort),
                                        index[b], setup.vr(b, b_effort), setup.vr(b, b_flow)),
               f"power bond {a}.{a_effort}*{a_flow} = {b}.{b_effort}*{b_flow}")

    # A time-series observer reads only the variables it observes (a last-value observer
    # reads every variable of every FMU after each step).  ECCO reads its bonds' inputs
    # through the observer's exposure, so those are observed too.
    observer = CosimObserver.create_time_series(buffer_size=most_samples)
    _check(execution.add_observer(observer), "adding the observer")
    observed = [tuple(item.split(".", 1)) for item in setup.record]
    observed += [(comp, var) for a, a_effort, a_flow, b, b_effort, b_flow in bonds
                 for comp, var in ((a, a_effort), (a, a_flow), (b, b_effort), (b, b_flow))]
    for comp, var in dict.fromkeys(observed):
        _check(observer.start_time_series(index[comp], setup.vr(comp, var), CosimVariableType.REAL),
               f"observing {comp}.{var}")

    error = stage = None
    started = clock.perf_counter()
    try:
        stage = "initialisation"
        for name, values in ({} if from_file else setup.parameters).items():
            for param, value in values.items():
                var = setup.variables[name][param]
                # libcosim's real_initial_value, integer_initial_value, ...: one per FMI call type
                set_initial = getattr(execution, f"{typed_values.CALL_TYPE[var.type].lower()}_initial_value")
                _check(set_initial(index[name], var.valueReference, typed_values.typed(var, value, f"{name}.{param}")),
                       f"setting {name}.{param} = {value!r}")
        stage = "stepping"
        _check(execution.simulate_until(stop_ns), f"simulate_until({e.stop:g} s)")
    except LibcosimError as caught:
        error = " | ".join(line.strip() for line in str(caught).splitlines() if line.strip())
    wall = clock.perf_counter() - started

    times, traces = _observed_series(observer, index, setup, most_samples)
    if error is not None and len(times) == 0:
        stage = "initialisation"   # libcosim samples step 0 once initialisation has succeeded
    bad = _first_non_finite(times, traces)
    if error is None and bad is not None:
        keep = bad[0] + 1
        times, traces = times[:keep], {n: v[:keep] for n, v in traces.items()}
        error, stage = bad[1], "stepping"
    failure = None
    if error is not None:
        failure = (f"{error} (peer {peer}, step {step:g} s, "
                   + (f"after {len(times) - 1} steps)" if stage == "stepping" else "during initialisation)"))
    steps = np.diff(times)
    counters = {"steps": len(steps)}
    if ecco and len(steps):
        counters.update(min_step=float(steps.min()), max_step=float(steps.max()), mean_step=float(steps.mean()))
    # Free the execution (and with it the FMU instances) before the wrappers it uses.
    del execution, observer, algorithm, local_slaves
    return dict(times=times, traces=traces, wall_time=wall, counters=counters, failure=failure,
                failure_stage=stage if failure else None)


def _execution_from_file(setup: _SceneSetup, step: float, peer: str):
    """A libcosim execution built by libcosim from the scene written as an SSP archive
    or as an OspSystemStructure.xml (in this child's scratch folder, TMPDIR)."""
    from dataclasses import replace

    from libcosimpy.CosimExecution import CosimExecution

    from harness.formats import osp
    from harness.formats import ssp

    scene = replace(setup.scene, experiment=replace(setup.scene.experiment, step=step))
    folder = Path(tempfile.mkdtemp(prefix=f"{peer}-"))
    try:
        if peer == "libcosim-ssp":
            archive = ssp.export(scene, folder / f"{scene.name}.ssp", setup.fmu_dir)
            return CosimExecution.from_ssp_file(str(archive), round(step * _NS))
        config = folder / "OspSystemStructure.xml"
        config.write_text(osp.system_structure(scene, setup.fmu_dir))
        return CosimExecution.from_osp_config_file(str(config))
    except AssertionError as error:   # libcosimpy asserts on a failed creation
        raise LibcosimError(f"{peer}: {error}") from None


def _observed_series(observer, index: dict, setup: _SceneSetup, most_samples: int) -> tuple[np.ndarray, dict]:
    """The recorded samples from step 0 on, and their times.  Calls libcosimc directly:
    libcosimpy 0.0.6's ``time_series_real_samples`` trims as many samples as there are
    step numbers equal to 0, so it always drops the last one."""
    from libcosimpy._internal import libcosimc

    get_samples = libcosimc().cosim_observer_slave_get_real_samples
    get_samples.restype = ctypes.c_int64
    get_samples.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_uint32, ctypes.c_int64, ctypes.c_size_t,
                            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    observer_ptr = ctypes.cast(observer.ptr(), ctypes.c_void_p)
    times = None
    traces = {}
    for item in setup.record:
        comp, _, var = item.partition(".")
        values = np.empty(most_samples)
        step_numbers = np.empty(most_samples, dtype=np.int64)
        time_points = np.empty(most_samples, dtype=np.int64)
        count = get_samples(observer_ptr, index[comp], setup.vr(comp, var), 0, most_samples,
                            values.ctypes.data, step_numbers.ctypes.data, time_points.ctypes.data)
        count = max(int(count), 0)    # -1: nothing recorded (initialisation failed)
        traces[item] = values[:count]
        if times is None or count < len(times):
            times = time_points[:count] / _NS
    times = np.empty(0) if times is None else times
    return times, {item: v[:len(times)].copy() for item, v in traces.items()}


def _first_non_finite(times: np.ndarray, traces: dict[str, np.ndarray]) -> tuple[int, str] | None:
    """The first row with a non-finite value and the harness's message for it, or None."""
    if not traces or len(times) == 0:
        return None
    table = np.column_stack(list(traces.values()))
    bad_rows = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if len(bad_rows) == 0:
        return None
    i = int(bad_rows[0])
    bad = [name for k, name in enumerate(traces) if not math.isfinite(table[i, k])]
    return i, f"non-finite value of {', '.join(bad)} at t = {times[i]:.6g} s"
