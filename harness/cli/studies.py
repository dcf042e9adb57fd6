"""``lever bench``, ``stability``, ``sweep``, ``study``, ``measured``, ``engines``, ``hosts``,
``fingerprint``: the studies, each a call of ``harness.api`` and its results printed."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from harness import api
from harness.cli.common import TIME, UserError, user_errors
from harness.paths import RESULTS


@click.command("bench", short_help="Error against run time of every master and peer.")
@click.argument("scene", default="kavz685")
@click.option("--repeats", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per case; the median run time is quoted.")
@click.option("--only", "only", multiple=True, type=click.Choice(list(api.masters())),
              help="Bench only these masters (repeatable).")
@click.option("--no-peers", is_flag=True, help="Leave out fmpy and libcosim.")
@click.option("--no-monolithic", is_flag=True, help="Leave out the monolithic scipy solutions.")
@click.option("--no-fmi-editions", is_flag=True, help="Leave out the FMUs' FMI 2.0 and FMI 3.0 editions side by "
              "side (FMU-call floor, each call's price, the baseline master's run).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/bench/<scene>).")
@click.option("--fresh", is_flag=True, help="Start afresh instead of resuming from the cases already in "
              "OUT/cases.jsonl (the earlier log is kept, renamed).")
def bench(scene, repeats, only, no_peers, no_monolithic, no_fmi_editions, out, fresh):
    """Error against run time for every master (and peers) on SCENE, and the FMUs' FMI 3.0
    editions against their FMI 2.0 ones: writes bench.csv, bench.md, bench.json and
    work_precision.png."""
    with user_errors():
        result = api.bench(scene, repeats=repeats, only=list(only), peers=not no_peers, monolithic=not no_monolithic,
                           progress=click.echo, out=out, resume=not fresh, fmi_editions=not no_fmi_editions)
    click.echo("")
    for line in result["summary"]:
        click.echo(line)
    click.echo("written: " + ", ".join(str(p) for p in result["written"]))


@click.command("stability", short_help="The stability map: which master at which step is stable.")
@click.argument("scene", default="kavz685")
@click.option("--stiffness", "stiffnesses", type=float, multiple=True, metavar="C",
              help="Coupling stiffness [N*m/rad] to sweep (repeatable; default: the scene's, 1e4, 1e5, 1e6).")
@click.option("--damping", "dampings", type=float, multiple=True, metavar="B",
              help="Coupling damping [N*m*s/rad] to sweep (repeatable; default: the scene's, a tenth, 0).")
@click.option("--h-omega", "h_omegas", type=float, multiple=True, metavar="X",
              help="Communication step as h*omega_n (repeatable; default 0.05 ... 5, 7 values).")
@click.option("--master", "masters", multiple=True, type=click.Choice(list(api.masters(fixed_step=True))),
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
    stability.csv, stability_map.png and the resumable case log cases.jsonl.  Before the
    cases run it says how long they will take, about (each master timed on the scene).
    SCENE may be any scene with our LeverCoupling between two shafts: a shaft FMU of one's
    own is measured first (its Model Exchange derivatives, or short probe runs); where it
    refuses the probe runs, the map says so and shows the observed runs only, at the
    scene's step times 0.1 ... 100."""
    with user_errors():
        done = api.stability_map(scene, stiffnesses=stiffnesses, dampings=dampings, h_omegas=h_omegas,
                                 masters=masters, dense=dense, min_steps=min_steps, refine=not no_refine, jobs=jobs,
                                 resume=not fresh, out=out, progress=click.echo if progress else None)
    agreed = done["agreement"]
    if agreed.get("no_prediction"):
        if not progress:        # with progress lines it was said first, before the cases ran
            click.echo(agreed["no_prediction"])
        click.echo("From the observed runs only:")
        for line in agreed["advice"]:
            click.echo(f"  {line}")
    if agreed["explicit_rows"]:
        click.echo(f"explicit masters: predicted edge inside the observed bracket in {agreed['explicit_bracketed']} "
                   f"of {agreed['explicit_rows']} rows; observed/predicted median {agreed['explicit_ratio_median']:.3g}")
    for m, s in agreed["by_master"].items():
        click.echo(f"  {m:24s} prediction agrees in {s['agree']}/{s['cases']} cases")
    click.echo("written: " + ", ".join(str(p) for p in done["written"]))


@click.command("study", short_help="The numbers behind a documented decision or statement.")
@click.argument("name", type=click.Choice(["transfer-modes", "runup", "reference-agreement"]))
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "studies", show_default=True)
@click.option("--scan", "lags", multiple=True, type=float,
              help="runup: settling times of kavz685_runup_rest at this engine torque lag [s] (repeatable)")
def study(name, out, lags):
    """Recompute the numbers behind a documented decision (docs/record/decisions.md) or statement
    (runup: the no-load run-up beside the monograph's 0.42 s, docs/models-and-fmus.md;
    reference-agreement: errors against the references made from the FMUs beside those against
    the monolithic one, docs/how-to/measure-your-own-error.md)."""
    with user_errors():
        text, path = api.study(name, out, lags)
    click.echo(text)
    click.echo(f"written to {path}")


def print_measured(files, out: Path, stiffness: float | None = None, cycles: bool = True):
    """Model against measurement for ``files`` (default: the monograph's data): print a
    line per grade and the findings; exit 1 when there are findings."""
    with user_errors():
        done = api.measured(files, out, stiffness=stiffness, cycles=cycles)
    for g in done["grades"]:
        click.echo(f"  {g['grade']:12s} c {g['conditions']['stiffness']:6g} N*m/rad: RMS error model "
                   f"{100 * g['rms_model']:5.1f} %, naive {100 * g['rms_naive']:5.1f} %, scatter "
                   f"{100 * g['scatter']:4.1f} %; A measured {g['amplitude_measured']:5.1f}, predicted "
                   f"{g['amplitude_predicted']:5.1f} N*m  {'ok' if g['within_target'] else 'ABOVE TARGET'}")
    for finding in done["findings"]:
        click.echo(f"finding: {finding}", err=True)
    click.echo(f"written: {done['report']}")
    if done["findings"]:
        sys.exit(1)


@click.command("measured", short_help="The model against measured torque tables.")
@click.argument("files", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option("--stiffness", type=float, default=None,
              help="Torsional stiffness of the grade [N*m/rad], when the files do not state it (overrides them).")
@click.option("--no-cycles", is_flag=True, help="Compare the mean curves only (one run a grade).")
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "measured", show_default=True)
def measured(files, stiffness, no_cycles, out):
    """Model against measurement: predict the drive-shaft torque from the measured
    driven-shaft torque for every grade in FILES (tables or folders; default: the
    monograph's data) and report the errors (measured.md, measured.json, plots).  Exit
    code 1 when a grade misses the monograph's stated model-experiment difference."""
    print_measured(files, out, stiffness, not no_cycles)


@click.command("sweep", short_help="The monograph's parameter studies against its points.")
@click.argument("scene", required=False, default=None)
@click.option("--axis", "axes", multiple=True, metavar="NAME",
              help="Sweep only these axes (repeatable): load, inertia, stiffness, damping, misalignment, "
                   "stiffness_measured, load_alpha0, load_alpha5 (default: all).")
@click.option("--scene", "scene_option", default=None, hidden=True, help="Deprecated: the base scene is SCENE.")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override the base scene.")
@click.option("--stop", type=TIME, default=None,
              help="Simulated time per case [s], or with a time unit, e.g. 500ms (default: the scene's).")
@click.option("--thin", type=click.IntRange(1, 100), default=1, help="Every n-th value of each axis (ends kept).")
@click.option("--workers", type=click.IntRange(1, 256), default=None, help="Local processes (default: CPU count).")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS",
              help="Run the cases on the Dask cluster at ADDRESS (e.g. tcp://scheduler:8786) instead.")
@click.option("--no-resume", is_flag=True, help="Start afresh instead of reusing finished cases.")
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "sweep", show_default=True)
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
def sweep(scene, axes, scene_option, assignments, stop, thin, workers, dask_address, no_resume, out, progress):
    """The monograph's parameter studies (Figs. 3.15-3.18, 4.8, 4.12) on SCENE (default
    kavz685): amplitude and mean curves with its reported points overlaid, and a trend
    report (sweep.md, sweep.json, sweep_<axis>.png).  Finished and failed cases are kept in
    OUT/cases.jsonl; a re-run resumes."""
    if scene_option is not None:
        if scene is not None and scene != scene_option:
            raise UserError(f"SCENE {scene} and --scene {scene_option}: name the scene once, as SCENE")
        click.echo("note: --scene is deprecated; name the scene as SCENE (lever sweep SCENE)", err=True)
    scene = scene or scene_option or "kavz685"
    show_progress = sys.stderr.isatty() if progress is None else progress
    try:
        with user_errors():
            report = api.sweep(axes, scene=scene, overrides=list(assignments), stop=stop, thin=thin, workers=workers,
                               dask=dask_address, resume=not no_resume, out=out, progress=show_progress)
    except OSError as error:       # e.g. no Dask scheduler at the address
        raise click.ClickException(f"the sweep could not run: {error}") from None
    failed = [c for c in report["cases"] if c["result"].get("status") != "ok"]
    for t in report["trends"]:
        verdict = api.sweep_verdict(t)
        click.echo(f"  {verdict:14s}  {t['trend']}" + (f" (holds for {', '.join(t['holds_for'])})"
                                                       if t["reproduced"] == "partly" else "")
                   + (f" ({t['numbers']})" if t["reproduced"] not in ("yes", "partly", "no") else ""))
    click.echo(f"{len(report['cases']) - len(failed)} cases ok, {len(failed)} failed; written: {out / 'sweep.md'}")
    for c in failed:
        click.echo(f"  failed: {c['axis']} = {c['x']:g}: {c['result'].get('error')}", err=True)
    if failed:
        sys.exit(1)


@click.command("engines", short_help="A scene in every engine that runs our FMUs.")
@click.argument("scene", default="kavz685")
@click.option("--engine", "engine_names", multiple=True, metavar="ENGINE",
              help="Only these engines (repeatable; default all: lever, lever-jacobi, container, fmpy-ssp, "
                   "libcosim-ssp, libcosim-ecco).")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override (as for `lever run`).")
@click.option("--step", type=TIME, default=None,
              help="Communication step [s], or with a time unit, e.g. '1 ms' (default: the scene's).")
@click.option("--repeats", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per engine; the median run time is quoted.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (default results/engines/<scene>).")
def engines(scene, engine_names, assignments, step, repeats, out):
    """SCENE in every engine that runs our FMUs (ours, fmpy.ssp, libcosim, the container
    FMU): error against the monolithic reference and run time; writes engines.md and
    engines.json."""
    with user_errors():
        paths = api.engines(scene, list(assignments), engines=engine_names, step=step, repeats=repeats, out=out,
                            progress=click.echo)
    click.echo("written: " + ", ".join(str(p) for p in paths))


@click.command("hosts", short_help="A scene in hosts we did not write, timed against ours.")
@click.argument("scene", default="kavz685")
@click.option("--host", "host_names", multiple=True, metavar="HOST",
              help="Only these hosts (repeatable; default all: harness-jacobi, libcosim-fixed, ecos, ecos-serial, "
                   "ecos-log-all, c-importer).")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Override (as for `lever run`).")
@click.option("--step", type=TIME, default=1e-3, show_default=True,
              help="Communication step [s], or with a time unit, e.g. '1 ms'.")
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
    with user_errors():
        done = api.hosts(scene, list(assignments), hosts=host_names, step=step, repeats=repeats, fmu_dir=fmu_dir,
                         native_env=native_env, out=out, log=click.echo)
    click.echo(done["table"])
    click.echo("written: " + ", ".join(str(p) for p in done["written"]))


@click.command("fingerprint", short_help="SHA-256 of every scene's traces with every master.")
@click.argument("names", nargs=-1, metavar="[SCENES]...")
@click.option("--master", "masters", multiple=True, type=click.Choice(list(api.masters())),
              help="Only this master (repeatable; default: every master).")
@click.option("--stop", type=TIME, default=0.2, show_default=True,
              help="Run each scene for at most this many seconds (0: each scene's own length).")
def fingerprint(names, masters, stop):
    """Print a SHA-256 of the traces of every committed scene (or SCENES) run with every
    master: `lever fingerprint > before.txt`, change the code, run it again and `diff`
    - a refactor that keeps behaviour leaves every line the same, bit for bit."""
    with user_errors():
        for name, master, rows, digest in api.fingerprints(names, masters, stop):
            click.echo(f"{name:28s} {master:24s} {rows:7d} {digest}")


COMMANDS = (bench, stability, study, measured, sweep, engines, hosts, fingerprint)
