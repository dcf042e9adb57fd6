"""A unit's factor, once pint has worked it out, is kept in the cache (``unit-factors``): a
later process converts "15 deg" from there without importing pint, to the same bits; a
refusal is never kept; an unreadable file is pint's work again, not an error."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

from harness import cache
from harness.description import units

_CONVERT = """
import sys
from harness.description import units
print(repr(units.convert("15 deg", "rad")), repr(units.convert("2 kN.m/rad", "N.m/rad")))
print("pint" in sys.modules)
"""


def _convert_in_a_process(folder) -> tuple[str, bool]:
    done = subprocess.run([sys.executable, "-c", _CONVERT], capture_output=True, text=True, timeout=120,
                          env={**os.environ, cache.ENVIRONMENT: str(folder)})
    assert done.returncode == 0, done.stderr
    values, pint_imported = done.stdout.splitlines()
    return values, pint_imported == "True"


def test_a_factor_worked_out_once_is_read_from_the_cache_to_the_same_bits(tmp_path):
    first, pint_first = _convert_in_a_process(tmp_path)
    kept = list((tmp_path / units.FACTORS).rglob("pint-*.json"))
    assert len(kept) == 1 and kept[0].parent.name == cache.code_digest()
    assert pint_first
    again, pint_again = _convert_in_a_process(tmp_path)
    assert again == first and not pint_again
    # the kept figures are pint's, checked by hand: 15 deg = 15 pi/180 rad, 2 kN.m/rad = 2000 N.m/rad
    assert first == f"{15 * (math.pi / 180)!r} 2000.0"


def test_a_refusal_is_not_kept_and_an_unreadable_file_is_worked_out_again(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.ENVIRONMENT, str(tmp_path))
    with pytest.raises(units.UnitProblem, match="cannot be a value in rad"):
        units.convert("3 kg", "rad")
    path = units._factors_file()
    assert not path.exists() or "kg" not in path.read_text()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("{not json")
    units._read.pop(path, None)
    assert units.convert("90 deg", "rad") == 90 * (math.pi / 180)
    assert json.loads(path.read_text()) == {"factor deg\0rad": math.pi / 180}
