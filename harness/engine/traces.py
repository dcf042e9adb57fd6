"""The trace CSV of a run (``traces.csv``): written at once (``write``) or while a run
goes (``lever run --stream``, ``TraceStream``), for runs too long to hold in memory.

Rows are appended to the trace CSV in chunks, each written with one call, flushed and
synced before the run goes on, so a run killed part-way leaves a valid trace file up to
its last chunk (``read`` drops a line cut short).  In memory a stream keeps only what the
report needs, in arrays allocated once: every k-th row (for statistics and plots, at
most ``keep`` rows whatever the run's length), the exact running integrals the energy
balance needs (the trapezoidal integral of the dissipated power over *every* row), and
the process's resident memory at each chunk (to show it stays flat).
"""
from __future__ import annotations

import math
import os
import resource
from contextlib import contextmanager
from pathlib import Path

import numpy as np

#: rows a chunk holds: ~4 s of a 1 ms run, ~0.5 MB of CSV
CHUNK = 4096


def integrals_for(plan) -> dict[str, str]:
    """Running integrals a stream must keep for a checked scene's features
    (harness.description.plan): the coupling's dissipated power -> its dissipated energy
    (the name the reference uses too)."""
    if "energy_balance" not in plan.scene.features:
        return {}
    coupling = plan.roles[1]
    return {f"{coupling}.dissipated_power": f"{coupling}.dissipated_energy"} if coupling else {}


def _header(names) -> str:
    return ",".join(["time"] + list(names)) + "\n"


def _lines(times: np.ndarray, block: np.ndarray) -> str:
    """CSV lines of the rows ``block[i]`` at ``times[i]``; repr: the floats read back exactly."""
    return "".join(",".join(map(repr, [t] + row)) + "\n" for t, row in zip(times.tolist(), block.tolist()))


@contextmanager
def replaced(path: Path):
    """Write ``path`` whole or not at all: yields a temporary name beside it (hidden, with
    the same suffix, so writers that go by the suffix still do), renamed to ``path`` when
    the block ends normally (``os.replace``: atomic), removed when it does not (an
    exception, Ctrl-C); ``path`` is then as it was before."""
    path = Path(path)
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.partial{path.suffix}")
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write(path: Path, times: np.ndarray, traces: dict[str, np.ndarray]):
    """Write a whole run's traces at once, in the format a stream writes (and ``read``
    reads); whole or not at all (``replaced``)."""
    names = list(traces)
    times = np.asarray(times, dtype=float)
    block = np.empty((len(times), len(names)))
    for j, name in enumerate(names):
        block[:, j] = traces[name]
    with replaced(path) as temporary, open(temporary, "w", newline="") as f:
        f.write(_header(names))
        for start in range(0, len(times), CHUNK):
            f.write(_lines(times[start:start + CHUNK], block[start:start + CHUNK]))


def resident_bytes() -> int:
    """The process's resident memory now (Linux /proc; the peak elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


class TraceStream:
    def __init__(self, path: Path, names: list[str], expected_rows: int, keep: int = 200_000,
                 integrate: dict[str, str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.names = list(names)
        self.integrate = {self.names.index(src): out for src, out in (integrate or {}).items() if src in self.names}
        self.stride = max(1, math.ceil(expected_rows / keep))
        capacity = math.ceil(expected_rows / self.stride) + 2
        # Written through at once, so the process's memory is all there from the start
        # (np.empty's pages would be mapped as they fill and look like growth).
        self._kept_times = np.full(capacity, np.nan)
        self._kept = np.full((capacity, len(self.names) + len(self.integrate)), np.nan)
        self.n_kept = 0
        self.rows_written = 0
        self._last: tuple[float, np.ndarray] | None = None     # last row written, with its integrals
        self._last_kept_index = -1
        self.memory: list[tuple[float, int]] = []               # (t, resident bytes) after each chunk
        self._file = open(self.path, "w", newline="")
        self._file.write(_header(self.names))
        self._sync()

    def _sync(self):
        self._file.flush()
        os.fsync(self._file.fileno())

    def append(self, times: np.ndarray, block: np.ndarray):
        """Write rows (``block[i]`` holds the values of ``names`` at ``times[i]``)."""
        n = len(times)
        if n == 0:
            return
        self._file.write(_lines(times, block))
        self._sync()
        # Running integrals by trapezoids, continued from the last row of the previous chunk.
        extra = np.empty((n, len(self.integrate)))
        for k, (column, _) in enumerate(self.integrate.items()):
            t, y = times, block[:, column]
            start = 0.0
            if self._last is not None:
                t = np.concatenate([[self._last[0]], t])
                y = np.concatenate([[self._last[1][column]], y])
                start = self._last[1][len(self.names) + k]
            steps = 0.5 * (y[1:] + y[:-1]) * np.diff(t)
            cumulative = start + np.cumsum(steps)
            extra[:, k] = cumulative if self._last is not None else np.concatenate([[0.0], cumulative])
        full = np.hstack([block, extra])
        index = np.arange(self.rows_written, self.rows_written + n)
        for i in np.flatnonzero(index % self.stride == 0):
            self._keep(times[i], full[i], index[i])
        self._last = (float(times[-1]), full[-1].copy())
        self._last_index = index[-1]
        self.rows_written += n
        self.memory.append((float(times[-1]), resident_bytes()))

    def _keep(self, t, row, index):
        if self.n_kept == len(self._kept_times):
            # More rows than expected (a variable-step run): keep every other one, twice the stride.
            half = (self.n_kept + 1) // 2
            self._kept_times[:half] = self._kept_times[:self.n_kept:2]
            self._kept[:half] = self._kept[:self.n_kept:2]
            self.n_kept, self.stride = half, 2 * self.stride
            if index % self.stride:
                return
        self._kept_times[self.n_kept] = t
        self._kept[self.n_kept] = row
        self.n_kept += 1
        self._last_kept_index = index

    def close(self):
        """Keep the last row too (the energy balance needs both ends) and close the file."""
        if self._last is not None and self._last_kept_index != self._last_index:
            self._keep(self._last[0], self._last[1], self._last_index)
        if not self._file.closed:
            self._file.close()

    def traces(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The kept rows: every ``stride``-th row and the last, with the running integrals."""
        n = self.n_kept
        names = self.names + list(self.integrate.values())
        return self._kept_times[:n].copy(), {name: self._kept[:n, j].copy() for j, name in enumerate(names)}

    def report(self) -> dict:
        rss = [m for _, m in self.memory]
        out = {"trace_file": str(self.path), "rows_written": self.rows_written, "rows_in_memory": self.n_kept,
               "stride": self.stride, "peak_resident_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
        if rss:
            out.update({"resident_MB_after_first_chunk": rss[0] / 2 ** 20, "resident_MB_at_end": rss[-1] / 2 ** 20,
                        "resident_MB_max_while_stepping": max(rss) / 2 ** 20,
                        # ten samples over the run: (simulated time [s], resident memory [MB])
                        "resident_MB_over_the_run": [(t, round(m / 2 ** 20, 1)) for t, m in
                                                     self.memory[::max(1, len(self.memory) // 10)]]})
        return out


def read(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read a trace CSV; a last line cut short by a kill (missing cells or newline) is dropped."""
    text = Path(path).read_text()
    lines = text.split("\n")
    header = lines[0].split(",")
    body = lines[1:]
    if body and body[-1] == "":
        body = body[:-1]                 # the file ends with a complete line
    elif body:
        body = body[:-1]                 # the last line has no newline: cut short
    rows = []
    for line in body:
        cells = line.split(",")
        if len(cells) != len(header):
            break
        rows.append([float(c) for c in cells])
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return data[:, 0], {name: data[:, j] for j, name in enumerate(header[1:], start=1)}
