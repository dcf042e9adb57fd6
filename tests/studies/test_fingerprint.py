"""`lever fingerprint`: the before/after check of a refactor (a hash of each run's traces)."""
import numpy as np

from harness.studies.fingerprint import trace_hash


def test_trace_hash_sees_one_bit_and_a_failure():
    times = np.linspace(0.0, 1.0, 11)
    traces = {"a.w": np.sin(times), "b.tau": np.cos(times)}
    base = trace_hash(times, traces, None)
    flipped = traces["a.w"].copy()
    flipped[5] = np.nextafter(flipped[5], np.inf)
    assert trace_hash(times, {**traces, "a.w": flipped}, None) != base
    assert trace_hash(times, traces, "diverged") != base
    assert trace_hash(times, dict(traces), None) == base


def test_fingerprint_command_prints_one_line_per_scene_and_master(lever):
    result = lever("fingerprint", "kavz685", "--master", "jacobi", "--master", "gauss-seidel",
                                       "--stop", "0.01")
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [line.split()[:3] for line in lines] == [["kavz685", "jacobi", "11"], ["kavz685", "gauss-seidel", "11"]]
    assert all(len(line.split()[3]) == 64 for line in lines)
    refused = lever("fingerprint", "kavz685", "--master", "no-such-master")
    assert refused.exit_code == 2 and "no-such-master" in refused.output
