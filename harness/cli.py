"""The ``lever`` command line."""
from __future__ import annotations

import importlib.util
import math
import os
import sys
from pathlib import Path

import click

from . import scene as scenes
from .paths import BUILD, FMUS, RESULTS, SCENES


class UserError(click.ClickException):
    """A problem with the user's input: shown as a message, exit code 2, no traceback."""

    exit_code = 2


def _build_module():
    spec = importlib.util.spec_from_file_location("_lever_build_fmus", BUILD / "fmus.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def ensure_fmus(fmu_dir: Path = FMUS, force: bool = False, quiet: bool = False):
    """Build the FMUs when they are missing or older than their sources."""
    build = _build_module()
    if force or not build.is_current(fmu_dir):
        build.build(fmu_dir, force=force, log=(lambda *_: None) if quiet else click.echo)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main():
    """Co-simulation of lever-articulated drive-shaft couplings (FMI 2.0, fmpy)."""


@main.command()
@click.option("--force", is_flag=True, help="Rebuild even when the sources did not change.")
@click.option("--out", type=click.Path(path_type=Path), default=FMUS, show_default=True)
def build(force, out):
    """Build the FMUs (LeverCoupling, EngineShaft, LoadShaft) into build/fmus."""
    try:
        ensure_fmus(out, force)
    except RuntimeError as error:
        raise click.ClickException(str(error)) from None


@main.command("scenes")
def list_scenes():
    """List the scenes in resources/scenes."""
    for path in sorted(SCENES.glob("*.toml")):
        try:
            click.echo(f"{path.stem:24s} {scenes.load(path).description}")
        except scenes.SceneError as error:
            click.echo(f"{path.stem:24s} (invalid: {error})")


@main.command()
@click.argument("scene", default="kavz685")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
              help="Override a parameter: component.parameter=value (e.g. coupling.stiffness=900, "
                   "coupling.misalignment='20 deg') or experiment.stop=5.")
@click.option("--master", type=str, default=None, help="Co-simulation master (default: the scene's).")
@click.option("--step", type=float, default=None, help="Communication step [s] (default: the scene's).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/<scene>).")
@click.option("--tolerance", type=float, default=None,
              help="Tolerance of an adaptive master (relative torque error per step) or of an iterative "
                   "master's coupling iteration.")
@click.option("--no-reference", is_flag=True, help="Skip the monolithic reference solution.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
@click.option("--stream", is_flag=True, help="For long runs: write traces.csv while running (synced chunks: a "
              "run killed part-way leaves valid traces), keep every k-th row in memory for the report, skip "
              "the reference (the energy balance, integrated over every row, judges the run).")
def run(scene, assignments, master, step, tolerance, out, no_reference, progress, stream):
    """Run SCENE (a name in resources/scenes or a .toml path) and write traces, plots,
    summary.json and report.md."""
    from . import masters as family
    from . import reference as references
    from . import report
    from .run import simulate
    from .system import SceneInvalid

    try:
        spec = scenes.load(scene).with_overrides(list(assignments))
    except scenes.SceneError as error:
        raise UserError(str(error)) from None
    chosen = master or spec.experiment.master
    if chosen not in family.MASTERS:
        raise UserError(f"master '{chosen}' is unknown (known: {', '.join(family.MASTERS)})")
    if step is not None and not (math.isfinite(step) and step > 0):
        raise UserError(f"--step {step}: the communication step must be > 0 s")
    options = {}
    if tolerance is not None:
        if "tolerance" not in family.MASTERS[chosen].options:
            raise UserError(f"--tolerance: master '{chosen}' takes no tolerance (masters that do: "
                            + ", ".join(n for n, m in family.MASTERS.items() if "tolerance" in m.options) + ")")
        if not (math.isfinite(tolerance) and 0 < tolerance < 1):
            raise UserError(f"--tolerance {tolerance}: must lie in (0, 1)")
        options["tolerance"] = tolerance
    try:
        ensure_fmus(quiet=True)
    except RuntimeError as error:
        raise click.ClickException(f"building the FMUs failed: {error}") from None
    show_progress = sys.stderr.isatty() if progress is None else progress
    out = out or RESULTS / spec.name
    try:
        result = simulate(spec, master, step, progress=show_progress, options=options,
                          stream=out / "traces.csv" if stream else None)
    except SceneInvalid as error:
        raise UserError(str(error)) from None
    reference = None
    if "reference" in spec.features and not no_reference and not stream and result.ok:
        try:
            reference = references.solve(spec, result.times)
        except references.ReferenceUnavailable as error:
            click.echo(f"note: no reference for this scene: {error}", err=True)
    summary = report.write(out, result, reference)
    _print_summary(summary, out)
    if not result.ok:
        click.echo(f"error: {result.failure}", err=True)
        if result.failure_stage == "initialisation":
            # Refused before the first step: the scene's values are at fault, not the run.
            sys.exit(UserError.exit_code)
        click.echo(f"the traces computed before the failure are in {out / 'traces.csv'}", err=True)
        sys.exit(1)


def _print_summary(summary: dict, out: Path):
    click.echo(f"{summary['scene']}: master {summary['master']}, step {summary['step_s']:g} s, "
               f"wall time {summary['wall_time_s']:.2f} s")
    stats = summary.get("statistics") or {}
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
    from . import bench as benchmark

    try:
        spec = scenes.load(scene)
        benchmark.plan(spec, list(only))      # refuses unknown masters before anything runs
    except (scenes.SceneError, ValueError) as error:
        raise UserError(str(error)) from None
    ensure_fmus(quiet=True)
    out = out or benchmark.default_out(spec)
    result = benchmark.bench(spec, repeats, only=list(only), peers=not no_peers, monolithic=not no_monolithic,
                             progress=click.echo, out=out, resume=not fresh)
    paths = benchmark.write(out, result)
    click.echo("")
    claims = result["claims"]
    target = claims["target_error"]
    for name, t in claims["time_at_target_s"].items():
        click.echo(f"  at {100 * target:g} % RMS torque error: {name:26s} "
                   + ("not reached" if t is None else f"{t:.3f} s"))
    if claims.get("best_master"):
        speedup = claims.get("speedup_over_baseline")
        click.echo(f"  best master: {claims['best_master']}"
                   + (f", {speedup:.1f}x faster than {claims['baseline']}" if speedup else ""))
    if claims.get("overhead_above_floor"):
        click.echo("  above the FMU-call floor: " + ", ".join(
            f"{n} {100 * v:.0f} %" for n, v in claims["overhead_above_floor"].items()))
    click.echo("written: " + ", ".join(str(p) for p in paths))


@main.command()
@click.argument("name", type=click.Choice(["transfer-modes"]))
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "studies", show_default=True)
def study(name, out):
    """Recompute the numbers behind a documented decision (docs/decisions.md)."""
    from . import studies

    ensure_fmus(quiet=True)
    click.echo(studies.transfer_modes(out))
    click.echo(f"written to {out / 'transfer_modes.md'}")


@main.command("badinputs")
@click.option("--verbose", is_flag=True, help="Also print every case with the message the FMU logged.")
def bad_inputs(verbose):
    """Run the bad-input corpus (harness/badinputs.py) through fmpy's FMU2Slave on the built
    FMUs: every case must be refused with an FMI error naming the variable and its range."""
    from . import badinputs

    ensure_fmus(quiet=True)
    outcomes = badinputs.run()
    if verbose:
        for o in outcomes:
            click.echo(f"{'ok  ' if o.passed else 'FAIL'} {o.case.name}: {' | '.join(o.messages)}")
    click.echo(badinputs.summary(outcomes))
    if not all(o.passed for o in outcomes):
        sys.exit(1)


def entry():
    """Console entry point.  pythonfmu 0.7's native library can corrupt the heap while
    the process tears down, after all results are written; so flush and leave without
    interpreter and library teardown, keeping the command's exit status."""
    try:
        main.main(standalone_mode=True)
        status = 0
    except SystemExit as done:
        status = done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    from .component import remove_extractions
    remove_extractions()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == "__main__":
    entry()
