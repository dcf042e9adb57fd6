"""OSP libcosim (PyPI ``libcosimpy``) as peers, one class per way of running it:

* ``libcosim-fixed`` - its fixed-step algorithm, the system built through the API.  libcosim
  reads a slave's outputs right after its ``doStep`` and sets its inputs just before the
  next one, so an output with direct feedthrough (the coupling's torques) is computed from
  the inputs of the step before: the shafts see the torque of the states one step older
  than under the harness's ``jacobi``.
* ``libcosim-ssp`` - the same with the scene loaded from its SSP export
  (``CosimExecution.from_ssp_file``: libcosim reads the components, connections and
  parameter sets itself).
* ``libcosim-osp`` - the same with the scene loaded from an ``OspSystemStructure.xml`` whose
  connections go flange to flange (``VariableGroupConnection`` between the FMUs' OSP ports,
  ``harness.formats.osp``).
* ``libcosim-ecco`` - libcosim's ECCO algorithm: the same step, with the step size
  controlled by the power residual of power bonds (Sadjina and Pedersen 2020).  libcosim
  0.11 only adapts the step; it applies no energy correction.  The bonds are the connected
  ``AngularMechanicalPort`` pairs of the OSP model descriptions next to the FMUs, or, for
  FMUs without one, found from the units of the connected variables: a speed (rad/s) one way
  and a torque (N.m) the other way between two components.  Its communication points are
  irregular, and the last one may pass the stop time by less than a step (libcosim does not
  shorten the last step).

Every libcosim run happens in a child process (``child_main``): libcosim 0.11 lets an
exception escape its worker threads while initialising (std::terminate: an FMU refusing a
parameter aborts the whole process), and pythonfmu FMUs can corrupt the heap at
interpreter exit.  libcosim steps the FMUs on a worker thread, and pythonfmu then creates
and destroys a Python thread state on every FMI call (``PyGILState_Ensure`` on a thread
Python does not know): part of what libcosim's wall time measures with these FMUs.
Loading and instantiating the FMUs and starting the child are not timed.
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
from abc import abstractmethod
from pathlib import Path

import numpy as np

from harness.description import typed_values
from harness.engine.run import RunResult
from harness.paths import CODE
from harness.peers.base import Peer, SceneSetup, first_non_finite

LIBCOSIMPY_PIN = "libcosimpy==0.0.6"

#: libcosim counts time in nanoseconds.
_NS = 1_000_000_000

#: Units that make a power bond: a flow one way, an effort the other way.
FLOW_UNITS = ("rad/s",)
EFFORT_UNITS = ("N.m",)


class LibcosimError(RuntimeError):
    pass


def _check(result, what: str):
    """libcosimpy answers True/False or an index/status that is negative on failure."""
    from libcosimpy._internal import get_last_error_message
    if result is False or (not isinstance(result, bool) and result < 0):
        raise LibcosimError(f"{what}: {get_last_error_message()}")


def _libcosimc():
    """(libcosimpy's libcosimc library, None) or (None, why it cannot be had)."""
    try:
        from libcosimpy._internal import libcosimc
        return libcosimc(), None
    except ImportError:
        return None, f"libcosimpy not installed (pip install {LIBCOSIMPY_PIN})"
    except OSError as error:
        return None, f"libcosimpy is installed but its libcosimc library does not load: {error}"


# libcosim runs in a child process (see the module's docstring): it reads its request from
# a file and writes its outcome to another.
_CHILD = "import sys; sys.path.insert(0, sys.argv[1]); from harness.peers.libcosim import child_main; " \
         "child_main(sys.argv[2], sys.argv[3])"


class LibcosimFixed(Peer):
    """libcosim's fixed-step algorithm, the system built through its API.  The other ways of
    running libcosim subclass it: how the execution is made (``make_execution``), whether
    libcosim builds the system itself (``builds_system``), the power bonds the algorithm
    needs (``bonds``), the counters of its steps (``step_counters``)."""

    name = "libcosim-fixed"
    summary = "OSP libcosim fixed-step algorithm (libcosimpy); feedthrough outputs lag one step"
    fmi_limit = ("libcosim (libcosimpy 0.0.6) imports FMI 1.0 and 2.0 FMUs only: its importer knows no other "
                 "fmiVersion and refuses the FMU ('Unsupported FMI version')")
    #: libcosim builds the components, connections and parameter values from a file itself
    builds_system = False

    def unavailable(self) -> str | None:
        return _libcosimc()[1]

    def scene_problem(self, setup: SceneSetup) -> str | None:
        scene = setup.scene
        if scene.experiment.start != 0.0:
            return (f"{self.name}: libcosimpy creates executions at t = 0 only; scene {scene.name} starts at "
                    f"{scene.experiment.start} s")
        return None

    def bonds(self, setup: SceneSetup) -> list[tuple[str, str, str, str, str, str]]:
        """The power bonds the algorithm is told of (``power_bonds``' form): none."""
        return []

    def make_execution(self, setup: SceneSetup, step: float, tolerance: float | None):
        """``(execution, algorithm or None, the most samples a series can hold)``."""
        from libcosimpy.CosimExecution import CosimExecution

        return CosimExecution.from_step_size(round(step * _NS)), None, _fixed_samples(setup, step)

    def step_counters(self, steps: np.ndarray) -> dict:
        return {"steps": len(steps)}

    # -- in this process: start the child and read its outcome --------------------------------
    def run(self, setup: SceneSetup, step: float, tolerance: float | None, environment: dict | None) -> RunResult:
        with tempfile.TemporaryDirectory(prefix="lever-peer-") as scratch:
            request, answer = Path(scratch) / "request.pickle", Path(scratch) / "answer.pickle"
            request.write_bytes(pickle.dumps(dict(peer=self, scene=setup.scene, fmu_dir=str(setup.fmu_dir),
                                                  record=setup.record, step=step, tolerance=tolerance)))
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
            return setup.nothing_run(self.name, step, 0.0,
                                     f"libcosim ended the process ({how}): {' | '.join(said) or 'no message'} "
                                     f"(peer {self.name}, step {step:g} s, during initialisation)", "initialisation")
        if "exception" in outcome:
            raise LibcosimError(outcome["exception"])
        return RunResult(setup.scene, self.name, step, outcome["times"], outcome["traces"], outcome["wall_time"],
                         outcome["counters"], outcome["failure"], outcome["failure_stage"])

    # -- in the child --------------------------------------------------------------------------
    def run_here(self, setup: SceneSetup, step: float, tolerance: float | None) -> dict:
        """One libcosim run in this process: the fields of a ``RunResult`` as a dict."""
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimSlave import CosimLocalSlave

        scene, e = setup.scene, setup.scene.experiment
        bonds = self.bonds(setup)
        log_output_level(CosimLogLevel.WARNING)   # libcosim logs every FMU load at INFO
        execution, algorithm, most_samples = self.make_execution(setup, step, tolerance)

        local_slaves = {}   # the Python wrappers free their C objects when collected
        index = {}
        if self.builds_system:
            for name in scene.components:
                index[name] = execution.slave_index_from_instance_name(name)
                if index[name] is None:
                    raise LibcosimError(f"{self.name}: libcosim loaded no component '{name}'")
        else:
            for name in scene.components:
                local_slaves[name] = CosimLocalSlave(fmu_path=str(setup.fmu_paths[name]), instance_name=name)
                if not local_slaves[name].ptr():
                    _check(False, f"loading {setup.fmu_paths[name].name} as '{name}'")
                index[name] = execution.add_local_slave(local_slaves[name])
                _check(index[name], f"adding '{name}' to the execution")
            for c in scene.connections:
                _check(execution.connect_real_variables(index[c.source], setup.vr(c.source, c.output),
                                                        index[c.target], setup.vr(c.target, c.input)),
                       f"connecting {c}")
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
            for name, values in ({} if self.builds_system else setup.parameters).items():
                for param, value in values.items():
                    var = setup.variables[name][param]
                    # libcosim's real_initial_value, integer_initial_value, ...: one per FMI call type
                    set_initial = getattr(execution, f"{typed_values.CALL_TYPE[var.type].lower()}_initial_value")
                    _check(set_initial(index[name], var.valueReference,
                                       typed_values.typed(var, value, f"{name}.{param}")),
                           f"setting {name}.{param} = {value!r}")
            stage = "stepping"
            _check(execution.simulate_until(round(e.stop * _NS)), f"simulate_until({e.stop:g} s)")
        except LibcosimError as caught:
            error = " | ".join(line.strip() for line in str(caught).splitlines() if line.strip())
        wall = clock.perf_counter() - started

        times, traces = _observed_series(observer, index, setup, most_samples)
        if error is not None and len(times) == 0:
            stage = "initialisation"   # libcosim samples step 0 once initialisation has succeeded
        bad = first_non_finite(times, traces)
        if error is None and bad is not None:
            keep = bad[0] + 1
            times, traces = times[:keep], {n: v[:keep] for n, v in traces.items()}
            error, stage = bad[1], "stepping"
        failure = None
        if error is not None:
            failure = (f"{error} (peer {self.name}, step {step:g} s, "
                       + (f"after {len(times) - 1} steps)" if stage == "stepping" else "during initialisation)"))
        steps = np.diff(times)
        counters = self.step_counters(steps)
        # Free the execution (and with it the FMU instances) before the wrappers it uses.
        del execution, observer, algorithm, local_slaves
        return dict(times=times, traces=traces, wall_time=wall, counters=counters, failure=failure,
                    failure_stage=stage if failure else None)


def _fixed_samples(setup: SceneSetup, step: float) -> int:
    """How many samples a fixed-step run records at most."""
    return math.ceil(round(setup.scene.experiment.stop * _NS) / round(step * _NS)) + 2


class _FromFile(LibcosimFixed):
    """libcosim's fixed step on an execution libcosim builds from a file the scene is
    written to (in the child's scratch folder, TMPDIR)."""

    builds_system = True

    @abstractmethod
    def write_and_load(self, scene, folder: Path, fmu_dir: Path, step: float):
        """The execution libcosim makes of ``scene`` written into ``folder``."""

    def make_execution(self, setup: SceneSetup, step: float, tolerance: float | None):
        from dataclasses import replace

        scene = replace(setup.scene, experiment=replace(setup.scene.experiment, step=step))
        folder = Path(tempfile.mkdtemp(prefix=f"{self.name}-"))
        try:
            execution = self.write_and_load(scene, folder, setup.fmu_dir, step)
        except AssertionError as error:   # libcosimpy asserts on a failed creation
            raise LibcosimError(f"{self.name}: {error}") from None
        return execution, None, _fixed_samples(setup, step)


class LibcosimSsp(_FromFile):
    name = "libcosim-ssp"
    summary = "OSP libcosim fixed step on the scene's SSP export (CosimExecution.from_ssp_file)"

    def write_and_load(self, scene, folder: Path, fmu_dir: Path, step: float):
        from libcosimpy.CosimExecution import CosimExecution

        from harness.formats import ssp

        archive = ssp.export(scene, folder / f"{scene.name}.ssp", fmu_dir)
        return CosimExecution.from_ssp_file(str(archive), round(step * _NS))


class LibcosimOsp(_FromFile):
    name = "libcosim-osp"
    summary = "OSP libcosim fixed step on an OspSystemStructure.xml connecting the FMUs' OSP ports"

    def write_and_load(self, scene, folder: Path, fmu_dir: Path, step: float):
        from libcosimpy.CosimExecution import CosimExecution

        from harness.formats import osp

        config = folder / "OspSystemStructure.xml"
        config.write_text(osp.system_structure(scene, fmu_dir))
        return CosimExecution.from_osp_config_file(str(config))


class LibcosimEcco(LibcosimFixed):
    name = "libcosim-ecco"
    summary = "OSP libcosim ECCO: step size controlled by the power residual at the coupling's bonds"
    adaptive = True
    counters = ("steps", "min_step", "max_step", "mean_step")

    #: ECCO's step range relative to the scene's step (its first step is the scene's step).
    MIN_STEP_RATIO = 0.1
    MAX_STEP_RATIO = 20.0
    #: ECCO's step controller as in libcosim's own ECCO test.  Not libcosimpy's EccoParams
    #: defaults: their max_change_rate = 0.2 caps the step's growth factor at 0.2, so the
    #: step only ever shrinks (to min_step_size after the second step).
    CONTROLLER = dict(safety_factor=0.99, min_change_rate=0.2, max_change_rate=1.5, p_gain=0.2, i_gain=0.15)
    #: ECCO's absolute (J) and relative tolerance on the energy residual of a step when
    #: none is given: libcosimpy's default.
    TOLERANCE = 1e-4

    def unavailable(self) -> str | None:
        library, reason = _libcosimc()
        if reason:
            return reason
        try:
            from libcosimpy import CosimAlgorithm as algorithms
        except ImportError:
            algorithms = None
        if not (hasattr(algorithms, "EccoParams") and hasattr(library, "cosim_ecco_add_power_bond")):
            return "this libcosimpy has no ECCO algorithm (CosimAlgorithm.EccoParams, cosim_ecco_add_power_bond)"
        return None

    def scene_problem(self, setup: SceneSetup) -> str | None:
        if problem := super().scene_problem(setup):
            return problem
        if not power_bonds(setup):
            return (f"{self.name}: no power bonds in scene {setup.scene.name} (a {'/'.join(FLOW_UNITS)} connection "
                    f"one way and a {'/'.join(EFFORT_UNITS)} connection back between two components)")
        return None

    def bonds(self, setup: SceneSetup) -> list[tuple[str, str, str, str, str, str]]:
        return power_bonds(setup)

    def make_execution(self, setup: SceneSetup, step: float, tolerance: float | None):
        from libcosimpy.CosimAlgorithm import CosimAlgorithm, EccoParams
        from libcosimpy.CosimExecution import CosimExecution

        tolerance = self.TOLERANCE if tolerance is None else tolerance
        params = EccoParams(step_size=step, min_step_size=step * self.MIN_STEP_RATIO,
                            max_step_size=step * self.MAX_STEP_RATIO,
                            abs_tolerance=tolerance, rel_tolerance=tolerance, **self.CONTROLLER)
        algorithm = CosimAlgorithm.create_ecco_algorithm(params)
        execution = CosimExecution.from_algorithm(algorithm)
        return execution, algorithm, math.ceil(setup.scene.experiment.stop / params.min_step_size) + 2

    def step_counters(self, steps: np.ndarray) -> dict:
        counters = super().step_counters(steps)
        if len(steps):
            counters.update(min_step=float(steps.min()), max_step=float(steps.max()), mean_step=float(steps.mean()))
        return counters


def power_bonds(setup: SceneSetup) -> list[tuple[str, str, str, str, str, str]]:
    """``(a, a_effort_input, a_flow_output, b, b_effort_output, b_flow_input)`` for each pair
    of components joined by a flow one way and an effort the other way: the connected ports
    of the OSP model descriptions, or (FMUs without one) a flow unit one way and an effort
    unit back."""
    from harness.formats import osp

    groups = osp.scene_groups(setup.scene, setup.fmu_dir)
    if any(groups.values()):
        return osp.power_bonds(setup.scene, groups)

    def unit(comp, var):
        return setup.variables[comp][var].unit

    bonds = []
    for flow in setup.scene.connections:
        if unit(flow.source, flow.output) not in FLOW_UNITS:
            continue
        for effort in setup.scene.connections:
            if (effort.source, effort.target) == (flow.target, flow.source) \
                    and unit(effort.source, effort.output) in EFFORT_UNITS:
                bonds.append((flow.source, effort.input, flow.output, flow.target, effort.output, flow.input))
    return bonds


def child_main(request_path: str, answer_path: str):
    """Entry point of the child process: run the request, pickle the outcome, and leave
    without Python's teardown."""
    request = pickle.loads(Path(request_path).read_bytes())
    try:
        setup = SceneSetup(request["scene"], Path(request["fmu_dir"]), request["record"])
        outcome = request["peer"].run_here(setup, request["step"], request["tolerance"])
    except Exception as error:  # noqa: BLE001 - the parent raises it
        outcome = {"exception": f"{type(error).__name__}: {error}"}
    Path(answer_path).write_bytes(pickle.dumps(outcome))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _observed_series(observer, index: dict, setup: SceneSetup, most_samples: int) -> tuple[np.ndarray, dict]:
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
