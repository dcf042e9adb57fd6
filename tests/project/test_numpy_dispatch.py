"""The second pass of `make test` with numpy's SIMD dispatch limited (tests/numpy_dispatch.py)."""
import ast
import os
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(TESTS))
import numpy_dispatch  # noqa: E402


def test_every_numerics_sensitive_name_is_a_test_of_the_suite():
    # A renamed test would drop out of the second pass unseen.
    for name in numpy_dispatch.numerics_names():
        file, function = name.split("::")
        tree = ast.parse((TESTS / file).read_text())
        assert function in {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}, name


@pytest.mark.parametrize("level,disabled", numpy_dispatch.limited_levels() or [("baseline already", None)])
def test_each_pass_runs_numpy_at_the_level_it_names(level, disabled):
    # numpy ignores a feature it does not dispatch (only an ImportWarning, an error in
    # in_use), so a pass naming one would run at another level than it says.
    if disabled is None:      # no pass: numpy runs its baseline code only, as things stand
        assert numpy_dispatch.in_use(dict(os.environ)) == []
        return
    used = numpy_dispatch.in_use(numpy_dispatch.limited_env(disabled))
    assert not set(used) & set(disabled), (level, used)
    if level.startswith("baseline"):
        assert used == [], used
    else:
        assert used[-1] == level, (level, used)
