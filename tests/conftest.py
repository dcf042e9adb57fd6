"""Shared fixtures of the test suite."""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
FMU_NAMES = ("LeverCoupling", "EngineShaft", "LoadShaft", "MisalignmentSource")


#: Tests whose outcome could move with numpy's SIMD dispatch: they compare what went through
#: numpy's vectorised functions, reductions or FFTs with the physics' standard-library results,
#: with scipy or fmpy, or with committed numbers, exactly or close to rounding.  They get the
#: marker ``numerics``; `make test` runs them again with numpy's dispatch limited to each
#: lower level this CPU has (tests/numpy_dispatch.py, docs/testing.md).
NUMERICS = (
    "physics/test_loads_and_shafts.py::test_random_load_draws_are_numpys_default_rng_bit_for_bit",
    "physics/test_loads_and_shafts.py::test_random_load_scalar_resistance_is_the_multisine",
    "physics/test_loads_and_shafts.py::test_random_load_stays_within_its_bound",
    "physics/test_kinematics.py::test_pairwise_sum_is_numpys_sum_bit_for_bit",
    "physics/test_kinematics.py::test_the_standard_library_fft_agrees_with_numpy_to_rounding",
    "physics/test_kinematics.py::test_standard_library_real_ffts_agree_with_numpy",
    "physics/test_kinematics.py::test_position_derivative_is_the_transfer_function",
    "physics/test_kinematics.py::test_kinematic_mode_is_the_renormalised_half_coupling_ratio",
    "physics/test_kinematics.py::test_the_reported_amplitude_fit_agrees_with_scipy",
    "physics/test_coupling_physics.py::test_torques_are_minus_t_and_u12_t",
    "oracle/test_oracle_physics.py::test_monotone_cubic_slopes_are_scipys_pchip_on_uneven_tables",
    "oracle/test_oracle_closed_forms.py::test_stability_edges_table_of_the_docs",
    "judges/test_validate.py::test_band_is_fmpys_with_the_cross_check_figures",
    "judges/test_validate.py::test_cross_check_fraction_is_fmpys_validate_result",
    "judges/test_validate.py::test_lever_reference_reports_every_committed_trace_current",
)

#: Test files whose tests run the built FMUs from where the harness looks for them
#: (harness.paths.FMUS) without asking for ``fmu_dir``: the FMUs are built, or found current,
#: before each of their tests (``_built_fmus``).
RUN_BUILT_FMUS = (
    "engine/test_cosim.py",
    "engine/test_extreme.py",
    "engine/test_iteration_and_adaptive.py",
    "engine/test_masters.py",
    "fmus/test_dropin.py",
    "formats/test_peers.py",
    "judges/test_stability.py",
    "oracle/test_oracle_closed_forms.py",
    "studies/test_bench.py",
)

#: What ``make test-fast`` (``pytest -m "not slow"``) leaves out: a test file, or a test of one
#: (all its parameters), that took about a second or more in a whole run with ``--durations=0``
#: on the shared two-core machine (docs/testing.md).  The rest keeps tests of every folder
#: (tests/project/test_suite_lists.py).
SLOW = (

)


def pytest_configure(config):
    config.addinivalue_line("markers", "numerics: the outcome could move with numpy's SIMD dispatch "
                                       "(tests/conftest.py NUMERICS)")
    # A suite started as a background job of a shell without job control inherits SIGINT
    # ignored, and so would every `lever` the Ctrl-C tests start: they would wait for an
    # interrupt that never comes.  A handled signal is reset to its default across exec.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(config, items):
    for item in items:
        file = item.path.relative_to(TESTS).as_posix()
        if f"{file}::{item.originalname}" in NUMERICS:
            item.add_marker(pytest.mark.numerics)
        if file in SLOW or f"{file}::{item.originalname}" in SLOW:
            item.add_marker(pytest.mark.slow)


def pytest_report_header(config):
    # Which SIMD code numpy runs here, so that a log says at which dispatch level it passed.
    from numpy._core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__
    used = [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]
    return (f"numpy SIMD: baseline {' '.join(__cpu_baseline__) or '-'}, dispatched in use: {' '.join(used) or 'none'}"
            f" (NPY_DISABLE_CPU_FEATURES={os.environ.get('NPY_DISABLE_CPU_FEATURES', '')!r})")


def pytest_addoption(parser):
    parser.addoption("--accuracy-report", action="store_true", default=False,
                     help="print each master's measured errors (tests/oracle/test_oracle_accuracy.py), to re-measure")


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """The built FMUs, (re)built first when they are missing or older than their sources."""
    from harness.cli import ensure_fmus
    from harness.paths import FMUS

    ensure_fmus(quiet=True)
    for name in FMU_NAMES:
        assert (FMUS / f"{name}.fmu").exists(), name
    return FMUS


@pytest.fixture(autouse=True)
def _built_fmus(request):
    if request.path.relative_to(TESTS).as_posix() in RUN_BUILT_FMUS:
        request.getfixturevalue("fmu_dir")


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
