"""The output docs/guide/validate-a-result.md and docs/validation.md show is what `lever
validate` prints: each block marked ``<!-- validate-output: FILE -->`` is remade from
the committed reference (FILE built as the page says) and compared line by line."""
from __future__ import annotations

import re

import numpy as np
import pytest

from harness.formats import reference_traces
from harness.paths import ROOT

PAGES = (ROOT / "docs" / "guide" / "validate-a-result.md", ROOT / "docs" / "validation.md")
FIVE = ("engine.w", "load.w", "coupling.tau1", "coupling.tau2")


def _write(folder, name: str):
    """The CSVs the pages judge: the exact solution every 10 ms in four columns
    (``my_tool.csv``), and the same with tau2's ripple 8 % larger after the start-up, its
    columns named as a container FMU names them (``other_tool.csv``)."""
    ref = reference_traces.read("kavz685")
    t, signals = ref.outputs.times, ref.outputs.signals
    rows = np.arange(0, len(t), 10)
    traces = {n: signals[n][rows] for n in FIVE}
    if name == "other_tool.csv":
        tau2 = traces["coupling.tau2"]
        steady = t[rows] >= 2.0
        mean = tau2[steady].mean()
        traces = {n.replace(".", "_"): v for n, v in traces.items()}
        traces["coupling_tau2"] = np.where(steady, mean + 1.08 * (tau2 - mean), tau2)
    reference_traces.write_csv(folder / name, reference_traces.Traces(t[rows], traces))


def _blocks():
    for page in PAGES:
        text = page.read_text()
        for match in re.finditer(r"<!-- validate-output: (\S+) -->\n```text\n(.*?)\n```", text, re.S):
            yield pytest.param(page, match.group(1), match.group(2), id=f"{page.name}:{match.group(1)}")


@pytest.mark.parametrize("page, name, shown", list(_blocks()))
def test_the_pages_show_what_lever_validate_prints(lever, tmp_path, monkeypatch, page, name, shown):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, name)
    said = lever("validate", "--result", name, "kavz685", "--out", "results/validate/kavz685")
    assert said.exit_code in (0, 1), said.output
    printed = said.output.rstrip("\n").splitlines()
    for i, (want, got) in enumerate(zip(shown.splitlines(), printed)):
        assert want == got, f"{page.name}, block {name}, line {i + 1}:\n  page: {want}\n  now:  {got}"
    assert len(shown.splitlines()) == len(printed), f"{page.name}, block {name}: the output has another length"


def test_each_page_shows_an_output():
    assert {p.name for p, *_ in (b.values for b in _blocks())} == {p.name for p in PAGES}
