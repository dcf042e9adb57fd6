"""What one communication step costs through the FMI 3.0 entry against the FMI 2.0 entry of
the same FMU: ``python examples/fmi3_step_cost.py [--steps N] [--rounds R]`` (after
``make fmus``).

Both editions run the same Python model behind the same FMI 2.0 entry; the FMI 3.0 entry is
one more C layer in front of it, so the difference is that layer's cost (state checks and
the out-arguments of fmi3DoStep) plus ctypes' marshalling of four more arguments (the calls
go to the libraries through ctypes with their arguments made once; fmpy's wrappers, which
make new ctypes objects at every call, are left out).  Each
round times ``--steps`` calls of fmi2DoStep on one instance and of fmi3DoStep on another,
interleaved round by round on the same machine, so that a busy machine slows both alike;
the table gives the medians over the rounds and their spread (the 10th and 90th
percentiles), per call, in microseconds, and the ratio of the medians.  The inputs are held
at their start values: the figure is the step's cost, not a physics scene's.
"""
from __future__ import annotations

import argparse
import ctypes
import statistics
import sys
import tempfile
import time
from pathlib import Path

import fmpy
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lever.fmus.registry import NAMES  # noqa: E402


def _open(kind, path: Path, name: str, unzip: str):
    md = fmpy.read_model_description(str(path))
    fmu = kind(guid=md.guid, unzipDirectory=fmpy.extract(str(path), unzipdir=unzip), modelIdentifier=name,
               instanceName=name)
    fmu.instantiate()
    if kind is FMU2Slave:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
    else:
        fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    return fmu


def _stepper(fmu):
    """One doStep call of the FMU's library with the arguments made once (ctypes directly,
    not fmpy's wrapper, so that the importer's own cost stays out of the figure)."""
    if isinstance(fmu, FMU2Slave):
        step = fmu.dll.fmi2DoStep
        step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        return lambda t, h: step(fmu.component, t, h, 1)
    step = fmu.dll.fmi3DoStep
    flags = [ctypes.c_bool() for _ in range(3)]
    reached = ctypes.c_double()
    out = [ctypes.byref(f) for f in flags] + [ctypes.byref(reached)]
    step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool] + [ctypes.c_void_p] * 4
    return lambda t, h: step(fmu.component, t, h, True, *out)


def _round(step, t: float, h: float, steps: int) -> tuple[float, float]:
    """Seconds per call of ``steps`` calls from ``t``; the time reached."""
    start = time.perf_counter()
    for _ in range(steps):
        if step(t, h) > 1:
            raise RuntimeError(f"doStep at t = {t} failed")
        t += h
    return (time.perf_counter() - start) / steps, t


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200, help="calls per round (default 200)")
    parser.add_argument("--rounds", type=int, default=31, help="rounds (default 31)")
    parser.add_argument("--h", type=float, default=1e-4, help="communication step in s (default 1e-4)")
    args = parser.parse_args(argv)
    fmi2_dir, fmi3_dir = ROOT / "build" / "fmus", ROOT / "build" / "fmus3"
    print(f"per-call wall time of doStep, µs: median [p10, p90] over {args.rounds} rounds of {args.steps} calls, "
          f"h = {args.h} s, one process, rounds interleaved")
    print(f"{'FMU':20s} {'fmi2DoStep':>24s} {'fmi3DoStep':>24s} {'FMI 3 / FMI 2':>14s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in NAMES:
            a = _open(FMU2Slave, fmi2_dir / f"{name}.fmu", name, f"{tmp}/{name}2")
            b = _open(FMU3Slave, fmi3_dir / f"{name}.fmu", name, f"{tmp}/{name}3")
            step_a, step_b = _stepper(a), _stepper(b)
            ta = tb = 0.0
            _, ta = _round(step_a, ta, args.h, args.steps)       # warm-up
            _, tb = _round(step_b, tb, args.h, args.steps)
            two, three = [], []
            for _ in range(args.rounds):
                cost, ta = _round(step_a, ta, args.h, args.steps)
                two.append(cost * 1e6)
                cost, tb = _round(step_b, tb, args.h, args.steps)
                three.append(cost * 1e6)
            for fmu in (a, b):
                fmu.terminate()
                fmu.freeInstance()

            def cell(values):
                q = statistics.quantiles(values, n=10)
                return f"{statistics.median(values):8.1f} [{q[0]:6.1f}, {q[-1]:6.1f}]"

            ratio = statistics.median(three) / statistics.median(two)
            print(f"{name:20s} {cell(two):>24s} {cell(three):>24s} {ratio:14.3f}")


if __name__ == "__main__":
    main()
