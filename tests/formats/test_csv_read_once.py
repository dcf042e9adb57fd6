"""A CSV of traces (a committed reference, a result) is parsed once a process for the same
bytes at the same path; each read gets arrays of its own, and a file rewritten in place -
the same size, the same modification time - is read anew."""
from __future__ import annotations

import os

import numpy as np

from harness.formats import reference_traces


def test_the_same_bytes_are_parsed_once_and_every_read_gets_its_own_arrays(tmp_path, monkeypatch):
    path = tmp_path / "result.csv"
    path.write_text("time,a\n0,1.5\n1,2.5\n")
    parses = []
    parse = reference_traces._parse_csv
    monkeypatch.setattr(reference_traces, "_parse_csv", lambda *a: parses.append(a[0]) or parse(*a))
    first = reference_traces.read_csv(path)
    first.signals["a"][0] = 99.0                 # a caller's own change stays its own
    second = reference_traces.read_csv(path)
    assert parses == [path]
    assert second.signals["a"].tolist() == [1.5, 2.5] and second.times.tolist() == [0.0, 1.0]
    assert second.signals["a"] is not first.signals["a"]
    # rewritten in place: same size, modification time put back
    stat = path.stat()
    path.write_text("time,a\n0,7.5\n1,8.5\n")
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert path.stat().st_size == stat.st_size
    assert reference_traces.read_csv(path).signals["a"].tolist() == [7.5, 8.5]
    assert parses == [path, path]


def test_a_committed_reference_read_twice_is_the_same(monkeypatch):
    first = reference_traces.read("EngineShaft")
    again = reference_traces.read("EngineShaft")
    assert np.array_equal(first.outputs.times, again.outputs.times)
    assert all(np.array_equal(first.outputs.signals[n], again.outputs.signals[n]) for n in first.outputs.signals)
    assert reference_traces.scene_names() == reference_traces.scene_names()
    assert "kavz685" in reference_traces.scene_names()
