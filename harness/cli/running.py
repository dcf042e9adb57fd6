"""``lever scenes``, ``lever run``, ``lever validate``, ``lever reference``: a scene run and
judged against its reference."""
from __future__ import annotations

import sys
from pathlib import Path

import click

from harness import api
from harness.cli.common import INTERRUPTED_EXIT, TIME, UNTRUSTED_EXIT, UserError, user_errors
from harness.cli.studies import print_measured
from harness.paths import RESULTS


@click.command("scenes", short_help="List the committed scenes.")
def list_scenes():
    """List the committed scenes (resources/scenes): each name, then its description."""
    listed = api.scenes()
    width = max(map(len, listed), default=0)
    for name, description in listed.items():
        click.echo(f"{name:{width}s}  {description}")


#: the masters, listed in --help and checked by click
MASTER_CHOICE = click.Choice(list(api.masters()))


@click.command("run", short_help="Run a scene and write its traces, plots and report.")
@click.argument("scene", default="kavz685")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
              help="Override a parameter: component.parameter=value (e.g. coupling.stiffness=900, "
                   "coupling.misalignment='20 deg') or experiment.stop=5.")
@click.option("--master", type=MASTER_CHOICE, default=None,
              help="Co-simulation master (default: the scene's; what each does: docs/reference/masters.md).")
@click.option("--step", type=TIME, default=None,
              help="Communication step [s], or with a time unit, e.g. '1 ms' (default: the scene's).")
@click.option("--stop", type=TIME, default=None,
              help="Stop time [s], or with a time unit, e.g. 500ms (as --set experiment.stop=S); a scene's start-up "
                   "transient that does not fit the "
                   "shorter run takes the same share of it (said before the run).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/<scene>).")
@click.option("--tolerance", type=float, default=None,
              help="Tolerance of an adaptive master (relative torque error per step), of an iterative "
                   "master's coupling iteration, or me-cvode's CVODE relative tolerance (default 1e-6).")
@click.option("--no-reference", is_flag=True, help="Skip the monolithic reference solution.")
@click.option("--strict", is_flag=True, help="Refuse the scene when an input is connected to nothing and not set "
              "(as experiment.strict = true); without it such an input is named and held at its start value.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
@click.option("--stream", is_flag=True, help="For long runs: write traces.csv while running (synced chunks: a "
              "run killed part-way leaves valid traces), keep every k-th row in memory for the report, skip "
              "the reference (the energy balance, integrated over every row, judges the run).")
@click.option("--latency", is_flag=True, help="Time every step for real-time use: median, p99, p99.9 and maximum "
              "step time, the start-up steps and why the slowest were slow (latency.md, latency.json).")
@click.option("--no-plots", is_flag=True, help="Write the traces, summary.json and report.md without drawing the "
              "plots (most of a short run's time: for scripts and batches).")
def run(scene, assignments, master, step, stop, tolerance, out, no_reference, strict, progress, stream, latency,
        no_plots):
    """Run SCENE (a name in resources/scenes, a .toml path or an SSP archive .ssp) and
    write traces, plots, summary.json and report.md.

    Exit code: 0 for a run to be trusted; 3 for a run that completed but whose energy
    residual exceeds 5 % of the work in (summary.json's "untrusted" and the report say so:
    the traces are not the system's motion); 1 when the run failed part-way; 2 on bad
    input (or values the FMUs refused at initialisation); 130 on Ctrl-C."""
    with user_errors():
        spec = api.load(scene, list(assignments), stop=stop, strict=strict)
    show_progress = sys.stderr.isatty() if progress is None else progress
    try:
        with user_errors():
            done = api.run(spec, master=master, step=step, tolerance=tolerance, reference=not no_reference,
                           out=out or RESULTS / spec.name, progress=show_progress, stream=stream, latency=latency,
                           plots=not no_plots, notify=_said_before_the_summary)
    except api.BuildError as error:
        raise click.ClickException(f"building the FMUs failed: {error}") from None
    result, out = done.result, done.out
    _print_summary(done.summary, out, list(done.scene.record))
    for line in done.latency or ():
        click.echo(line)
    if done.outcome == "interrupted":
        click.echo(f"{result.failure}; what was computed is in {out}/ (marked interrupted)", err=True)
        sys.exit(INTERRUPTED_EXIT)
    if done.outcome == "untrusted":
        sys.exit(UNTRUSTED_EXIT)
    if done.outcome != "ok":
        click.echo(f"error: {result.failure}", err=True)
        if done.outcome == "refused":
            sys.exit(UserError.exit_code)
        click.echo(f"the traces computed before the failure are in {out / 'traces.csv'}", err=True)
        sys.exit(1)


def _said_before_the_summary(kind: str, message: str):
    """A run's warnings and notes on stderr as they come; the run's verdict NOT TO BE TRUSTED
    is the summary's own line (stdout), not said twice."""
    if not message.startswith(api.UNTRUSTED):
        click.echo(f"{kind}: {message}", err=True)


def _print_summary(summary: dict, out: Path, recorded: list[str] | None = None):
    click.echo(f"{summary['scene']}: master {summary['master']}, step {summary['step_s']:g} s, "
               f"wall time {summary['wall_time_s']:.2f} s")
    stats = summary.get("statistics") or {}
    if stats and not any(stats.values()):
        click.echo(f"  no statistics: the run ended before the start-up transient did (t < {summary['transient_s']:g} s)")
    for name, s in stats.items():
        if s and name.split(".")[-1] in ("w", "tau1", "tau2"):      # the speeds and torques
            extra = f", unevenness {s['unevenness']:.4f}" if "unevenness" in s else ""
            click.echo(f"  {name:14s} mean {s['mean']:10.4f}  amplitude {s['amplitude']:9.4f}{extra}")
    errs = summary.get("error_vs_reference") or {}
    if errs:
        ref = summary.get("reference") or {}
        balance = (ref.get("energy_balance") or {}).get("residual_relative")
        quality = ref.get("quality") or (f"{ref.get('method')}; its own energy residual {balance:.1e}"
                                         if balance is not None else ref.get("method"))
        click.echo(f"  reference: {ref.get('source', 'monolithic')} - {quality}")
        left = [n for n in (recorded if recorded is not None else stats) if n not in errs]
        click.echo("  error vs reference (RMS, relative): " + ", ".join(
            f"{k} {100 * v['rms_relative']:.3g} %" for k, v in errs.items())
            + (f"; not covered: {', '.join(left)} (lever validate --result judges every recorded signal)"
               if left else ""))
    eb = summary.get("energy_balance")
    if eb:
        click.echo(f"  energy residual: {100 * eb['residual_relative']:.2g} % of the work in")
    if summary.get("untrusted"):
        click.echo(f"  NOT TO BE TRUSTED: {summary['untrusted']}")
    if summary.get("energy_balance_unavailable"):
        click.echo(f"  energy balance: not computed: {summary['energy_balance_unavailable']}")
    if summary.get("stream"):
        s = summary["stream"]
        click.echo(f"  streamed {s['rows_written']} rows to {s['trace_file']} (1 in {s['stride']} kept for the "
                   f"report); resident memory {s.get('resident_MB_after_first_chunk', 0):.0f} MB after the first "
                   f"chunk, {s.get('resident_MB_at_end', 0):.0f} MB at the end, peak {s['peak_resident_MB']:.0f} MB")
    click.echo(f"  results: {out}/ ({files_written(summary)})")


def files_written(summary: dict) -> str:
    """The files a run wrote, as summary.json lists them: the plots counted, not named."""
    files = summary.get("files") or ["report.md", "summary.json", "traces.csv"]
    plots = [f for f in files if f.endswith(".png")]
    named = [f for f in files if not f.endswith(".png")]
    return ", ".join(named + ([f"{len(plots)} plots (*.png)"] if plots else []))


@click.command("reference", short_help="Check the committed reference traces are current.")
@click.argument("names", nargs=-1, metavar="[NAMES]...")
@click.option("--update", is_flag=True, help="Regenerate the traces (all, or NAMES) and write them.")
@click.option("--until", type=TIME, default=None, help="Check each trace up to this time only [s], or with a time "
              "unit, e.g. '0.5 s': quicker, and a change that shows only later is not seen (not with --update).")
def reference(names, update, until):
    """Check that the committed reference traces (resources/reference/) are what the project
    computes now; with --update, regenerate them and show what changed (per signal: max change).

    NAMES are FMUs (LeverCoupling, EngineShaft, LoadShaft) or scenes; default: all.
    Exit code without --update: 0 when every trace is current, 1 otherwise."""
    stale = []
    with user_errors():
        for check in api.references(names, update, until):
            if check.status == "unavailable":
                click.echo(f"{check.name}: no reference ({check.reason})")
                continue
            if check.status == "current":
                click.echo(f"{check.name}: current")
                continue
            stale.append(check.name)
            if check.status == "updated":
                click.echo(f"{check.name}: updated ({check.folder})")
            else:
                click.echo(f"{check.name}: NOT current (`lever reference --update {check.name}` regenerates it)")
            for problem in check.problems:
                click.echo(f"  {problem}")
            for change in check.changes:
                click.echo(f"  {change.signal:24s} max change {change.max_change:11.4g} "
                           f"({100 * change.relative:.3g} % of its largest magnitude) at t = {change.at_time:.6g} s")
    if stale and not update:
        sys.exit(1)


@click.command("validate", short_help="Judge a result against its reference traces.")
@click.argument("names", nargs=-1, metavar="[NAMES]...")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
              help="Change a parameter of the run under test, not of the reference: component.parameter=value "
                   "for a scene, parameter=value for an FMU (e.g. --set coupling.stiffness=800).")
@click.option("--master", type=MASTER_CHOICE, default=None, help="Master for a scene (default: the scene's).")
@click.option("--step", type=TIME, default=None, help="Communication step for a scene [s], or with a time unit, e.g. '1 ms' "
                   "(default: the scene's).")
@click.option("--result", "result_csv", type=click.Path(exists=True, path_type=Path), default=None,
              help="Validate this result instead of running NAME: a CSV from another tool's run (a 'time' column "
                   "and columns named like the reference's signals: component.variable for a scene, the FMU's "
                   "variable names for an FMU; 'anything.component.variable' and 'component_variable' match too) "
                   "or a lever results folder (its traces.csv, judged against its reference.csv: the reference "
                   "made for that run's parameters).")
@click.option("--reference", "reference_path", type=click.Path(exists=True, path_type=Path), default=None,
              help="Judge against this reference instead of NAME's committed one: a CSV (a time column and named "
                   "columns) or a lever results folder (its reference.csv).  NAME still says what the signals are.")
@click.option("--verbose", is_flag=True, help="Also print each signal's tolerances and power, and the whole "
              "sentence on what the verdict cannot see (validation.json holds them all).")
@click.option("--tolerance", type=click.Choice(["lever", "cross-check"]), default="lever", show_default=True,
              help="The verdict: 'lever' (per signal over the window after the start-up transient: mean, ripple "
                   "amplitude, leading rotation orders and a tube, each against a tolerance relative to it, with "
                   "the verdict's power; docs/validation.md) or the FMI cross-check's band (fmpy's: 10 % of the "
                   "range, 2 % of the span, at most 10 % outside).")
@click.option("--rtol", multiple=True, metavar="[SIGNAL|KIND:]QUANTITY=VALUE",
              help="A relative tolerance of the 'lever' verdict (repeatable): QUANTITY mean, amplitude, order or "
                   "tube, for every signal, a kind (speed, torque, acceleration, angle, ...) or one signal, e.g. "
                   "amplitude=0.05, torque:mean=0.002, coupling.tau2:order=0.1.  Defaults: mean 0.001, amplitude "
                   "0.02, order 0.05, tube 0.05; a scene's [validation] table sets its own.")
@click.option("--signals", default=None, metavar="NAME,NAME...",
              help="Judge only these of the reference's signals (default: every one the result has; those it "
                   "lacks are listed as not judged).")
@click.option("--measured", is_flag=True,
              help="Model vs measurement instead (lever validate --measured GRADE_FILES...): NAMES are "
                   "measurement files (drive and driven torque tables of a rubber grade), handed with --out to "
                   "the model-vs-measurement check (as lever measured; default: the monograph's grades).")
@click.option("--window", default=None, metavar="START:STOP",
              help="Judge only this span of the reference [s] (e.g. 0:1 or 0:500 ms for a short result, 2:10 for the steady "
                   "part; an empty side is the reference's own start or stop); the verdict says the span judged.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/validate/<NAME>).")
@click.option("--no-plots", is_flag=True, help="Write validation.json and the result without a plot of each failing "
              "signal (for scripts and batches).")
def validate(names, assignments, master, step, result_csv, reference_path, verbose, tolerance, rtol, signals, window,
             measured, out, no_plots):
    """Run each NAME (an FMU stand-alone, driven by its _in.csv under fmpy's simulate_fmu;
    or a scene, with its master), or take --result, and judge each signal the result has
    against its committed reference trace: over the window after the start-up transient,
    its mean, ripple amplitude, leading rotation orders and a tube, each against a relative
    tolerance (--rtol); beside each verdict the smallest change it catches, and one line on
    what it cannot see; a plot per failing signal (--no-plots: none).  NAMES default: every reference.
    A NAME may be an FMU file (FMI 2.0 or 3.0, e.g. build/fmus3/EngineShaft.fmu): run
    stand-alone as its model's name is, judged by that model's reference (results in
    results/validate/<Model>-fmi<version>).

    Exit code: 0 only when every judged signal of every NAME passes; 1 when one fails;
    2 on bad input (a result with none of the reference's signals among it, times not sorted,
    too few samples for the window, a reference without a time column or without any of the
    result's signals)."""
    if measured:
        if no_plots:
            raise click.UsageError("--no-plots: the model-vs-measurement check (--measured) always draws its plots "
                                   "(measured_<grade>.png)")
        print_measured([Path(n) for n in names], out or RESULTS / "validate" / "measured")
        return
    all_passed = True
    try:
        with user_errors():
            for verdict in api.validate_each(names, overrides=list(assignments), master=master, step=step,
                                             result=result_csv, tolerance=tolerance, window=window, out=out,
                                             rtol=list(rtol), reference=reference_path,
                                             signals=[x.strip() for x in signals.split(",") if x.strip()]
                                             if signals else None, notify=_said_before_the_summary,
                                             plots=not no_plots):
                if verdict.findings.KIND == "lever":
                    _print_verdict(verdict.name, verdict.findings, verdict.result, verdict.out, verbose)
                else:
                    _print_validation(verdict.name, verdict.findings, verdict.result, verdict.out)
                all_passed &= verdict.passed
    except api.BuildError as error:
        raise click.ClickException(f"building the FMUs failed: {error}") from None
    sys.exit(0 if all_passed else 1)


def _check_said(check) -> str:
    """One check in a few words: the result's figure, the reference's, the difference, the allowed."""
    if not check.judged:
        return f"{check.quantity} not judged"
    mark = "" if check.passed else "FAIL "
    if check.quantity == "mean" or check.quantity == "amplitude":
        return (f"{mark}{check.quantity} {check.result:.5g} vs {check.reference:.5g} ({check.difference:+.2g}, "
                f"+-{check.allowed:.2g})")
    if check.quantity.startswith("order"):
        return f"{mark}{check.quantity} off by {check.difference:.2g} (+-{check.allowed:.2g})"
    if check.passed:
        return f"{check.quantity} ok"
    return (f"{mark}{check.quantity} {100 * check.result:.2g} % outside (<= {100 * check.allowed:g} %)"
            + (f", {check.also}" if check.also else ""))


def _print_verdict(name, verdict, result, out: Path, verbose: bool = False):
    """The engineer's verdict: a line a signal (each quantity: the result's, the reference's,
    the difference, the allowed), which reference judged, one line on the power and one on what
    cannot be seen; ``verbose``: each signal's tolerances and power, the whole blind-spot sentence."""
    click.echo(f"{name}: {result.how}")
    if verdict.reference:
        click.echo(f"  reference: {verdict.reference}")
    if verdict.window:
        click.echo(f"  judged: t = {verdict.window[0]:g} ... {verdict.window[1]:g} s at the result's own samples "
                   f"({verdict.sampling})" + (f"; the start-up t = {verdict.transient[0]:g} ... "
                                              f"{verdict.transient[1]:g} s by its own tube" if verdict.transient else ""))
    for s in verdict.signals:
        orders = [c for c in s.checks if c.quantity.startswith("order") and c.judged and c.passed]
        shown = [_check_said(c) for c in s.checks if not (c in orders)]
        if orders:
            shown.insert(2, f"orders {','.join(c.quantity.split()[1] for c in orders)} ok")
        click.echo(f"  {s.name:21s} {'pass' if s.passed else 'FAIL'}  " + "; ".join(shown))
        if verbose:
            tolerances = ", ".join(f"{q} {v:g}" + ("" if src == "default" else f" ({src})")
                                   for q, (v, src) in s.rtol.items())
            click.echo(f"      rtol {tolerances}")
            for check in s.checks:
                click.echo(f"      {check.quantity}: {check.detail}")
            if s.power is not None:
                click.echo(f"      power: {s.power.describe()}")
    powers = [s.power for s in verdict.signals if s.power is not None]
    if powers and not verbose:
        amplitude = [p.amplitude for p in powers if p.amplitude is not None]
        shift = [p.shift_s for p in powers if p.shift_s is not None]
        said = []
        if amplitude:
            said.append(f"ripple changes of {100 * min(amplitude):.2g} ... {100 * max(amplitude):.2g} %")
        if shift:
            said.append(f"time shifts of {1e3 * min(shift):.2g} ... {1e3 * max(shift):.2g} ms")
        click.echo(f"  power: a pass rules out {', '.join(said) or 'no change'} and each mean moved by its "
                   "tolerance (per signal: --verbose)")
    if verdict.not_judged:
        click.echo(f"  not judged (not in the result{' or not chosen' if verdict.chosen else ''}): "
                   f"{', '.join(verdict.not_judged)}")
    _print_problems_and_notes(verdict)
    if verdict.blind_spots:
        if verbose:
            click.echo(f"  {verdict.blind_spots}")
        else:
            unjudged = [f"{s.name} {c.quantity}" for s in verdict.signals for c in s.unjudged]
            click.echo(f"  cannot see: {verdict.blind_spots.split('; ')[0].split(': ', 2)[-1]}"
                       + (f"; not shown by its sampling: {', '.join(unjudged)}" if unjudged else ""))
    failed = "; ".join(f"{s.name}: {', '.join(c.quantity for c in s.failed)}" for s in verdict.signals if not s.passed)
    summary = "PASS" if verdict.passed else "FAIL" + (f" ({failed})" if failed else "")
    click.echo(f"  {name}: {summary} over {verdict.describe_span()}; written to {out}/")


def _print_validation(name, findings, result, out: Path):
    click.echo(f"{name}: {result.how}; tolerance {findings.tolerance.describe()}")
    if findings.span:
        click.echo(f"  judged: {findings.describe_span()}")
    click.echo(f"  {'signal':24s} {'RMS error':>11s} {'max error':>11s} {'at t [s]':>9s} {'band +-':>10s} "
               f"{'outside':>8s}  verdict")
    for s in findings.signals:
        click.echo(f"  {s.name:24s} {s.rms_error:11.4g} {s.max_error:11.4g} {s.max_error_time:9.4g} "
                   f"{s.band_width:10.4g} {100 * s.fraction_outside:7.3g}%  {'pass' if s.passed else 'FAIL'}")
    _print_problems_and_notes(findings)
    verdict = "PASS" if findings.passed else "FAIL" + (
        f" ({', '.join(findings.failed_signals)})" if findings.failed_signals else "")
    span = f" over {findings.describe_span()}" if findings.span else ""
    click.echo(f"  {name}: {verdict}{span}; written to {out}/")


def _print_problems_and_notes(findings):
    """What fails the whole result and what the reader should know, as both verdicts list them."""
    for problem in findings.problems:
        click.echo(f"  problem: {problem}")
    for note in findings.notes:
        click.echo(f"  note: {note}")


COMMANDS = (list_scenes, run, reference, validate)
