"""Shared fixtures of the test suite."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FMU_NAMES = ("LeverCoupling", "EngineShaft", "LoadShaft", "MisalignmentSource")


def pytest_addoption(parser):
    parser.addoption("--accuracy-report", action="store_true", default=False,
                     help="print each master's measured errors (tests/test_oracle_accuracy.py), to re-measure")


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """The built FMUs, (re)built first when they are missing or older than their sources."""
    from harness.cli import ensure_fmus
    from harness.paths import FMUS

    ensure_fmus(quiet=True)
    for name in FMU_NAMES:
        assert (FMUS / f"{name}.fmu").exists(), name
    return FMUS


# pythonfmu 0.7's native library can corrupt the heap while the process tears down
# (seen as "corrupted double-linked list" after every test had passed, about one run in
# four with a few hundred FMU instances).  Once pytest has printed its summary, leave
# without running interpreter and library teardown, keeping pytest's exit status.
def pytest_sessionfinish(session, exitstatus):
    session.config._lever_exit_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    status = getattr(config, "_lever_exit_status", None)
    # mutmut runs pytest inside its own process (it sets MUTANT_UNDER_TEST): leaving from
    # here would end mutmut itself (tests/mutation/run_mutants.py).
    if status is not None and "MUTANT_UNDER_TEST" not in os.environ:
        from harness.engine.component import remove_extractions
        remove_extractions()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
