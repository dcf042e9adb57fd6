"""The archive `lever export-ssp` writes, run in every engine the export command names,
the way that command says to run it, and judged at the default band of `lever validate`
(``validation.compare``, what ``lever validate --result`` calls): each engine must run the
scene with the archive's parameter values, not the FMUs' defaults."""
from __future__ import annotations

import numpy as np
import pytest

from harness.description import scene
from harness.formats import reference_traces, ssp
from harness.judges import validation
from harness.peers import ecos

ENGINES = ["lever", "libcosim", "ecos", "fmpy.ssp"]


@pytest.fixture(scope="module")
def archive(lever, tmp_path_factory, fmu_dir):
    path = tmp_path_factory.mktemp("ssp") / "kavz685.ssp"
    result = lever("export-ssp", "kavz685", "--out", path)
    assert result.exit_code == 0, result.output
    for engine in ENGINES:           # the command says how each engine it names runs the archive
        assert f"  {engine}:" in result.output
    return path


def _run(lever, engine: str, archive, tmp_path, request):
    """(times, traces) of the archive run in ``engine`` as ``ssp.HOW_TO_RUN`` says."""
    spec = scene.load("kavz685")
    e = spec.experiment
    if engine == "lever":
        result = lever("run", archive, "--out", tmp_path / "run", "--no-reference", "--no-plots", "--no-progress")
        assert result.exit_code == 0, result.output
        table = reference_traces.read_csv(tmp_path / "run" / "traces.csv")
        return table.times, table.signals
    if engine == "libcosim":
        # CosimExecution.from_ssp_file on the same export (in a child process, see peers;
        # the run tests/fmus/test_dropin.py judges too, made once)
        result = request.getfixturevalue("kavz685_in_libcosim_from_ssp")
        assert result.ok, result.failure
        return result.times, result.traces
    if engine == "ecos":
        result = ecos.run_ecos(archive, e.stop, e.step, tmp_path / "bin", record=list(spec.record))
        return ecos.ecos_traces(result.csv)
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    table = simulate_ssp(str(archive), start_time=e.start, stop_time=e.stop, step_size=e.step,
                         parameter_set=read_ssv(str(archive), resource=ssp.QUALIFIED_SET))
    # simulate_ssp labels the values after each step with the step's start time
    times = np.asarray(table["time"], dtype=float) + e.step
    return times, {name: np.asarray(table[name], dtype=float) for name in spec.record}


@pytest.mark.parametrize("engine", ENGINES)
def test_the_exported_archive_runs_with_its_values_in_every_engine_we_name(lever, engine, archive, tmp_path,
                                                                           request):
    times, traces = _run(lever, engine, archive, tmp_path, request)
    ref = reference_traces.read("kavz685")
    # fmpy.ssp records no row at the start (its first is after the first step): judged from there
    start = max(ref.opt.start, float(times[0]))
    findings, _ = validation.compare("kavz685", times, traces, ref.outputs.times, ref.outputs.signals,
                                     validation.TOLERANCES["lever"], start, ref.opt.stop)
    assert findings.passed, (engine, findings.problems, [(s.name, s.problem) for s in findings.signals
                                                        if not s.passed])


def test_fmpy_ssp_without_the_qualified_set_runs_on_the_fmus_defaults(archive):
    """Why the export says what fmpy.ssp needs: without parameter_set, simulate_ssp reads the
    SSD's bindings and applies none of them (fmpy 0.3.32), without a word."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    table = simulate_ssp(str(archive), stop_time=0.05, step_size=1e-3)
    with_values = simulate_ssp(str(archive), stop_time=0.05, step_size=1e-3,
                               parameter_set=read_ssv(str(archive), resource=ssp.QUALIFIED_SET))
    assert not np.allclose(table["load.load_torque"], with_values["load.load_torque"])
