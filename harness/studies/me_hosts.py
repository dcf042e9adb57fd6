"""Each FMU's Model Exchange edition alone, in hosts we did not write the numerics of,
judged against its stand-alone reference (``lever validate --result``):

* ``fmpy`` - fmpy's ``simulate_fmu(fmi_type='ModelExchange', solver='CVode')`` in this
  process, driven by the reference's ``_in.csv`` (fmpy interpolates a continuous input
  linearly between its rows and makes a repeated row an input event);
* ``c-importer`` - our minimal C host (tests/c_host/minimal_importer.c, ``--me``) in a bare
  environment: the standard's Model Exchange calling sequence around a fixed-step classical
  Runge-Kutta integrator (RK4) with event indicators checked after every step, a sign change
  located by bisection, the inputs from a CSV (linear between rows, a repeated row an input
  event), the outputs to a CSV;
* ``cvode-roots`` and ``cvode-roots-fmi3`` - the FMI 2.0 and 3.0 editions in a host as C
  hosts with CVODE write it (``cvode_host``, after Reference-FMUs' ``fmusim --solver
  cvode``): the event indicators are CVODE's own root functions, CVODE goes on from its
  own history after an event that changed no state, so an indicator still zero there
  stops the run;
* ``c-importer-fmi3-rk4`` and ``c-importer-fmi3-cs`` - the same C importer on the FMI 3.0
  edition (``build/fmus3``, ``--me3``, ``--cs3``): the same RK4 loop through FMI 3.0's Model
  Exchange calls, and its Co-Simulation loop (the inputs set at each communication point,
  ``fmi3DoStep``, the outputs read after it: the references' own sampling).

An FMU with a stand-alone reference (``reference_traces.FMU_CASES``) runs as its reference
says (defaults, its inputs, its span and output step).  The freewheel rectifier has none
(``lever.fmus.registry`` says why); its reference is the scene ``freewheel_rectifier``,
which is this FMU alone, unconnected: it runs with that scene's parameters and its result's
columns are named as the scene records them (``rectifier.<variable>``).

What both hosts record at an output point is read after the inputs of that time are set:
an output that depends directly on an input (a shaft's acceleration ``a``) is the exact
one, where the references take the input held from the point before (fmpy's co-simulation
sampling, ``reference_traces``).  For the engine shaft, whose torque falls with its speed,
those differ at the edge of the ``lever`` band (see ``FEEDTHROUGH``).
"""
from __future__ import annotations

import csv
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..description import scene as scenes
from ..description.plan import converted
from ..formats import reference_traces
from ..paths import FMUS, fmi3_dir
from ..peers import BARE_ENVIRONMENT
from . import hosts

#: FMU without a stand-alone reference -> the scene that runs it alone (its reference)
SCENE_REFERENCES = {"FreewheelRectifier": "freewheel_rectifier"}

#: the outputs that depend directly on an input and whose ``lever`` verdict in a host that
#: reads them with the inputs of the same time sits at the band's edge: the reference's engine
#: acceleration ``a(t_k)`` is taken with the torque of ``t_k-1`` (the co-simulation sampling),
#: and the engine's torque falls with its speed (dM/dw / I = -110 1/s), so the exact ``a``'s
#: ripple is 2.2 % above the reference's (172.68 vs 168.94), against the 2 % plus the
#: reference's own error (0.44) allowed: fmpy's CVODE fails it by a hair, the RK4 loop passes
#: it by one, and no host step moves it.  They are judged with the cross-check's figures, and
#: against the exact acceleration.
FEEDTHROUGH = {"EngineShaft": ("a",)}

#: CVode's relative tolerance in fmpy: the references' 1e-10 makes CVode take more than
#: fmpy's 500 steps between two output points at the first kinks of an input interpolated
#: linearly between 1 ms rows (the shafts' 420 rad/s torque component, t = 1.8 ms)
FMPY_RTOL = 1e-8


@dataclass
class AloneCase:
    """One FMU's Model Exchange edition run alone as its reference says."""
    fmu: str
    reference: str
    start_values: dict
    #: the inputs (``_in.csv``), None without
    inputs: reference_traces.Traces | None
    #: reference signal -> FMU variable
    columns: dict
    opt: reference_traces.Options


def alone_case(fmu: str) -> AloneCase:
    if fmu in reference_traces.FMU_CASES:
        ref = reference_traces.read(fmu)
        return AloneCase(fmu, fmu, {}, ref.inputs, {n: n for n in ref.outputs.signals}, ref.opt)
    name = SCENE_REFERENCES[fmu]
    spec = scenes.load(name)
    (component, c), = spec.components.items()
    if c.fmu != fmu or spec.connections:
        raise ValueError(f"scene {name} is not {fmu} alone")
    from fmpy import read_model_description

    variables = {v.name: v for v in read_model_description(str(FMUS / f"{fmu}.fmu")).modelVariables}
    start = {k: converted(variables[k], v, f"{component}.{k}") for k, v in c.parameters.items()}
    ref = reference_traces.read(name)
    return AloneCase(fmu, name, start, None, {n: n.split(".", 1)[1] for n in ref.outputs.signals}, ref.opt)


def run_fmpy(case: AloneCase, fmu_dir: Path = FMUS, rtol: float = FMPY_RTOL) -> tuple[np.ndarray, dict]:
    """fmpy's Model Exchange simulation with CVode: the times and the traces named as the
    reference's signals."""
    from fmpy import simulate_fmu

    from ..engine.component import unzipped

    opt = case.opt
    signal = None
    if case.inputs is not None:
        signal = np.rec.fromarrays([case.inputs.times] + list(case.inputs.signals.values()),
                                   names=["time"] + list(case.inputs.signals))
    result = simulate_fmu(unzipped(Path(fmu_dir) / f"{case.fmu}.fmu"), fmi_type="ModelExchange", solver="CVode",
                          start_time=opt.start, stop_time=opt.stop, output_interval=opt.step,
                          relative_tolerance=rtol, input=signal, output=list(dict.fromkeys(case.columns.values())),
                          start_values=dict(case.start_values))
    return (np.asarray(result["time"], dtype=float),
            {ref: np.asarray(result[var], dtype=float) for ref, var in case.columns.items()})


# -- the C importer's Model Exchange loop -------------------------------------------------------

#: RK4 steps per output step of the C importer, for each FMU: the freewheel's contacts ring at
#: 2000-5000 rad/s (RK4 is stable to h * 5000 < 2.8, accurate well below): 1e-5 s there
C_SUBSTEPS = {"FreewheelRectifier": 20}
C_SUBSTEPS_DEFAULT = 10


def run_c_importer_me(program: Path, case: AloneCase, scratch: Path, fmu_dir: Path = FMUS,
                      env: dict | None = None, substeps: int | None = None, timeout: float = 600,
                      fmi: int = 2, interface: str = "ModelExchange") -> tuple[np.ndarray, dict, subprocess.CompletedProcess]:
    """The C importer's Model Exchange loop (or, with ``interface="CoSimulation"``, its
    Co-Simulation loop driven by the same inputs) on ``case`` through FMI ``fmi`` (2 or 3;
    the FMI 3.0 edition is taken from ``fmi3_dir(fmu_dir)``): its inputs written to a CSV
    for it, its outputs read from the CSV it writes.  Raises RuntimeError when it fails."""
    from fmpy import extract, read_model_description

    if fmi not in (2, 3) or interface not in ("ModelExchange", "CoSimulation"):
        raise ValueError(f"the C importer runs FMI 2 or 3, ModelExchange or CoSimulation, not {fmi} {interface}")
    me = interface == "ModelExchange"
    source = Path(fmu_dir) if fmi == 2 else fmi3_dir(fmu_dir)
    scratch.mkdir(parents=True, exist_ok=True)
    folder = scratch / (case.fmu if fmi == 2 else f"{case.fmu}-fmi3")
    if not folder.exists():
        extract(str(source / f"{case.fmu}.fmu"), str(folder))
    md = read_model_description(str(folder / "modelDescription.xml"))
    variables = {v.name: v for v in md.modelVariables}
    tag = f"{'me' if me else 'cs'}{'' if fmi == 2 else '3'}"
    inputs_csv = scratch / f"{case.fmu}_{tag}_in.csv"
    input_vrs = []
    if case.inputs is not None:
        names = list(case.inputs.signals)
        input_vrs = [variables[n].valueReference for n in names]
        reference_traces.write_csv(inputs_csv, case.inputs)
    else:
        inputs_csv.write_text('"time"\n')
    parameters = []
    for name, value in case.start_values.items():
        v = variables[name]
        kind = {"Real": "r", "Float64": "r", "Integer": "i", "Int32": "i"}.get(v.type)
        if kind is None:
            raise ValueError(f"the C importer sets Real and Integer start values only, not {v.type} {name}")
        parameters.append(f"{kind}{v.valueReference}={float(value)!r}")
    outputs = list(dict.fromkeys(case.columns.values()))
    out_csv = scratch / f"{case.fmu}_{tag}_out.csv"
    opt = case.opt
    n_out = int(round((opt.stop - opt.start) / opt.step))
    identifier = (md.modelExchange if me else md.coSimulation).modelIdentifier
    if me:
        sizes = [str(md.numberOfContinuousStates), str(md.numberOfEventIndicators)]
        timing = [repr(opt.start), repr(opt.step), str(n_out),
                  str(substeps or C_SUBSTEPS.get(case.fmu, C_SUBSTEPS_DEFAULT))]
    else:
        sizes, timing = [], [repr(opt.start), repr(opt.step), str(n_out)]
    args = [str(program), f"--{tag}", str(folder), identifier, md.guid, *sizes, *timing, str(inputs_csv),
            ",".join(map(str, input_vrs)) or "-", ",".join(parameters) or "-",
            ",".join(f"{n}={variables[n].valueReference}" for n in outputs), str(out_csv)]
    done = subprocess.run(args, env=BARE_ENVIRONMENT if env is None else env, capture_output=True, text=True,
                          timeout=timeout)
    if done.returncode != 0:
        raise RuntimeError(f"the C importer failed on {case.fmu} (FMI {fmi} {interface}, exit {done.returncode}):\n"
                           f"{done.stderr[-3000:]}")
    table = reference_traces.read_csv(out_csv)
    return table.times, {ref: table.signals[var] for ref, var in case.columns.items()}, done


def compile_c_importer(dest: Path) -> Path:
    return hosts.compile_c_importer(dest)


def exact_engine_acceleration(times: np.ndarray) -> np.ndarray:
    """The engine shaft's exact acceleration in its stand-alone case, with the torque of the
    same time (what a host that sets the inputs before it reads gets)."""
    from lever.physics import component_parameters

    ref = reference_traces.read("EngineShaft")
    case = reference_traces.FMU_CASES["EngineShaft"]
    shaft = component_parameters.engine_from({})
    tau = case.inputs(np.asarray(times, dtype=float))["tau"]
    phi = np.interp(times, ref.outputs.times, ref.outputs.signals["phi"])
    w = np.interp(times, ref.outputs.times, ref.outputs.signals["w"])
    return np.array([shaft.rates(t, p, v, q)[0] for t, p, v, q in zip(times, phi, w, tau)])


def c_counts(done: subprocess.CompletedProcess) -> dict:
    """What the C importer's Model Exchange loop counted (its ``me:`` line on stderr): RK4
    steps, state, time, input and step events, the loop's time [s]."""
    line = next(line for line in done.stderr.splitlines() if line.startswith("me:"))
    return {key: float(value) for key, _, value in (word.partition("=") for word in line[3:].split())}


def write_result(path: Path, times: np.ndarray, traces: dict) -> Path:
    """The result as ``lever validate --result`` reads it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["time", *traces])
        for i, t in enumerate(times):
            writer.writerow([repr(float(t))] + [repr(float(traces[n][i])) for n in traces])
    return path


#: the hosts ``main`` runs, in order
HOSTS = ("fmpy-cvode", "cvode-roots", "cvode-roots-fmi3", "c-importer-rk4", "c-importer-fmi3-rk4",
         "c-importer-fmi3-cs")


def run_cvode_roots(case: AloneCase, fmu_dir: Path = FMUS, fmi: int = 2, rtol: float = FMPY_RTOL):
    """``case`` in the CVODE host with its own root finding (``cvode_host``): the times, the
    traces named as the reference's signals, and the host's run (events, restarts).  An
    FMU with inputs is refused (the host holds them at their start values)."""
    from . import cvode_host

    if case.inputs is not None:
        raise ValueError(f"{case.fmu}: the CVODE root-finding host holds the inputs; its reference has an input file")
    fmu = (Path(fmu_dir) if fmi == 2 else fmi3_dir(Path(fmu_dir))) / f"{case.fmu}.fmu"
    names = list(dict.fromkeys(case.columns.values()))
    opt = case.opt
    run = cvode_host.run(fmu, fmi, case.start_values, names, opt.stop, opt.step, rtol=rtol, atol=rtol * 1e-2)
    return run.times, {ref: run.outputs[var] for ref, var in case.columns.items()}, run


def main(out: Path, fmus=None, names: tuple = HOSTS) -> list[str]:
    """Runs every FMU alone in each host of ``names``, writes each result to
    ``out/<host>/<FMU>_me.csv`` (``_cs.csv`` for Co-Simulation) and returns the ``lever validate --result`` command for each."""
    import tempfile

    commands = []
    with tempfile.TemporaryDirectory(prefix="lever-me-hosts-") as scratch:
        program = compile_c_importer(Path(scratch) / "bin" / "minimal_importer")
        for fmu in fmus or [m for m in reference_traces.registry.NAMES]:
            case = alone_case(fmu)
            for host in names:
                if host == "fmpy-cvode":
                    times, traces = run_fmpy(case)
                elif host.startswith("cvode-roots"):
                    if case.inputs is not None:
                        continue
                    times, traces, _ = run_cvode_roots(case, fmi=3 if host.endswith("fmi3") else 2)
                else:
                    fmi = 3 if "fmi3" in host else 2
                    interface = "CoSimulation" if host.endswith("-cs") else "ModelExchange"
                    times, traces, _ = run_c_importer_me(program, case, Path(scratch) / "run", fmi=fmi,
                                                         interface=interface)
                suffix = "cs" if host.endswith("-cs") else "me"
                path = write_result(out / host / f"{fmu}_{suffix}.csv", times, traces)
                commands.append(f"lever validate --result {path} {case.reference} --out {out / host / fmu}")
    return commands


if __name__ == "__main__":      # python -m harness.studies.me_hosts [OUT]: the results and the commands
    import sys

    from ..paths import RESULTS

    for command in main(Path(sys.argv[1]) if len(sys.argv) > 1 else RESULTS / "me_hosts"):
        print(command)
