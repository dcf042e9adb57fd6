"""Run the numerics-sensitive tests (tests/conftest.py NUMERICS) again with numpy's SIMD
dispatch limited, once per lower level this CPU offers, so that a test holding at one
dispatch level only fails on the machine that runs it (docs/testing.md).

numpy picks, at import, the best of its dispatched code paths (``__cpu_dispatch__``) that
the CPU has; ``NPY_DISABLE_CPU_FEATURES`` takes some away.  Each pass here disables every
dispatched feature from one level up: on a CPU with AVX2 but no AVX-512 one pass, at the
baseline; on one with AVX-512 more passes (without the AVX-512 extras, without AVX-512,
without AVX2).  Only names numpy dispatches are given: numpy refuses to import when a
baseline feature is named (RuntimeError) and ignores an unknown name with an ImportWarning.

    python tests/numpy_dispatch.py [PYTEST ARGS...]     # `make test-dispatch`
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def numerics_names() -> tuple[str, ...]:
    """``folder/file::test`` (relative to tests/) of each numerics-sensitive test, from the one
    list in conftest.py."""
    spec = importlib.util.spec_from_file_location("lever_tests_conftest", TESTS / "conftest.py")
    conftest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conftest)
    return conftest.NUMERICS


def limited_levels() -> list[tuple[str, list[str]]]:
    """``(level, features to disable)`` for each pass: ``level`` is the best code path
    numpy keeps (a dispatched feature, or the baseline), highest first."""
    from numpy._core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__
    dispatched = list(__cpu_dispatch__)                  # lowest first, as numpy builds them
    available = [name for name in dispatched if __cpu_features__.get(name)]
    passes = []
    for k in range(len(available) - 1, -1, -1):
        kept = available[:k]
        level = kept[-1] if kept else "baseline " + " ".join(__cpu_baseline__)
        passes.append((level, [name for name in dispatched if name not in kept]))
    return passes


def limited_env(disabled: list[str]) -> dict[str, str]:
    env = dict(os.environ, NPY_DISABLE_CPU_FEATURES=" ".join(disabled))
    env.pop("NPY_ENABLE_CPU_FEATURES", None)         # numpy refuses both at once
    return env


def in_use(env: dict) -> list[str]:
    """The dispatched features numpy uses under ``env``, in a fresh interpreter; a name numpy
    would ignore (its ImportWarning) is an error here."""
    probe = ("from numpy._core._multiarray_umath import __cpu_dispatch__ as d, __cpu_features__ as f;"
             "print(' '.join(n for n in d if f.get(n)))")
    return subprocess.run([sys.executable, "-W", "error::ImportWarning", "-c", probe], env=env, check=True,
                          capture_output=True, text=True).stdout.split()


def main(argv: list[str]) -> int:
    passes = limited_levels()
    if not passes:
        print("numpy dispatch: numpy runs its baseline code only here (this CPU or NPY_DISABLE_CPU_FEATURES):"
              " nothing to limit")
        return 0
    tests = [str(TESTS / name) for name in numerics_names()]
    failed = []
    for level, disabled in passes:
        env = limited_env(disabled)
        try:
            still = set(in_use(env)) & set(disabled)
        except subprocess.CalledProcessError as error:
            print(f"numpy dispatch: numpy refuses NPY_DISABLE_CPU_FEATURES={env['NPY_DISABLE_CPU_FEATURES']!r}:\n"
                  f"{error.stderr.strip()}")
            return 1
        if still:
            print(f"numpy dispatch: disabling {' '.join(disabled)} left {' '.join(sorted(still))} in use")
            return 1
        print(f"numpy dispatch limited to {level} (NPY_DISABLE_CPU_FEATURES={env['NPY_DISABLE_CPU_FEATURES']!r}):"
              f" the {len(tests)} numerics-sensitive tests of tests/conftest.py", flush=True)
        status = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *argv, *tests],
                                env=env).returncode
        if status != 0:
            failed.append(level)
    if failed:
        print(f"numpy dispatch: the numerics-sensitive tests failed with numpy limited to {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
