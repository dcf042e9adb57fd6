"""The archive `lever export-ssp` writes, run in every engine the export command names,
the way that command says to run it, and judged at the default band of `lever validate`
(``validation.compare``, what ``lever validate --result`` calls): each engine must run the
scene with the archive's parameter values, not the FMUs' defaults."""
from __future__ import annotations

import shlex

import numpy as np
import pytest

from harness.description import scene
from harness.formats import reference_traces, ssp
from harness.judges import validation
from harness.peers import ecos

ENGINES = ["lever", "libcosim", "ecos", "fmpy.ssp"]


@pytest.fixture(scope="module")
def exported(lever, tmp_path_factory, fmu_dir):
    """(the archive, what `lever export-ssp` printed)"""
    path = tmp_path_factory.mktemp("ssp") / "kavz685.ssp"
    result = lever("export-ssp", "kavz685", "--out", path)
    assert result.exit_code == 0, result.output
    for engine in ENGINES:           # the command says how each engine it names runs the archive
        assert f"  {engine}:" in result.output
    assert "warning" not in result.output           # the FMUs carry every value
    return path, result.output


@pytest.fixture(scope="module")
def archive(exported):
    return exported[0]


def _printed_fmpy_recipe(output: str) -> str:
    """The Python code of the fmpy.ssp line the export printed (``python -c CODE && ...``)."""
    line = next(line for line in output.splitlines() if line.startswith("  fmpy.ssp:"))
    words = shlex.split(line.split(":", 1)[1].split(" && ")[0])
    assert words[:2] == ["python", "-c"], line
    return words[2]


def _run(lever, engine: str, exported, tmp_path, request):
    """(times, traces) of the archive run in ``engine`` as `lever export-ssp` says."""
    archive, output = exported
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
    # the printed recipe as it is: it writes a CSV beside the archive (in this test's folder)
    exec(_printed_fmpy_recipe(output), {})
    table = reference_traces.read_csv(archive.with_name(f"{archive.stem}-fmpy-ssp.csv"))
    return table.times, table.signals


@pytest.mark.parametrize("engine", ENGINES)
def test_the_exported_archive_runs_with_its_values_in_every_engine_we_name(lever, engine, exported, tmp_path,
                                                                           request):
    times, traces = _run(lever, engine, exported, tmp_path, request)
    ref = reference_traces.read("kavz685")
    # fmpy.ssp records no row at the start (its first is after the first step): judged from there
    start = max(ref.opt.start, float(times[0]))
    findings, _ = validation.compare("kavz685", times, traces, ref.outputs.times, ref.outputs.signals,
                                     validation.TOLERANCES["lever"], start, ref.opt.stop)
    assert findings.passed, (engine, findings.problems, [(s.name, s.problem) for s in findings.signals
                                                        if not s.passed])


def test_fmpy_ssp_runs_the_same_without_the_parameter_set(archive):
    """simulate_ssp reads the SSD's bindings and applies none of them (fmpy 0.3.32), without
    a word; the archive's FMUs start at the scene's values, so its plain call runs the scene:
    every trace the same, bit for bit, as with the archive's parameter set."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    table = simulate_ssp(str(archive), stop_time=0.05, step_size=1e-3)
    with_values = simulate_ssp(str(archive), stop_time=0.05, step_size=1e-3,
                               parameter_set=read_ssv(str(archive), resource=ssp.QUALIFIED_SET))
    assert table.dtype.names == with_values.dtype.names
    for name in table.dtype.names:
        assert np.array_equal(table[name], with_values[name]), name
