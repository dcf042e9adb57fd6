"""Shared fixtures of the test suite."""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FMU_NAMES = ("LeverCoupling", "EngineShaft", "LoadShaft")


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """The built FMUs, (re)built first when they are missing or older than their sources."""
    from harness.cli import ensure_fmus
    from harness.paths import FMUS

    ensure_fmus(quiet=True)
    for name in FMU_NAMES:
        assert (FMUS / f"{name}.fmu").exists(), name
    return FMUS
