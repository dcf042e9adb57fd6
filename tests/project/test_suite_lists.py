"""The suite's own lists in tests/conftest.py: the fast subset (``make test-fast``, the tests
not marked ``slow``) keeps tests of every folder, so that the edit-test loop still reaches
every layer; and every file or test the lists name exists (a renamed or moved one would
silently drop out of its list)."""
import ast
import importlib.util
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def _conftest():
    spec = importlib.util.spec_from_file_location("lever_tests_conftest_lists", TESTS / "conftest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _tests_of(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {node.name for node in tree.body if isinstance(node, ast.FunctionDef) and node.name.startswith("test_")}


def _test_files() -> dict[str, set[str]]:
    return {path.relative_to(TESTS).as_posix(): _tests_of(path) for path in sorted(TESTS.glob("*/test_*.py"))}


def test_every_name_in_the_lists_is_a_file_or_test_of_the_suite():
    conftest, files = _conftest(), _test_files()
    for name in (*conftest.SLOW, *conftest.RUN_BUILT_FMUS, *conftest.NUMERICS, *conftest.SERIAL):
        file, _, test = name.partition("::")
        assert file in files, f"{name}: no such test file under tests/"
        assert not test or test in files[file], f"{name}: no such test in {file}"


def test_the_fast_subset_keeps_tests_of_every_folder():
    slow = set(_conftest().SLOW)
    files = _test_files()
    folders = {file.split("/")[0] for file in files}
    fast = {file.split("/")[0] for file, tests in files.items() if file not in slow
            for test in tests if f"{file}::{test}" not in slow}
    assert folders - fast == set(), f"every test of these folders is marked slow: {sorted(folders - fast)}"
    # the layers the suite is organised by; a folder renamed or emptied shows here too
    assert {"physics", "fmus", "description", "engine", "judges", "formats", "studies", "cli", "oracle",
            "project"} <= fast


def test_what_runs_alone_is_left_out_of_the_fast_subset():
    # `make test-fast` runs side by side with no serial pass of its own: a serial test in it
    # would run beside others after all.
    conftest, files = _conftest(), _test_files()
    slow = set(conftest.SLOW)
    for name in conftest.SERIAL:
        file, _, test = name.partition("::")
        for each in [test] if test else sorted(files[file]):
            assert file in slow or f"{file}::{each}" in slow, f"{file}::{each} runs alone (SERIAL) but is not in SLOW"


def test_each_shared_work_names_a_fixture_where_it_says():
    conftest = _conftest()
    for name in conftest.SHARED_WORK:
        file, _, fixture = name.rpartition("::")
        tree = ast.parse((TESTS / (file or "conftest.py")).read_text())
        defined = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert fixture in defined, f"{name}: no fixture {fixture} in {file or 'conftest.py'}"
