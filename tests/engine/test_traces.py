"""Streamed traces (harness/traces.py, ``lever run --stream``): the file is valid up to
the last chunk when the run is killed, the streamed run equals the ordinary one bit for
bit, and what a stream keeps in memory gives the same energy balance."""
from __future__ import annotations

import os
import signal
import subprocess
import time

import numpy as np
import pytest

from harness.judges import metrics
from harness.description import scene
from harness.engine import traces
from harness.engine.run import simulate

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_stream_keeps_every_kth_row_the_last_one_and_exact_integrals(tmp_path):
    names = ["a", "p"]
    t = np.linspace(0.0, 1.0, 1001)
    block = np.column_stack([np.sin(t), t ** 2])
    stream = traces.TraceStream(tmp_path / "t.csv", names, len(t), keep=100, integrate={"p": "energy"})
    for start in range(0, len(t), 64):            # chunks of any size
        stream.append(t[start:start + 64], block[start:start + 64])
    stream.close()
    kept_t, kept = stream.traces()
    assert stream.stride == 11 and kept_t[0] == 0.0 and kept_t[-1] == 1.0
    assert np.array_equal(kept_t[:-1], t[::11]) and np.array_equal(kept["a"][:-1], block[::11, 0])
    # The running integral covers every row, not only the kept ones.
    full = np.concatenate([[0.0], np.cumsum(0.5 * (block[1:, 1] + block[:-1, 1]) * np.diff(t))])
    assert kept["energy"][-1] == pytest.approx(full[-1], rel=1e-14)
    assert kept["energy"][-1] == pytest.approx(1.0 / 3.0, rel=1e-6)
    read_t, read = traces.read(tmp_path / "t.csv")
    assert np.array_equal(read_t, t) and np.array_equal(read["p"], block[:, 1])      # repr: exact


def test_stream_with_more_rows_than_expected_stays_bounded(tmp_path):
    stream = traces.TraceStream(tmp_path / "t.csv", ["x"], 100, keep=10)
    t = np.arange(1000.0)
    stream.append(t, t[:, None])
    stream.close()
    kept_t, _ = stream.traces()
    assert len(kept_t) <= 14 and kept_t[-1] == 999.0 and np.all(np.diff(kept_t) > 0)
    assert len(stream._kept_times) == 12                                              # never reallocated


def test_reading_drops_a_line_cut_short(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,x\n0.0,1.0\n0.1,2.0\n0.2,3")
    t, x = traces.read(path)
    assert t.tolist() == [0.0, 0.1] and x["x"].tolist() == [1.0, 2.0]
    path.write_text("time,x\n0.0,1.0\n0.1\n")
    assert traces.read(path)[0].tolist() == [0.0]


def test_streamed_run_equals_the_ordinary_run(tmp_path, fmu_dir):
    spec = scene.load("kavz685").with_overrides(["experiment.stop=5"])
    plain = simulate(spec, fmu_dir=fmu_dir)
    streamed = simulate(spec, fmu_dir=fmu_dir, stream=tmp_path / "traces.csv")
    t, written = traces.read(tmp_path / "traces.csv")
    assert np.array_equal(t, plain.times)
    assert all(np.array_equal(written[n], plain.traces[n]) for n in plain.traces)
    assert streamed.stream["rows_written"] == len(t) == 5001
    a = metrics.energy_balance(spec, plain.times, plain.traces)
    b = metrics.energy_balance(spec, streamed.times, streamed.traces)
    assert b["residual_J"] == pytest.approx(a["residual_J"], rel=1e-9, abs=1e-12)


def test_a_run_killed_part_way_leaves_valid_traces(lever_process, tmp_path, fmu_dir):
    out = tmp_path / "killed"
    child = lever_process.start("run", "kavz685", "--set", "experiment.stop=600", "--stream", "--no-progress",
                                "--out", out, cwd=REPO, stdout=subprocess.DEVNULL, text=False)
    path = out / "traces.csv"
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            if path.exists() and path.stat().st_size > 3 * traces.CHUNK * 200:   # about three chunks
                break
            assert child.poll() is None, child.stderr.read().decode()
            time.sleep(0.05)
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    assert child.returncode == -signal.SIGKILL
    t, written = traces.read(path)
    assert len(t) >= 2 * traces.CHUNK and len(t) % traces.CHUNK == 0          # whole chunks only
    assert t[0] == 0.0 and np.allclose(np.diff(t), 1e-3, rtol=1e-9)
    assert all(np.isfinite(v).all() for v in written.values())
    # The rows the killed run left are the rows a complete run computes, bit for bit.
    n = 2 * traces.CHUNK
    spec = scene.load("kavz685").with_overrides([f"experiment.stop={(n - 1) * 1e-3!r}"])
    full = simulate(spec, fmu_dir=fmu_dir)
    assert all(np.array_equal(written[name][:n], full.traces[name][:n]) for name in full.traces)
