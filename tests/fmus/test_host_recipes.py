"""The host recipes of examples/hosts/ (PyFMI, OMSimulator's command line and its Python
package): each run in its host, when the environment names the host, and its result judged by
`lever validate --result CSV kavz685` at the default verdict; docs/hosts.md quotes each recipe
as it is.  CI has no hosts: there the recipe runs are skipped, saying which variable names
which host (docs/hosts.md says how to build them)."""
from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HOSTS = ROOT / "examples" / "hosts"
DOC = ROOT / "docs" / "hosts.md"


def _runner():
    spec = importlib.util.spec_from_file_location("lever_host_recipes", HOSTS / "run_recipes.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module     # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


recipes = _runner()


@pytest.mark.parametrize("recipe", recipes.RECIPES, ids=lambda r: r.file)
def test_each_recipes_result_passes_the_default_verdict_in_its_host(recipe, fmu_dir, tmp_path):
    if not os.environ.get(recipe.needs):
        pytest.skip(f"{recipe.needs} not set: no {recipe.host} to run it in (docs/hosts.md, building the hosts)")
    outcome = recipes.run(recipe, tmp_path)
    assert outcome.verdict == "PASS", f"{recipe.file}: {outcome.verdict}: {outcome.detail}"


def test_a_host_that_writes_no_result_is_an_error_not_a_verdict(fmu_dir, tmp_path, monkeypatch):
    """OMSimulator's command line exits 0 even when initialisation fails: the recipe judges by
    its result file, and the runner calls a recipe without one an error."""
    monkeypatch.setenv("OMSIMULATOR", "true")
    weak = next(r for r in recipes.RECIPES if r.file == "omsimulator_weak.sh")
    outcome = recipes.run(weak, tmp_path)
    assert outcome.verdict == "ERROR" and "OMSimulator wrote no result" in outcome.detail, outcome


def test_a_recipe_whose_host_is_not_named_is_listed_as_not_run_with_the_variable(monkeypatch, tmp_path):
    for recipe in recipes.RECIPES:
        monkeypatch.delenv(recipe.needs, raising=False)
    outcomes = [recipes.run(r, tmp_path) for r in recipes.RECIPES]
    assert [o.verdict for o in outcomes] == ["NOT RUN"] * len(recipes.RECIPES)
    table = recipes.table(outcomes)
    for recipe in recipes.RECIPES:
        assert f"| {recipe.host} | `examples/hosts/{recipe.file}` | NOT RUN: {recipe.needs} not set |" in table
    assert list(tmp_path.iterdir()) == []


def _quoted_blocks() -> dict[str, str]:
    """docs/hosts.md's fenced blocks, each preceded by the comment naming the file it quotes."""
    text = DOC.read_text()
    pattern = re.compile(r"<!-- quoted: (\S+) -->\n```[a-z]*\n(.*?)```\n", re.S)
    blocks = {}
    for name, body in pattern.findall(text):
        assert name not in blocks, f"docs/hosts.md quotes {name} twice"
        blocks[name] = body
    assert text.count("<!-- quoted:") == len(blocks), "a quote marker without its fenced block after it"
    return blocks


def test_the_docs_quote_every_recipe_as_it_is():
    blocks = _quoted_blocks()
    files = {f"examples/hosts/{p.name}" for p in HOSTS.iterdir() if p.is_file() and p.name != "run_recipes.py"}
    assert files == {f"examples/hosts/{r.file}" for r in recipes.RECIPES}, "a recipe the runner does not run"
    assert set(blocks) == files
    for name, body in blocks.items():
        assert body == (ROOT / name).read_text(), f"docs/hosts.md's copy of {name} is not the file"


def test_each_recipe_says_in_its_first_lines_how_it_is_run():
    for recipe in recipes.RECIPES:
        head = "\n".join((HOSTS / recipe.file).read_text().splitlines()[:12])
        assert f"examples/hosts/{recipe.file} RESULT.csv" in head, recipe.file
        assert recipe.needs in head, recipe.file
        assert "lever validate --result RESULT.csv kavz685" in head, recipe.file
