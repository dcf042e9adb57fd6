"""The ``lever`` command line."""
from __future__ import annotations

import contextlib
import copy
import json
import math
import os
import sys
from pathlib import Path

import click

from harness import api
from harness.description import kinds
from harness.description import scene as scenes
from harness.paths import FMUS, RESULTS


class UserError(click.ClickException):
    """A problem with the user's input: shown as a message, exit code 2, no traceback."""

    exit_code = 2


#: what to do without a C compiler (the FMUs' native entry is compiled when they are built)
NO_COMPILER = ("the FMUs' native entry is C, compiled when they are built: install a C compiler "
               "(Debian/Ubuntu: sudo apt install gcc; Fedora: sudo dnf install gcc; macOS: xcode-select --install) "
               "or name one with CC (e.g. CC=clang lever build)")


def ensure_fmus(fmu_dir: Path = FMUS, force: bool = False, quiet: bool = False):
    """Build the FMUs when they are missing or older than their sources."""
    try:
        api.build(force, fmu_dir, log=None if quiet else click.echo)
    except RuntimeError as error:
        raise RuntimeError(_with_compiler_hint(error)) from None


def _with_compiler_hint(error: Exception) -> str:
    """The build's message, with what to do when no C compiler could be run."""
    return f"{error}; {NO_COMPILER}" if "cannot run" in str(error) and NO_COMPILER not in str(error) else str(error)


def open_scene(name: str | Path) -> scenes.Scene:
    """The scene NAME: a name in resources/scenes, a .toml file or an SSP archive (.ssp)."""
    return api.load(name)


@contextlib.contextmanager
def _user_errors():
    """``api.InputError`` ends the command with exit code 2 and its message."""
    try:
        yield
    except api.InputError as error:
        raise UserError(str(error)) from None


def _scene(name: str, assignments=()) -> scenes.Scene:
    """The scene NAME (a name, a .toml or an .ssp) with the --set overrides; bad input ends
    the command with exit code 2 and the scene's message."""
    with _user_errors():
        return api.load(name, list(assignments))


def _check_masters(*names: str):
    """End the command with exit code 2 when one of ``names`` is not a master."""
    with _user_errors():
        api.check_masters(*names)


class _Lever(click.Group):
    """The command group: Ctrl-C anywhere a command does not take it itself ends with
    "interrupted" and exit status 130, not click's "Aborted!" and 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as error:
            click.echo(f"\n{error or 'interrupted'}", err=True)
            raise click.exceptions.Exit(INTERRUPTED_EXIT) from None


@click.group(cls=_Lever, context_settings={"help_option_names": ["-h", "--help"]})
def main():
    """Co-simulation of lever-articulated drive-shaft couplings (FMI 2.0, fmpy)."""


@main.command()
@click.option("--force", is_flag=True, help="Rebuild even when the sources did not change.")
@click.option("--out", type=click.Path(path_type=Path), default=FMUS, show_default=True,
              help="Where the FMUs go: build/fmus in a checkout; for a package installed with pip, the user's "
                   "cache folder; LEVER_FMU_DIR chooses another.")
def build(force, out):
    """Build the FMUs (LeverCoupling, EngineShaft, LoadShaft, FreewheelRectifier,
    MisalignmentSource)."""
    try:
        ensure_fmus(out, force)
    except RuntimeError as error:
        raise click.ClickException(str(error)) from None


@main.command("scenes")
def list_scenes():
    """List the committed scenes (resources/scenes)."""
    for name, description in api.scenes_list().items():
        click.echo(f"{name:24s} {description}")


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
              help="Override a parameter: component.parameter=value (e.g. coupling.stiffness=900, "
                   "coupling.misalignment='20 deg') or experiment.stop=5.")
@click.option("--master", type=str, default=None, help="Co-simulation master (default: the scene's).")
@click.option("--step", type=float, default=None, help="Communication step [s] (default: the scene's).")
@click.option("--stop", type=float, default=None,
              help="Stop time [s] (as --set experiment.stop=S); a scene's start-up transient that does not fit the "
                   "shorter run takes the same share of it (said before the run).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/<scene>).")
@click.option("--tolerance", type=float, default=None,
              help="Tolerance of an adaptive master (relative torque error per step) or of an iterative "
                   "master's coupling iteration.")
@click.option("--no-reference", is_flag=True, help="Skip the monolithic reference solution.")
@click.option("--strict", is_flag=True, help="Refuse the scene when an input is connected to nothing and not set "
              "(as experiment.strict = true); without it such an input is named and held at its start value.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
@click.option("--stream", is_flag=True, help="For long runs: write traces.csv while running (synced chunks: a "
              "run killed part-way leaves valid traces), keep every k-th row in memory for the report, skip "
              "the reference (the energy balance, integrated over every row, judges the run).")
@click.option("--latency", is_flag=True, help="Time every step for real-time use: median, p99, p99.9 and maximum "
              "step time, the start-up steps and why the slowest were slow (latency.md, latency.json).")
def run(scene, assignments, master, step, stop, tolerance, out, no_reference, strict, progress, stream, latency):
    """Run SCENE (a name in resources/scenes, a .toml path or an SSP archive .ssp) and
    write traces, plots, summary.json and report.md."""
    from harness.formats import outputs

    with _user_errors():
        spec = api.load(scene, list(assignments), stop=stop, strict=strict)
    out = out or RESULTS / spec.name        # claimed by api.run after its checks, before the run
    show_progress = sys.stderr.isatty() if progress is None else progress
    from harness.studies import latency as step_latency

    timer = step_latency.StepTimer() if latency else None
    try:
        done = api.run(spec, master=master, step=step, tolerance=tolerance, reference=not no_reference, out=out,
                       progress=show_progress, stream=stream, observer=timer,
                       notify=lambda kind, message: click.echo(f"{kind}: {message}", err=True))
    except api.InputError as error:
        outputs.abandon(out)             # refused before the run: no empty folder left
        raise UserError(str(error)) from None
    except api.BuildError as error:
        outputs.abandon(out)
        raise click.ClickException(f"building the FMUs failed: {_with_compiler_hint(error)}") from None
    result, out = done.result, done.out
    _print_summary(done.summary, out)
    if timer is not None:
        for line in step_latency.report(out, timer, result):
            click.echo(line)
    if result.interrupted:
        click.echo(f"{result.failure}; what was computed is in {out}/ (marked interrupted)", err=True)
        sys.exit(INTERRUPTED_EXIT)
    if not result.ok:
        click.echo(f"error: {result.failure}", err=True)
        if result.failure_stage == "initialisation":
            # Refused before the first step: the scene's values are at fault, not the run.
            sys.exit(UserError.exit_code)
        click.echo(f"the traces computed before the failure are in {out / 'traces.csv'}", err=True)
        sys.exit(1)


#: exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells report it)
INTERRUPTED_EXIT = 130


def _claim_out(out: Path) -> Path:
    """``out`` made, proven writable and locked for this command (exit 2 with a sentence
    when it cannot be, or another lever is writing there)."""
    from harness.formats import outputs

    try:
        return outputs.claim(out)
    except outputs.OutputError as error:
        raise UserError(str(error)) from None


@contextlib.contextmanager
def _resumable(out: Path):
    """A study that resumes from OUT/cases.jsonl: Ctrl-C ends it with exit status 130 and
    says what was kept."""
    try:
        yield
    except KeyboardInterrupt:
        click.echo(f"\ninterrupted: the finished cases are kept in {out / 'cases.jsonl'} (the ones under way are "
                   "logged as interrupted); run the same command again to resume", err=True)
        sys.exit(INTERRUPTED_EXIT)


def _print_summary(summary: dict, out: Path):
    click.echo(f"{summary['scene']}: master {summary['master']}, step {summary['step_s']:g} s, "
               f"wall time {summary['wall_time_s']:.2f} s")
    stats = summary.get("statistics") or {}
    if stats and not any(stats.values()):
        click.echo(f"  no statistics: the run ended before the start-up transient did (t < {summary['transient_s']:g} s)")
    for short in ("w1", "w2", "tau1", "tau2"):
        s = stats.get(short)
        if s:
            extra = f", unevenness {s['unevenness']:.4f}" if "unevenness" in s else ""
            click.echo(f"  {short:5s} mean {s['mean']:10.4f}  amplitude {s['amplitude']:9.4f}{extra}")
    errs = summary.get("error_vs_reference") or {}
    if errs:
        click.echo("  error vs reference (RMS, relative): " + ", ".join(
            f"{k} {100 * v['rms_relative']:.3g} %" for k, v in errs.items()))
    eb = summary.get("energy_balance")
    if eb:
        click.echo(f"  energy residual: {100 * eb['residual_relative']:.2g} % of the work in")
    if summary.get("energy_balance_unavailable"):
        click.echo(f"  energy balance: not computed: {summary['energy_balance_unavailable']}")
    if summary.get("stream"):
        s = summary["stream"]
        click.echo(f"  streamed {s['rows_written']} rows to {s['trace_file']} (1 in {s['stride']} kept for the "
                   f"report); resident memory {s.get('resident_MB_after_first_chunk', 0):.0f} MB after the first "
                   f"chunk, {s.get('resident_MB_at_end', 0):.0f} MB at the end, peak {s['peak_resident_MB']:.0f} MB")
    click.echo(f"  results: {out}/ (report.md, summary.json, traces.csv, *.png)")


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--repeats", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per case; the median run time is quoted.")
@click.option("--only", "only", multiple=True, metavar="MASTER", help="Bench only these masters (repeatable).")
@click.option("--no-peers", is_flag=True, help="Leave out fmpy and libcosim.")
@click.option("--no-monolithic", is_flag=True, help="Leave out the monolithic scipy solutions.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/bench/<scene>).")
@click.option("--fresh", is_flag=True, help="Start afresh instead of resuming from the cases already in "
              "OUT/cases.jsonl (the earlier log is kept, renamed).")
def bench(scene, repeats, only, no_peers, no_monolithic, out, fresh):
    """Error against run time for every master (and peers) on SCENE: writes bench.csv,
    bench.md, bench.json and work_precision.png."""
    from harness.studies import bench as benchmark

    try:
        spec = open_scene(scene)
        benchmark.plan(spec, list(only))      # refuses unknown masters before anything runs
    except (api.InputError, ValueError) as error:
        raise UserError(str(error)) from None
    ensure_fmus(quiet=True)
    out = _claim_out(out or benchmark.default_out(spec))
    with _resumable(out), _user_errors():
        result = api.bench(spec, repeats=repeats, only=list(only), peers=not no_peers, monolithic=not no_monolithic,
                           progress=click.echo, out=out, claimed=True, resume=not fresh)
    paths = result["written"]
    click.echo("")
    for line in benchmark.summary_lines(result):
        click.echo(line)
    click.echo("written: " + ", ".join(str(p) for p in paths))


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--stiffness", "stiffnesses", type=float, multiple=True, metavar="C",
              help="Coupling stiffness [N*m/rad] to sweep (repeatable; default: the scene's, 1e4, 1e5, 1e6).")
@click.option("--damping", "dampings", type=float, multiple=True, metavar="B",
              help="Coupling damping [N*m*s/rad] to sweep (repeatable; default: the scene's, a tenth, 0).")
@click.option("--h-omega", "h_omegas", type=float, multiple=True, metavar="X",
              help="Communication step as h*omega_n (repeatable; default 0.05 ... 5, 7 values).")
@click.option("--master", "masters", multiple=True, metavar="MASTER",
              help="Fixed-step master to sweep (repeatable; default: all).")
@click.option("--dense", is_flag=True, help="Denser default grids (7 stiffnesses, 5 dampings, 19 steps).")
@click.option("--min-steps", type=click.IntRange(16, 100000), default=500, show_default=True,
              help="Least communication steps per case.")
@click.option("--no-refine", is_flag=True, help="Do not add cases at 0.9 and 1.1 times each predicted edge.")
@click.option("--jobs", type=click.IntRange(1, 64), default=min(2, os.cpu_count() or 1),
              show_default="2; 1 on a one-core machine", help="Cases run in parallel (processes).")
@click.option("--fresh", is_flag=True, help="Start afresh instead of resuming from the case log.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/stability/<scene>).")
@click.option("--progress/--no-progress", default=True, show_default=True,
              help="Progress lines: the cases planned and already done, every 50 cases run.")
def stability(scene, stiffnesses, dampings, h_omegas, masters, dense, min_steps, no_refine, jobs, fresh, out,
              progress):
    """The stability map of SCENE: every case classified (stable / energy-drifting /
    divergent) against the edges the linear analysis predicts; writes stability.md,
    stability.csv, stability_map.png and the resumable case log cases.jsonl."""
    from harness.studies import stabilitymap

    try:
        spec = open_scene(scene)
        plan = stabilitymap.default_plan(spec, dense)
    except (scenes.SceneError, kinds.NotADriveline, ValueError) as error:
        raise UserError(str(error)) from None
    unknown = [m for m in masters if m not in stabilitymap.FIXED_STEP_MASTERS]
    if unknown:
        raise UserError(f"--master {', '.join(unknown)}: not a fixed-step master (known: "
                        f"{', '.join(stabilitymap.FIXED_STEP_MASTERS)})")
    for name, values, low in (("--stiffness", stiffnesses, 0.0), ("--h-omega", h_omegas, 0.0)):
        if any(not (math.isfinite(v) and v > low) for v in values):
            raise UserError(f"{name}: values must be finite and > {low:g}")
    if any(not (math.isfinite(v) and v >= 0) for v in dampings):
        raise UserError("--damping: values must be finite and >= 0")
    plan.stiffnesses = sorted(set(stiffnesses)) or plan.stiffnesses
    plan.dampings = sorted(set(dampings), reverse=True) or plan.dampings
    plan.h_omegas = sorted(set(h_omegas)) or plan.h_omegas
    plan.masters = list(dict.fromkeys(masters)) or plan.masters
    plan.min_steps = min_steps
    plan.refine = not no_refine
    ensure_fmus(quiet=True)
    out = _claim_out(out or stabilitymap.default_out(spec))
    with _resumable(out):
        result = stabilitymap.sweep(spec, plan, out, jobs=jobs, resume=not fresh,
                                    progress=click.echo if progress else None)
    paths = stabilitymap.write(out, result)
    agreed = stabilitymap.agreement(result)
    if agreed["explicit_rows"]:
        click.echo(f"explicit masters: predicted edge inside the observed bracket in {agreed['explicit_bracketed']} "
                   f"of {agreed['explicit_rows']} rows; observed/predicted median {agreed['explicit_ratio_median']:.3g}")
    for m, s in agreed["by_master"].items():
        click.echo(f"  {m:24s} prediction agrees in {s['agree']}/{s['cases']} cases")
    click.echo("written: " + ", ".join(str(p) for p in paths))


@main.command()
@click.argument("name", type=click.Choice(["transfer-modes", "runup"]))
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "studies", show_default=True)
@click.option("--scan", "lags", multiple=True, type=float,
              help="runup: settling times of kavz685_runup_rest at this engine torque lag [s] (repeatable)")
def study(name, out, lags):
    """Recompute the numbers behind a documented decision (docs/decisions.md) or statement
    (runup: the no-load run-up beside the monograph's 0.42 s, docs/models-and-fmus.md)."""
    if name == "runup":
        from harness.studies import runup

        for lag in lags:
            if not (math.isfinite(lag) and 0.0 <= lag <= 100.0):
                raise UserError(f"--scan {lag}: engine.torque_lag must be in [0, 100] s")
        text = runup.scan(lags) if lags else runup.markdown(runup.table())
        out.mkdir(parents=True, exist_ok=True)
        (out / "runup.md").write_text(text + "\n")
        click.echo(text)
        click.echo(f"written to {out / 'runup.md'}")
        return
    if lags:
        raise UserError("--scan applies to the runup study only")
    from harness.studies import decisions as studies

    ensure_fmus(quiet=True)
    click.echo(studies.transfer_modes(out))
    click.echo(f"written to {out / 'transfer_modes.md'}")


def _measured_report(files, out: Path, stiffness: float | None = None, cycles: bool = True):
    """Model against measurement for ``files`` (default: the monograph's data): print a
    line per grade and the findings; exit 1 when there are findings."""
    import json

    from harness.studies import measured

    if stiffness is not None and not (math.isfinite(stiffness) and stiffness > 0):
        raise UserError(f"--stiffness {stiffness}: must be > 0 N*m/rad")
    _, unusable = measured.pair_tables(list(files) or measured.default_files())
    if unusable:       # the files are at fault, not the model: bad input
        raise UserError("the measurement files cannot be used:\n  - " + "\n  - ".join(unusable))
    ensure_fmus(quiet=True)
    findings = measured.validate_measured(list(files) or measured.default_files(), out, stiffness=stiffness,
                                          cycles=cycles)
    grades = json.loads((out / "measured.json").read_text())["grades"]
    for g in grades:
        click.echo(f"  {g['grade']:12s} c {g['conditions']['stiffness']:6g} N*m/rad: RMS error model "
                   f"{100 * g['rms_model']:5.1f} %, naive {100 * g['rms_naive']:5.1f} %, scatter "
                   f"{100 * g['scatter']:4.1f} %; A measured {g['amplitude_measured']:5.1f}, predicted "
                   f"{g['amplitude_predicted']:5.1f} N*m  {'ok' if g['within_target'] else 'ABOVE TARGET'}")
    for finding in findings:
        click.echo(f"finding: {finding}", err=True)
    click.echo(f"written: {out / 'measured.md'}")
    if findings:
        sys.exit(1)


@main.command("measured")
@click.argument("files", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option("--stiffness", type=float, default=None,
              help="Torsional stiffness of the grade [N*m/rad], when the files do not state it (overrides them).")
@click.option("--no-cycles", is_flag=True, help="Compare the mean curves only (one run a grade).")
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "measured", show_default=True)
def measured_command(files, stiffness, no_cycles, out):
    """Model against measurement: predict the drive-shaft torque from the measured
    driven-shaft torque for every grade in FILES (tables or folders; default: the
    monograph's data) and report the errors (measured.md, measured.json, plots).  Exit
    code 1 when a grade misses the monograph's stated model-experiment difference."""
    _measured_report(files, out, stiffness, not no_cycles)


@main.command("sweep")
@click.option("--axis", "axes", multiple=True, metavar="NAME",
              help="Sweep only these axes (repeatable): load, inertia, stiffness, damping, misalignment, "
                   "stiffness_measured, load_alpha0, load_alpha5 (default: all).")
@click.option("--scene", default="kavz685", show_default=True, help="Base scene.")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override the base scene.")
@click.option("--stop", type=float, default=None, help="Simulated time per case [s] (default: the scene's).")
@click.option("--thin", type=click.IntRange(1, 100), default=1, help="Every n-th value of each axis (ends kept).")
@click.option("--workers", type=click.IntRange(1, 256), default=None, help="Local processes (default: CPU count).")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS",
              help="Run the cases on the Dask cluster at ADDRESS (e.g. tcp://scheduler:8786) instead.")
@click.option("--no-resume", is_flag=True, help="Start afresh instead of reusing finished cases.")
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "sweep", show_default=True)
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
def sweep_command(axes, scene, assignments, stop, thin, workers, dask_address, no_resume, out, progress):
    """The monograph's parameter studies (Figs. 3.15-3.18, 4.8, 4.12): amplitude and mean
    curves with its reported points overlaid, and a trend report (sweep.md, sweep.json,
    sweep_<axis>.png).  Finished and failed cases are kept in OUT/cases.jsonl; a re-run
    resumes."""
    from harness.studies import sweep as sweeps

    try:
        chosen = sweeps.thin(sweeps.select(list(axes)), thin)
        open_scene(scene).with_overrides(list(assignments))
    except (ValueError, scenes.SceneError) as error:
        raise UserError(str(error)) from None
    if stop is not None and not (math.isfinite(stop) and stop > 0):
        raise UserError(f"--stop {stop}: must be > 0 s")
    try:
        sweeps.check(chosen, scene, stop, list(assignments))
    except scenes.SceneError as error:
        raise UserError(str(error)) from None
    ensure_fmus(quiet=True)
    show_progress = sys.stderr.isatty() if progress is None else progress
    _claim_out(out)
    try:
        with _resumable(out):
            report = sweeps.sweep(chosen, out, scene=scene, stop=stop, extra=list(assignments), workers=workers,
                                  dask=dask_address, progress=show_progress, resume=not no_resume)
    except scenes.SceneError as error:
        raise UserError(str(error)) from None
    except OSError as error:       # e.g. no Dask scheduler at the address
        raise click.ClickException(f"the sweep could not run: {error}") from None
    failed = [c for c in report["cases"] if c["result"].get("status") != "ok"]
    for t in report["trends"]:
        verdict = {"yes": "reproduced", "partly": "partly", "no": "NOT reproduced",
                   sweeps.NOT_JUDGED: sweeps.NOT_JUDGED}[t["reproduced"]]
        click.echo(f"  {verdict:14s}  {t['trend']}" + (f" (holds for {', '.join(t['holds_for'])})"
                                                       if t["reproduced"] == "partly" else "")
                   + (f" ({t['numbers']})" if t["reproduced"] == sweeps.NOT_JUDGED else ""))
    click.echo(f"{len(report['cases']) - len(failed)} cases ok, {len(failed)} failed; written: {out / 'sweep.md'}")
    for c in failed:
        click.echo(f"  failed: {c['axis']} = {c['x']:g}: {c['result'].get('error')}", err=True)
    if failed:
        sys.exit(1)


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--engine", "engine_names", multiple=True, metavar="ENGINE",
              help="Only these engines (repeatable; default all: lever, lever-jacobi, container, fmpy-ssp, "
                   "libcosim-ssp, libcosim-ecco).")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override (as for `lever run`).")
@click.option("--step", type=float, default=None, help="Communication step [s] (default: the scene's).")
@click.option("--repeats", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per engine; the median run time is quoted.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/engines/<scene>).")
def engines(scene, engine_names, assignments, step, repeats, out):
    """SCENE in every engine that runs our FMUs (ours, fmpy.ssp, libcosim, the container
    FMU): error against the monolithic reference and run time; writes engines.md and
    engines.json."""
    from harness.studies import engines as comparison

    spec = _scene(scene, assignments)
    chosen = list(engine_names) or list(comparison.ENGINES)
    unknown = [n for n in chosen if n not in comparison.ENGINES]
    if unknown:
        raise UserError(f"unknown engine {', '.join(unknown)} (known: {', '.join(comparison.ENGINES)})")
    ensure_fmus(quiet=True)
    rows = comparison.compare(spec, chosen, step, repeats, spec.fmu_dir or FMUS, progress=click.echo)
    paths = comparison.write(out or comparison.default_out(spec), spec, rows)
    click.echo("written: " + ", ".join(str(p) for p in paths))


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--host", "host_names", multiple=True, metavar="HOST",
              help="Only these hosts (repeatable; default all: harness-jacobi, libcosim-fixed, ecos, ecos-serial, "
                   "ecos-log-all, c-importer).")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override (as for `lever run`).")
@click.option("--step", type=float, default=1e-3, show_default=True, help="Communication step [s].")
@click.option("--repeats", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per host; the median is quoted.")
@click.option("--fmu-dir", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Time these FMUs (e.g. another build) instead of build/fmus.")
@click.option("--native-env", type=click.Choice(["bare", "set-up"]), default="bare", show_default=True,
              help="The environment of ecos and the C importer: bare (PATH only), or set up with LD_PRELOAD, "
                   "PYTHONHOME and PYTHONPATH of this Python (what FMUs that cannot find a Python need).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/hosts/<scene>).")
def hosts(scene, host_names, assignments, step, repeats, fmu_dir, native_env, out):
    """SCENE in hosts we did not write (libcosim, ecos) and in our harness (jacobi), at one
    fixed step: each host's median stepping time and its ratio to ours, in one run;
    writes hosts.md and hosts.json."""
    from .studies import hosts as comparison

    spec = _scene(scene, assignments)
    chosen = tuple(host_names) or comparison.HOSTS
    unknown = [n for n in chosen if n not in comparison.HOSTS]
    if unknown:
        raise UserError(f"unknown host {', '.join(unknown)} (known: {', '.join(comparison.HOSTS)})")
    if fmu_dir is None:
        ensure_fmus(quiet=True)
    environment = comparison.set_up_environment() if native_env == "set-up" else None
    report = comparison.time_hosts(spec, step, repeats, fmu_dir or spec.fmu_dir or FMUS, chosen, environment,
                                   log=click.echo)
    folder = out or comparison.default_out(spec)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "hosts.json").write_text(json.dumps(report, indent=1))
    (folder / "hosts.md").write_text(comparison.table(report))
    click.echo(comparison.table(report))
    click.echo(f"written: {folder / 'hosts.md'}, {folder / 'hosts.json'}")


def _export(scene, assignments, out, folder: str, suffix: str, export, how_to_run: dict | None = None):
    """Write SCENE (with the --set overrides) with ``export(spec, out, fmu_dir)`` to OUT,
    by default results/<folder>/<scene>.<suffix>; then say what each engine in
    ``how_to_run`` (engine -> how, ARCHIVE standing for the file) needs to run it."""
    from harness.engine.system import SceneInvalid

    spec = _scene(scene, assignments)
    ensure_fmus(quiet=True)
    out = out or RESULTS / folder / f"{spec.name}.{suffix}"
    try:
        path = export(spec, out, spec.fmu_dir or FMUS)
    except SceneInvalid as error:
        raise UserError(str(error)) from None
    click.echo(f"written: {path}")
    if how_to_run:
        click.echo("runs with its parameter values in:")
        for engine, how in how_to_run.items():
            click.echo(f"  {engine + ':':10s} {how.replace('ARCHIVE', str(path))}")


def _export_command(name: str, written: str, default: str):
    """A ``lever export-*`` command: SCENE, ``--set`` overrides and ``--out`` (the
    ``written`` file; ``default``: where ``_export`` puts it without one)."""
    def wrap(function):
        function = click.option("--out", type=click.Path(path_type=Path), default=None,
                                help=f"The {written} to write (default {default}).")(function)
        function = click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
                                help="Override a parameter before exporting (as for `lever run`).")(function)
        function = click.argument("scene", default="kavz685")(function)
        return main.command(name)(function)
    return wrap


@_export_command("export-ssp", "archive", "results/ssp/<scene>.ssp")
def export_ssp(scene, assignments, out):
    """Write SCENE as an SSP archive: SystemStructure.ssd, the FMUs (with their OSP model
    descriptions), each component's parameter set (.ssv, bound to it) and all of them in
    one set with qualified names (resources/qualified/parameters.ssv).  With its values it
    runs in `lever run ARCHIVE` and libcosim (they read the bindings), in ecos with
    `--parameterSet scene` (ecos applies only the set it is told to), and in fmpy.ssp
    only with `parameter_set=read_ssv(ARCHIVE, resource='resources/qualified/parameters.ssv')`:
    fmpy 0.3's simulate_ssp applies no binding of the SSD and, without that argument, runs
    every FMU on its defaults without a word."""
    from harness.formats import ssp

    _export(scene, assignments, out, "ssp", "ssp", ssp.export, ssp.HOW_TO_RUN)


@_export_command("export-container", "FMU", "results/container/<scene>.fmu")
def export_container(scene, assignments, out):
    """Write SCENE as one FMU (fmpy's container FMU holding the scene's FMUs): its
    parameters are the scene's values, its outputs the scene's recorded variables, its
    internal step the scene's step (Jacobi, as the harness's `jacobi` master)."""
    from harness.formats import container

    _export(scene, assignments, out, "container", "fmu", container.build_container)


@main.command("compliance")
@click.argument("fmus", nargs=-1, type=click.Path(path_type=Path))
def compliance_command(fmus):
    """Compliance checks on FMU files (default: the built ones): fmpy's validation plus
    ours (types, units, ranges, documentation, requirements, OSP ports).  Exit code 1
    when there are findings."""
    from harness.compliance import check_fmu

    if not fmus:
        ensure_fmus(quiet=True)
        fmus = sorted(FMUS.glob("*.fmu"))
    total = 0
    for path in fmus:
        findings = check_fmu(path)
        total += len(findings)
        click.echo(f"{path}: {len(findings)} finding{'' if len(findings) == 1 else 's'}")
        for finding in findings:
            click.echo(f"  - {finding}")
    if total:
        sys.exit(1)


@main.command("reference")
@click.argument("names", nargs=-1, metavar="[NAMES]...")
@click.option("--update", is_flag=True, help="Regenerate the traces (all, or NAMES) and write them.")
def reference_command(names, update):
    """Check that the committed reference traces (resources/reference/) are what the project
    computes now; with --update, regenerate them and show what changed (per signal: max change).

    NAMES are FMUs (LeverCoupling, EngineShaft, LoadShaft) or scenes; default: all.
    Exit code without --update: 0 when every trace is current, 1 otherwise."""
    from harness.formats import reference_traces as crosscheck
    from harness.judges.monolithic import ReferenceUnavailable

    chosen = _reference_names(names)
    stale = []
    for name in chosen:
        try:
            fresh = crosscheck.generate(name)
        except (ReferenceUnavailable, scenes.SceneError) as error:
            click.echo(f"{name}: no reference ({error})")
            continue
        try:
            committed = crosscheck.read(name)
        except crosscheck.TraceFileError:
            committed = None
        diff = crosscheck.difference(committed, fresh)
        if diff.current:
            click.echo(f"{name}: current")
            continue
        stale.append(name)
        if update:
            crosscheck.write(fresh)
            click.echo(f"{name}: updated ({crosscheck.paths(name)['ref'].parent})")
        else:
            click.echo(f"{name}: NOT current (`lever reference --update {name}` regenerates it)")
        for problem in diff.problems:
            click.echo(f"  {problem}")
        for change in diff.changes:
            click.echo(f"  {change.signal:24s} max change {change.max_change:11.4g} "
                       f"({100 * change.relative:.3g} % of its largest magnitude) at t = {change.at_time:.6g} s")
    if stale and not update:
        sys.exit(1)


def _reference_names(names) -> list[str]:
    from harness.formats import reference_traces as crosscheck

    known = crosscheck.all_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UserError(f"no reference '{', '.join(unknown)}' (known: {', '.join(known)})")
    return list(names) or known


def fmu_start_values(model: str, assignments) -> dict:
    """``--set name=value`` for an FMU run stand-alone (``api.fmu_start_values``); exit 2
    with its message on bad input."""
    with _user_errors():
        return api.fmu_start_values(model, assignments)


@main.command("validate")
@click.argument("names", nargs=-1, metavar="[NAMES]...")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
              help="Change a parameter of the run under test, not of the reference: component.parameter=value "
                   "for a scene, parameter=value for an FMU (e.g. --set coupling.stiffness=800).")
@click.option("--master", type=str, default=None, help="Master for a scene (default: the scene's).")
@click.option("--step", type=float, default=None, help="Communication step for a scene [s] (default: the scene's).")
@click.option("--result", "result_csv", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Validate this CSV from another tool's run of NAME instead of running it: a 'time' column and "
                   "columns named like the reference's signals (component.variable for a scene, the FMU's "
                   "variable names for an FMU; 'anything.variable' also matches an FMU's variable).")
@click.option("--tolerance", type=click.Choice(["lever", "cross-check"]), default="lever", show_default=True,
              help="The band's figures: 'lever' (1 % of each signal's range, one result step, at most 1 % of the "
                   "samples outside) or the FMI cross-check's (10 %, 2 % of the span, at most 10 % outside).")
@click.option("--measured", is_flag=True,
              help="Model vs measurement instead (lever validate --measured GRADE_FILES...): NAMES are "
                   "measurement files (drive and driven torque tables of a rubber grade), handed with --out to "
                   "the model-vs-measurement check (as lever measured; default: the monograph's grades).")
@click.option("--window", default=None, metavar="START:STOP",
              help="Judge only this span of the reference [s] (e.g. 0:1 for a 1 s result, 2:10 for the steady "
                   "part; an empty side is the reference's own start or stop); the verdict says the span judged.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/validate/<NAME>).")
def validate_command(names, assignments, master, step, result_csv, tolerance, window, measured, out):
    """Run each NAME (an FMU stand-alone, driven by its _in.csv under fmpy's simulate_fmu;
    or a scene, with its master) and compare every recorded output with its committed
    reference trace: RMS and max error, fraction of samples outside the tolerance band,
    pass/fail per signal; a plot per failing signal.  NAMES default: every reference.

    Exit code: 0 only when every signal of every NAME passes; 1 when one fails;
    2 on bad input."""
    if measured:
        _measured_report([Path(n) for n in names], out or RESULTS / "validate" / "measured")
        return

    chosen = _reference_names(names)
    if result_csv is not None and len(chosen) != 1:
        raise UserError("--result: name exactly one reference the CSV is to be compared with "
                        "(e.g. lever validate --result run.csv kavz685)")
    with _user_errors():
        span = api.parse_window(window)
    if step is not None and (problem := scenes.step_problem(step, "--step")):
        raise UserError(problem)
    if result_csv is None:
        try:
            ensure_fmus(quiet=True)
        except RuntimeError as error:
            raise click.ClickException(f"building the FMUs failed: {error}") from None
    all_passed = True
    for name in chosen:
        target = out if (out and len(chosen) == 1) else (out or RESULTS / "validate") / name
        with _user_errors():
            verdict = api.validate(name, overrides=list(assignments), master=master, step=step, result=result_csv,
                                   tolerance=tolerance, window=span, out=target)
        _print_validation(name, verdict.findings, verdict.result, target)
        all_passed &= verdict.passed
    sys.exit(0 if all_passed else 1)


def _print_validation(name, findings, result, out: Path):
    click.echo(f"{name}: {result.how}; tolerance {findings.tolerance.describe()}")
    if findings.span:
        click.echo(f"  judged: {findings.describe_span()}")
    click.echo(f"  {'signal':24s} {'RMS error':>11s} {'max error':>11s} {'at t [s]':>9s} {'band +-':>10s} "
               f"{'outside':>8s}  verdict")
    for s in findings.signals:
        click.echo(f"  {s.name:24s} {s.rms_error:11.4g} {s.max_error:11.4g} {s.max_error_time:9.4g} "
                   f"{s.band_width:10.4g} {100 * s.fraction_outside:7.3g}%  {'pass' if s.passed else 'FAIL'}")
    for problem in findings.problems:
        click.echo(f"  problem: {problem}")
    for note in findings.notes:
        click.echo(f"  note: {note}")
    verdict = "PASS" if findings.passed else "FAIL" + (
        f" ({', '.join(findings.failed_signals)})" if findings.failed_signals else "")
    span = f" over {findings.describe_span()}" if findings.span else ""
    click.echo(f"  {name}: {verdict}{span}; written to {out}/")


@main.command("fingerprint")
@click.argument("names", nargs=-1, metavar="[SCENES]...")
@click.option("--master", "masters", multiple=True, help="Only this master (repeatable; default: every master).")
@click.option("--stop", type=float, default=0.2, show_default=True,
              help="Run each scene for at most this many seconds (0: each scene's own length).")
def fingerprint_command(names, masters, stop):
    """Print a SHA-256 of the traces of every committed scene (or SCENES) run with every
    master: `lever fingerprint > before.txt`, change the code, run it again and `diff`
    - a refactor that keeps behaviour leaves every line the same, bit for bit."""
    from harness.studies.fingerprint import fingerprints

    _check_masters(*masters)
    if not (math.isfinite(stop) and stop >= 0):
        raise UserError(f"--stop {stop}: must be >= 0 s (0: each scene's own length)")
    ensure_fmus(quiet=True)
    try:
        for name, master, rows, digest in fingerprints(list(names) or None, list(masters) or None, stop or None):
            click.echo(f"{name:28s} {master:24s} {rows:7d} {digest}")
    except scenes.SceneError as error:
        raise UserError(str(error)) from None


@main.command("badinputs")
@click.option("--verbose", is_flag=True, help="Also print every case with the message the FMU logged.")
def bad_inputs(verbose):
    """Run the bad-input corpus (harness/formats/badinputs.py) through fmpy's FMU2Slave on the built
    FMUs: every case must be refused with an FMI error naming the variable and its range."""
    from harness.formats import badinputs

    ensure_fmus(quiet=True)
    outcomes = badinputs.run()
    if verbose:
        for o in outcomes:
            click.echo(f"{'ok  ' if o.passed else 'FAIL'} {o.case.name}: {' | '.join(o.messages)}")
    click.echo(badinputs.summary(outcomes))
    if not all(o.passed for o in outcomes):
        sys.exit(1)


def _alias(name: str, command: click.Command):
    """``lever NAME``: an older name of ``command``, kept so scripts that use it go on working."""
    alias = copy.copy(command)
    alias.name = name
    alias.help = f"The older name of `lever {command.name}`.\n\n" + (command.help or "")
    alias.short_help = f"older name of `lever {command.name}`"
    main.add_command(alias, name)


_alias("check", compliance_command)


def entry():
    """Console entry point."""
    main.main(standalone_mode=True)


if __name__ == "__main__":
    entry()
