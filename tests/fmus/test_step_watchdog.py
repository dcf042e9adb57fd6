"""Every FMU's fmi2DoStep returns, within a bound, for the extremes of every admitted real
parameter (the declared min and max, each with the others at their defaults) and step sizes
from 1e-300 to 1e300, starting at t = 0 and at t = 1e6 s: a step too costly is refused by
name, never ground through while the importer waits.

The steps run in a child process (tests/fmus/step_watchdog_child.py) that reports each call
before making it; a call that has not returned within ``BOUND`` seconds fails the test
(the child is killed and resumed after the hanging case, so one run reports them all)."""
from __future__ import annotations

import os
import selectors
import subprocess
import sys
import time
from pathlib import Path

CHILD = Path(__file__).with_name("step_watchdog_child.py")
#: the slowest admitted step: 200,000 RK4 substeps (about 6 s here), with room for a busy machine
BOUND = 60.0


def test_every_step_of_every_fmu_returns_within_the_bound(fmu_dir):
    hangs, slow, unnamed, first, calls = [], [], [], 0, 0
    while True:
        child = subprocess.Popen([sys.executable, str(CHILD), str(fmu_dir), str(first)], stdout=subprocess.PIPE,
                                 text=True, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
        selector = selectors.DefaultSelector()
        selector.register(child.stdout, selectors.EVENT_READ)
        current, finished = None, False
        while True:
            if not selector.select(timeout=BOUND):
                child.kill()
                child.wait()
                hangs.append(current)
                first = int(current.split()[1]) + 1
                break
            line = child.stdout.readline()
            if not line:
                child.wait()
                assert child.returncode == 0 or current is None, f"the child died (rc {child.returncode}) in {current}"
                finished = True
                break
            if line.startswith("start "):
                current = line.strip()
                calls += 1
            elif line.startswith("done "):
                seconds = float(line.split()[2])
                status, said = int(line.split()[5]), line.split(None, 6)[6:] or [""]
                if status not in (0, 1) and ("internal error" in said[0] or not said[0].strip()):
                    unnamed.append(f"{current}: status {status}, {said[0].strip()!r}")
                if seconds > BOUND / 4:
                    slow.append(f"{current}: {seconds} s")
            elif line.startswith("all done"):
                finished = True
        if finished:
            break
    assert not hangs, f"fmi2DoStep did not return within {BOUND} s: {hangs}"
    assert calls > 1000, calls
    assert not unnamed, "steps refused without naming the cause:\n" + "\n".join(unnamed)
    print(f"{calls} steps; slowest over {BOUND / 4} s: {slow}")
