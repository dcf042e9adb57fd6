"""`lever validate --reference` and a lever results folder as the result: a run made with
changed parameters is judged against the reference made for them, and a reference a user
brings is read as a result is - bad ones refused with exit 2 and a sentence."""
from __future__ import annotations

import numpy as np
import pytest

from harness import api
from harness.formats import reference_traces


@pytest.fixture(scope="module")
def runs(tmp_path_factory, fmu_dir):
    """KAVZ-685 at 15 and at 20 deg misalignment, 3 s each, written as lever run writes them."""
    root = tmp_path_factory.mktemp("runs")
    for degrees in (15, 20):
        api.run("kavz685", {"coupling.misalignment": f"{degrees} deg"}, stop=3.0, out=root / f"deg{degrees}",
                plots=False, notify=lambda *_: None)
    return root


def test_a_changed_run_passes_against_its_own_reference_and_fails_against_another(lever, runs, tmp_path):
    own = lever("validate", "--result", str(runs / "deg20"), "--window", "0:3", "--out", str(tmp_path / "own"))
    assert own.exit_code == 0, own.output
    assert f"reference: {runs / 'deg20' / 'reference.csv'}, made for that run's parameters" in own.output
    other = lever("validate", "--result", str(runs / "deg20"), "--reference", str(runs / "deg15"), "--window", "0:3",
                  "--no-plots", "--out", str(tmp_path / "other"))
    assert other.exit_code == 1, other.output
    assert f"reference: {runs / 'deg15' / 'reference.csv'} (given)" in other.output
    assert "coupling.tau2: " in other.output.splitlines()[-1] and "amplitude" in other.output.splitlines()[-1]
    # the same from Python
    judged = api.validate("kavz685", result=runs / "deg20", reference=runs / "deg15", window=(0, 3))
    assert not judged.passed and "deg15" in judged.findings.reference


def test_a_reference_without_a_time_column_or_the_results_signals_is_exit_2(lever, tmp_path):
    ref = reference_traces.read("kavz685")
    result = tmp_path / "result.csv"
    reference_traces.write_csv(result, ref.outputs)
    no_time = tmp_path / "no_time.csv"
    no_time.write_text("t,engine.w\n0,1\n1,2\n")
    said = lever("validate", "--result", str(result), "--reference", str(no_time), "kavz685")
    assert said.exit_code == 2 and "the first column must be 'time'" in said.output, said.output
    other = tmp_path / "other.csv"
    other.write_text("time,speed\n0,1\n10,2\n")
    said = lever("validate", "--result", str(result), "--reference", str(other), "kavz685")
    assert said.exit_code == 2 and "none of kavz685's signals" in said.output, said.output
    unsorted = tmp_path / "unsorted.csv"
    t = ref.outputs.times.copy()
    t[[10, 11]] = t[[11, 10]]
    reference_traces.write_csv(unsorted, reference_traces.Traces(t, ref.outputs.signals))
    said = lever("validate", "--result", str(unsorted), "kavz685")
    assert said.exit_code == 2 and "not sorted: row 12" in said.output, said.output
    sparse = tmp_path / "sparse.csv"
    rows = np.arange(0, len(ref.outputs.times), 1000)
    reference_traces.write_csv(sparse, reference_traces.Traces(ref.outputs.times[rows],
                                                               {n: v[rows] for n, v in ref.outputs.signals.items()}))
    said = lever("validate", "--result", str(sparse), "kavz685")
    assert said.exit_code == 2 and "at least 10 are needed" in said.output, said.output


def test_a_reference_given_as_traces_judges_in_python(tmp_path):
    ref = reference_traces.read("kavz685")
    t, signals = ref.outputs.times, ref.outputs.signals
    keep = t <= 4.0 + 1e-9
    mine = (t[keep], {"coupling.tau2": signals["coupling.tau2"][keep] * 1.002})
    judged = api.validate("kavz685", result=(t[keep], {"coupling.tau2": signals["coupling.tau2"][keep]}),
                          reference=mine, window=(0, 4))
    assert judged.findings.reference.startswith("the traces given")
    assert [c.quantity for c in judged.findings.signals[0].failed] == ["mean"]
