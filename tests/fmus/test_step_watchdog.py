"""Every FMU's fmi2DoStep returns, within a bound, for the extremes of every admitted real
parameter (the declared min and max, each with the others at their defaults) and step sizes
from 1e-300 to 1e300, starting at t = 0 and at t = 1e6 s: a step too costly is refused by
name, never ground through while the importer waits.

The steps run in child processes (tests/fmus/step_watchdog_child.py), two at once, each
handed the next case when it has finished one; a child reports each call before making it,
and a call that has not returned within ``BOUND`` seconds fails the test (that child is
killed and another takes its place, so one run reports them all)."""
from __future__ import annotations

import os
import selectors
import subprocess
import sys
import time
from collections import deque
from pathlib import Path

CHILD = Path(__file__).with_name("step_watchdog_child.py")
#: the slowest admitted step: 200,000 RK4 substeps (about 6 s here), with room for a busy machine
BOUND = 60.0
#: children stepping at once: the slowest cases (a chattering freewheel refused after its
#: 10,000th event, a few seconds each) then run side by side rather than one after another
WORKERS = 2


def test_every_step_of_every_fmu_returns_within_the_bound(fmu_dir):
    hangs, slow, unnamed, calls = [], [], [], 0
    pending, total, handed = None, None, set()
    selector = selectors.DefaultSelector()

    def spawn():
        child = subprocess.Popen([sys.executable, str(CHILD), str(fmu_dir)], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, bufsize=0,
                                 env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
        # the last call it began, since when it has been silent, the part of a line read
        selector.register(child.stdout, selectors.EVENT_READ,
                          {"child": child, "current": None, "since": time.monotonic(), "text": b""})

    def hand_on(worker):
        if pending:
            index = pending.popleft()
            handed.add(index)
            worker["child"].stdin.write(f"{index}\n".encode())
        else:
            worker["child"].stdin.close()      # no case left: the child ends

    def handle(worker, line):
        nonlocal pending, total, calls
        current = worker["current"]
        if line.startswith("cases "):
            if pending is None:
                total = int(line.split()[1])
                pending = deque(range(total))
            hand_on(worker)
        elif line.startswith("case done "):
            hand_on(worker)
        elif line.startswith("start "):
            worker["current"] = line.strip()
            calls += 1
        elif line.startswith("done "):
            seconds = float(line.split()[2])
            status, said = int(line.split()[5]), line.split(None, 6)[6:] or [""]
            if status not in (0, 1) and ("internal error" in said[0] or not said[0].strip()):
                unnamed.append(f"{current}: status {status}, {said[0].strip()!r}")
            if seconds > BOUND / 4:
                slow.append(f"{current}: {seconds} s")

    for _ in range(WORKERS):
        spawn()
    while selector.get_map():
        workers = [key.data for key in selector.get_map().values()]
        ready = selector.select(timeout=max(min(w["since"] for w in workers) + BOUND - time.monotonic(), 0.0))
        now = time.monotonic()
        for key, _ in ready:
            worker = key.data
            worker["since"] = now
            # all the pipe holds, read unbuffered: a line left in a reader's buffer would not
            # wake the selector while the child waits for its next case
            data = os.read(key.fileobj.fileno(), 1 << 16)
            if not data:
                selector.unregister(key.fileobj)
                child, current = worker["child"], worker["current"]
                child.wait()
                assert child.returncode == 0 or current is None, f"the child died (rc {child.returncode}) in {current}"
                continue
            # split into lines before decoding: a read may end inside a character of a message
            *lines, worker["text"] = (worker["text"] + data).split(b"\n")
            for line in lines:
                handle(worker, line.decode())
        for key in list(selector.get_map().values()):
            worker = key.data
            if now - worker["since"] >= BOUND:
                # silent for BOUND: the call it began hangs (the rest of that case is skipped)
                worker["child"].kill()
                worker["child"].wait()
                selector.unregister(key.fileobj)
                hangs.append(worker["current"])
                if pending:
                    spawn()
    assert not hangs, f"fmi2DoStep did not return within {BOUND} s: {hangs}"
    assert total and handed == set(range(total)), (total, sorted(handed))
    assert calls > 1000, calls
    assert not unnamed, "steps refused without naming the cause:\n" + "\n".join(unnamed)
    print(f"{calls} steps; slowest over {BOUND / 4} s: {slow}")
