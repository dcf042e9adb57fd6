"""Ctrl-C: real `lever` subprocesses sent SIGINT.  `lever run` stops within a step and
writes what it computed, marked interrupted (not an FMU failure), exit status 130; the
studies (bench, stability, sweep) log the cases under way as interrupted, keep the
finished ones, stop their workers at once, and a re-run does only what is left."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.engine import interrupt
from harness.engine import traces as trace_files
from harness.studies.cases import INTERRUPTED, CaseLog

def _start(lever_process, *args, **options) -> subprocess.Popen:
    # Its own session, as a terminal's foreground job: SIGINT goes to the whole group.
    return lever_process.start(*args, start_new_session=True, **options)


def _wait_for(condition, process: subprocess.Popen, timeout: float = 120.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "timed out waiting"
        time.sleep(0.05)


def _simulated(progress: str) -> float:
    """The simulated time the last progress bar in ``progress`` (stderr) shows; 0 before one."""
    shown = re.findall(r"\| ([0-9.e+-]+)/[0-9.e+]+ s simulated", progress)
    return float(shown[-1]) if shown else 0.0


def _case_lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()[1:]]


def _interrupt(process: subprocess.Popen, group: bool = True) -> tuple[str, str, float]:
    sent = time.monotonic()
    (os.killpg if group else os.kill)(process.pid, signal.SIGINT)
    out, err = process.communicate(timeout=120)
    return out, err, time.monotonic() - sent


def test_run_interrupted_keeps_the_computed_part(lever_process, tmp_path, fmu_dir):
    out = tmp_path / "run"
    # 600 s simulated: minutes of stepping, so the SIGINT lands in the stepping loop
    # without plots (the Ctrl-C tests below draw them after an interruption): the run's
    # own files are what this test judges
    # SIGINT once the progress bar says steps were taken (not a fixed wait after the start:
    # under load the run had not begun to step 1.5 s after it took its folder's lock)
    bar = tmp_path / "stderr.txt"
    with bar.open("w") as stderr:
        process = _start(lever_process, "run", "kavz685", "--set", "experiment.stop=600", "--no-plots", "--progress",
                         "--out", out, stderr=stderr)
        _wait_for(lambda: _simulated(bar.read_text()) > 0, process)
        _, _, took = _interrupt(process)
    err = bar.read_text()
    assert process.returncode == 130, err
    assert "interrupted at t = " in err and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    diagnosis = summary["diagnosis"]
    assert diagnosis["kind"] == "interrupted" and "fmu" not in diagnosis
    assert summary["ok"] is False and summary["failure"].startswith("interrupted at t = ")
    times, traces = trace_files.read(out / "traces.csv")
    # the rows up to the step it stopped at, on the 1 ms grid, nothing after
    assert 0 < diagnosis["time"] < 600 and times[-1] == pytest.approx(diagnosis["time"], abs=1e-9)
    assert len(times) == diagnosis["step_index"] + 1
    assert all(len(v) == len(times) for v in traces.values())
    assert "interrupted (Ctrl-C)" in (out / "report.md").read_text()
    # Stopped instead of stepping on: what follows SIGINT is writing the rows computed, so it
    # takes no longer than a whole run of that length, timed here beside it
    # (a bound in seconds holds on one machine's load only: 3-14 s seen on 2 cores).
    # Stepping on to 600 s would take minutes.
    clock = time.monotonic()
    same = lever_process.run("run", "kavz685", "--set", f"experiment.stop={diagnosis['time']}", "--no-reference",
                             "--no-plots", "--no-progress", "--out", tmp_path / "same_length")
    whole = time.monotonic() - clock
    assert same.returncode == 0, same.stderr
    assert took < 1.5 * whole, (took, whole)


def test_run_interrupted_while_streaming_keeps_valid_traces(lever_process, tmp_path, fmu_dir):
    out = tmp_path / "stream"
    process = _start(lever_process, "run", "kavz685", "--set", "experiment.stop=600", "--stream", "--no-plots",
                     "--no-progress", "--out", out)
    _wait_for(lambda: (out / "traces.csv").exists() and (out / "traces.csv").stat().st_size > 100_000, process)
    _, err, _ = _interrupt(process)
    assert process.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["diagnosis"]["kind"] == "interrupted"
    times, _ = trace_files.read(out / "traces.csv")
    # every row up to the interruption reached the file, the last chunk included
    assert summary["stream"]["rows_written"] == len(times) == summary["diagnosis"]["step_index"] + 1


def _bench_scene(tmp_path) -> Path:
    scene = tmp_path / "bench_scene.toml"
    scene.write_text('extends = "kavz685"\nname = "bench_scene"\n[experiment]\nstop = 1.0\ntransient = 0.25\n'
                     '[bench]\nsteps = {jacobi = [0.001, 0.0005]}\nmonolithic_rtol = []\n')
    return scene


# The FMI editions side by side are a study of their own (tests/studies/test_bench.py), not
# what is interrupted here.
_BENCH = ["--repeats", "1", "--no-peers", "--no-fmi-editions"]


def test_bench_interrupted_logs_the_case_and_resumes(lever_process, tmp_path, fmu_dir):
    scene, out = _bench_scene(tmp_path), tmp_path / "bench"
    process = _start(lever_process, "bench", scene, *_BENCH, "--out", out)
    log = out / "cases.jsonl"
    # interrupt while the first master case runs (after the floor cases are logged: ours and
    # the do-nothing twins')
    _wait_for(lambda: log.exists() and any(e["key"].startswith("floor|floor-hollow") for e in _case_lines(log)),
              process)
    _, err, _ = _interrupt(process)
    assert process.returncode == 130, err
    assert "interrupted" in err and "resume" in err and "Traceback" not in err
    entries = _case_lines(log)
    statuses = [e["result"].get("status") for e in entries]
    assert "failed" not in statuses
    interrupted = [e for e in entries if e["result"].get("status") == INTERRUPTED]
    assert len(interrupted) == 1 and interrupted[0]["key"].startswith("master|jacobi")
    assert not (out / "bench.md").exists()            # no report of half a benchmark
    # the re-run takes the floor from the log and redoes the interrupted case
    done = lever_process.run("bench", scene, *_BENCH, "--out", out)
    assert done.returncode == 0, done.stderr
    assert "floor" in done.stdout and "(from the case log)" not in done.stdout.split("FMU-call floor")[1]
    cases = {e["key"]: e["result"] for e in _case_lines(log)}
    assert all("status" not in r for r in cases.values())        # every case done: none failed or interrupted


def _stability_args(out):
    # 2000 steps a case (a second or so; 6000 asked for was held to the plan's 4000 at most):
    # after the first case is logged, the two left to run keep the workers busy well past
    # the 50 ms this test takes to see the log and send SIGINT.
    return ["stability", "kavz685", "--stiffness", "1e4", "--damping", "0", "--h-omega", "0.1", "--h-omega", "0.2",
            "--master", "jacobi", "--master", "gauss-seidel", "--min-steps", "2000", "--no-refine", "--jobs", "2",
            "--out", out]


def test_stability_interrupted_stops_its_workers_and_resumes(lever_process, tmp_path, fmu_dir):
    out = tmp_path / "stability"
    process = _start(lever_process, *_stability_args(out))
    log = out / "cases.jsonl"
    _wait_for(lambda: log.exists() and len(log.read_text().splitlines()) >= 2, process)
    workers = subprocess.run(["pgrep", "-P", str(process.pid)], capture_output=True, text=True).stdout.split()
    # SIGINT to the main process alone (as `kill -INT`): it must end its workers itself
    _, err, took = _interrupt(process, group=False)
    assert process.returncode == 130, err
    assert took < 10.0      # at once, not after the queue
    time.sleep(0.5)
    assert workers and not [w for w in workers if Path(f"/proc/{w}").exists()
                            and "zombie" not in Path(f"/proc/{w}/status").read_text().lower()]
    entries = _case_lines(log)
    done = [e for e in entries if e["result"].get("status") == "ok"]
    interrupted = [e for e in entries if e["result"].get("status") == INTERRUPTED]
    assert done and 1 <= len(interrupted) <= 2 and len(done) + len(interrupted) <= 4
    again = lever_process.run(*_stability_args(out))
    assert again.returncode == 0, again.stderr
    assert f"4 cases ({len(done)} already done)" in again.stdout


def test_sweep_interrupted_keeps_finished_cases(lever_process, tmp_path, fmu_dir):
    out = tmp_path / "sweep"
    args = ["sweep", "--axis", "stiffness", "--thin", "3", "--stop", "30", "--set", "experiment.transient=0.2",
            "--workers", "2", "--no-progress", "--out", out]
    process = _start(lever_process, *args)
    _wait_for(lambda: (out / "cases.jsonl").exists(), process)
    time.sleep(2.0)
    _, err, took = _interrupt(process)
    assert process.returncode == 130, err
    assert took < 10.0
    entries = _case_lines(out / "cases.jsonl")
    assert [e for e in entries if e["result"].get("status") == INTERRUPTED]
    assert not [e for e in entries if e["result"].get("status") == "failed"]
    assert not (out / "sweep.md").exists()
    # the log resumes: interrupted cases are not done
    from harness.studies import sweep as sweeps
    log = CaseLog(out, json.loads((out / "cases.jsonl").read_text().splitlines()[0])["fingerprint"])
    assert len(log) == len([e for e in entries if e["result"].get("status") == "ok"])


def test_case_log_redoes_interrupted_cases(tmp_path):
    log = CaseLog(tmp_path, {"study": "t"})
    log.record("a", {"status": "ok", "x": 1})
    with pytest.raises(interrupt.Interrupted):
        log.run("b", lambda: (_ for _ in ()).throw(interrupt.Interrupted(0.25)))
    assert "b" not in log
    with (tmp_path / "cases.jsonl").open("a") as f:
        f.write('{"key": "c", "resu')                     # a line cut short by a kill
    again = CaseLog(tmp_path, {"study": "t"})
    assert "a" in again and "b" not in again and len(again) == 1
    assert json.loads((tmp_path / "cases.jsonl").read_text().splitlines()[-1])["result"] == \
        {"status": INTERRUPTED, "time": 0.25}
    result, reused = again.run("b", lambda: {"status": "ok"})
    assert not reused and "b" in again


# -- Ctrl-C at each named phase of `lever run`, sent by the process itself ----------------------
# ``interrupt.phase`` is called at each phase of a run; here it is replaced by one that
# sends SIGINT to the process when the named phase begins (``times`` SIGINTs: a second one
# is a user who insists), so each phase is hit exactly, whatever the machine's speed.

_HOOKED = """
import os, signal, sys
from harness.engine import interrupt

target, times = sys.argv[1], int(sys.argv[2])
real = interrupt.phase

def phase(name):
    real(name)
    if name == target:
        for _ in range(times):
            os.kill(os.getpid(), signal.SIGINT)

interrupt.phase = phase
sys.argv = ["lever", *sys.argv[3:]]
from harness.cli import entry
entry()
"""

_SHORT = ["--set", "experiment.stop=0.5", "--set", "experiment.transient=0"]


def _run_hooked(phase: str, out: Path, times: int = 1, scene: str = "kavz685", extra=_SHORT):
    done = subprocess.run([sys.executable, "-c", _HOOKED, phase, str(times), "run", scene, *extra, "--no-progress",
                           "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert "Traceback" not in done.stderr, done.stderr
    return done


def _whole_files(out: Path) -> set[str]:
    """The files in ``out``, each checked whole and parseable (no temporary left)."""
    names = set()
    for path in out.iterdir():
        if path.name == ".lever.lock":
            continue
        assert not path.name.startswith("."), f"a temporary file was left: {path.name}"
        data = path.read_bytes()
        if path.suffix == ".csv":
            lines = data.decode().split("\n")
            assert lines[-1] == "", f"{path.name} does not end with a whole line"
            widths = {len(line.split(",")) for line in lines[:-1]}
            assert len(widths) == 1 and len(lines) > 2, f"{path.name}: rows of {widths} cells"
            [float(cell) for line in lines[1:-1] for cell in line.split(",")]
        elif path.suffix == ".json":
            json.loads(data)
        elif path.suffix == ".png":
            assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82"), path.name
        elif path.suffix == ".md":
            assert data.endswith(b"\n") and data.startswith(b"# "), path.name
        names.add(path.name)
    return names


_PLOTS = {"speeds.png", "torques.png", "accelerations.png", "u12_over_angle.png", "spectrum.png",
          "revolution.png", "revolutions.png"}


def test_ctrl_c_while_stepping_writes_the_part_computed(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("stepping", out)
    assert done.returncode == 130 and "interrupted at t = 0.001 s" in done.stderr, done.stderr
    files = _whole_files(out)
    assert {"traces.csv", "summary.json", "report.md"} <= files and "reference.csv" not in files
    summary = json.loads((out / "summary.json").read_text())
    assert summary["diagnosis"]["kind"] == "interrupted" and "interrupted_while_writing" not in summary
    assert len(trace_files.read(out / "traces.csv")[0]) == 2      # the start and the one step taken


def test_ctrl_c_while_solving_the_reference_writes_the_run_without_it(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("reference", out)
    assert done.returncode == 130 and "interrupted while solving the reference" in done.stderr, done.stderr
    files = _whole_files(out)
    assert {"traces.csv", "summary.json", "report.md"} | _PLOTS <= files and "reference.csv" not in files
    assert len(trace_files.read(out / "traces.csv")[0]) == 501
    assert json.loads((out / "summary.json").read_text())["failure"].startswith("interrupted after the run")


def test_ctrl_c_while_writing_the_traces_finishes_them_and_names_the_plots_not_drawn(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("writing traces.csv", out)
    assert done.returncode == 130, done.stderr
    files = _whole_files(out)
    assert files == {"traces.csv", "reference.csv", "summary.json", "report.md"}
    assert len(trace_files.read(out / "traces.csv")[0]) == 501
    not_drawn = json.loads((out / "summary.json").read_text())["interrupted_while_writing"]["not_drawn"]
    assert _PLOTS <= set(not_drawn)
    assert "Not drawn (Ctrl-C while the files were written): speeds.png" in (out / "report.md").read_text()
    assert f"interrupted while writing the run's files to {out}/: not written: speeds.png" in done.stderr


def test_ctrl_c_while_plotting_keeps_the_plots_drawn(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("plotting torques.png", out)
    assert done.returncode == 130, done.stderr
    files = _whole_files(out)
    assert {"traces.csv", "reference.csv", "summary.json", "report.md", "speeds.png"} <= files
    assert not files & (_PLOTS - {"speeds.png"})
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["interrupted_while_writing"]["not_drawn"]) >= _PLOTS - {"speeds.png"}
    assert "speeds.png" in summary["files"] and "torques.png" not in summary["files"]


def test_ctrl_c_while_writing_the_summary_finishes_every_file(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("writing summary.json", out)
    assert done.returncode == 130 and "every file was written whole" in done.stderr, done.stderr
    assert _whole_files(out) >= {"traces.csv", "reference.csv", "summary.json", "report.md"} | _PLOTS


def test_a_second_ctrl_c_while_writing_stops_and_names_what_is_missing(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("writing traces.csv", out, times=2)
    assert done.returncode == 130, done.stderr
    assert _whole_files(out) == set()          # nothing half-written, no temporary file
    assert ("not written: traces.csv, reference.csv, the plots not drawn yet, summary.json, report.md"
            in done.stderr), done.stderr


def test_ctrl_c_while_writing_a_freewheel_run(tmp_path, fmu_dir):
    out = tmp_path / "run"
    done = _run_hooked("writing traces.csv", out, scene="freewheel_rectifier", extra=["--set", "experiment.stop=0.2"])
    assert done.returncode == 130, done.stderr
    files = _whole_files(out)
    assert {"traces.csv", "summary.json", "report.md"} <= files and not [f for f in files if f.endswith(".png")]
    assert len(trace_files.read(out / "traces.csv")[0]) == 1001


def test_dask_sweep_interrupted_logs_the_case_under_way(tmp_path, fmu_dir, monkeypatch):
    """Ctrl-C (the flag, as ``interrupt.deferred`` sets it) once the first case is logged:
    the case a worker is running is logged as interrupted, the queued ones are not logged."""
    distributed = pytest.importorskip("distributed")
    from harness.studies import sweep as sweeps
    from harness.studies import sweep_axes

    axis = sweeps.Axis("stiffness", "3.17", "c", [450.0, 600.0, 900.0], sweep_axes.FIG_317, "coupling.stiffness")
    record = CaseLog.record

    def record_then_interrupt(self, key, result):
        record(self, key, result)
        # Ctrl-C once the worker runs the next case (its call stack shows it), not after a
        # fixed wait: on a fast machine the other cases could all be done by then.  The cases
        # are long enough (8 s simulated) that it is still running when the sweep looks.
        with distributed.Client(cluster.scheduler_address, timeout="30s") as watcher:
            deadline = time.monotonic() + 60.0
            while not any(watcher.call_stack().values()) and time.monotonic() < deadline:
                time.sleep(0.02)
        monkeypatch.setattr(interrupt, "_requested", True)

    monkeypatch.setattr(CaseLog, "record", record_then_interrupt)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with pytest.raises(interrupt.Interrupted):
            sweeps.sweep([axis], tmp_path, stop=8.0, extra=["experiment.transient=0.2"],
                         dask=cluster.scheduler_address, progress=False)
    entries = _case_lines(tmp_path / "cases.jsonl")
    assert [e["result"].get("status") for e in entries] == ["ok", INTERRUPTED]
