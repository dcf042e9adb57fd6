"""``lever build``, ``lever compliance``, ``lever badinputs``: the FMUs built and checked;
``lever cache``: what the harness keeps of its computations."""
from __future__ import annotations

import sys
from pathlib import Path

import click

from harness import api
from harness.paths import FMUS, fmi3_dir


@click.command("build", short_help="Build the FMUs and say where they are.")
@click.option("--force", is_flag=True, help="Rebuild even when the sources did not change.")
@click.option("--out", type=click.Path(path_type=Path), default=FMUS, show_default=True,
              help="Where the FMUs go: build/fmus in a checkout; for a package installed with pip, the user's "
                   "cache folder; LEVER_FMU_DIR chooses another.")
def build(force, out):
    """Build the FMUs (LeverCoupling, EngineShaft, LoadShaft, FreewheelRectifier,
    MisalignmentSource) when they are missing or older than their sources, and say where
    they are (FMI 2.0 and FMI 3.0 editions), built now or not."""
    said = []

    def log(line):
        said.append(line)
        click.echo(line)
    try:
        folder = api.build(force, out, log=log)
    except RuntimeError as error:
        raise click.ClickException(str(error)) from None
    state = "built now" if said else "up to date, nothing to build"
    click.echo(f"FMUs ({state}): {folder} (FMI 2.0), {fmi3_dir(folder)} (FMI 3.0)")


@click.command("compliance", short_help="Compliance checks on FMU files (fmpy's and ours).")
@click.argument("fmus", nargs=-1, type=click.Path(path_type=Path))
def compliance(fmus):
    """Compliance checks on FMU files, or the FMU files in a folder (default: the built ones,
    FMI 2.0 and 3.0 editions): fmpy's validation plus ours (types, units, ranges,
    documentation, requirements, OSP ports).  Exit code 1 when there are findings."""
    total = 0
    for path, findings in api.compliance(fmus):
        total += len(findings)
        click.echo(f"{path}: {len(findings)} finding{'' if len(findings) == 1 else 's'}")
        for finding in findings:
            click.echo(f"  - {finding}")
    if total:
        sys.exit(1)


@click.command("badinputs", short_help="The bad-input corpus through fmpy on the built FMUs.")
@click.option("--verbose", is_flag=True, help="Also print every case with the message the FMU logged.")
def bad_inputs(verbose):
    """Run the bad-input corpus (harness/formats/badinputs/) through fmpy's FMU2Slave and FMU2Model on
    the built FMUs, and FMU3Slave and FMU3Model on their FMI 3.0 editions: every case must be refused
    with an FMI error naming the variable and its range."""
    outcomes, summary = api.bad_inputs()
    if verbose:
        for o in outcomes:
            click.echo(f"{'ok  ' if o.passed else 'FAIL'} {o.case.name}: {' | '.join(o.messages)}")
    click.echo(summary)
    if not all(o.passed for o in outcomes):
        sys.exit(1)


def _files(count: int) -> str:
    return f"{count} file{'' if count == 1 else 's'}"


def _size(count: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if count < 1000 or unit == "GB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000


@click.command("cache", short_help="Where the cache is, its size; --clear empties it.")
@click.option("--clear", is_flag=True, help="Remove what the cache holds (made again when needed).")
@click.option("--clear-stale", is_flag=True, help="Remove only what other code or versions left (never read again).")
def cache(clear, clear_stale):
    """Where the harness keeps what it computes once - the references runs are measured
    against, the benchmark's do-nothing twins, the factors of the units values are given
    in - and how much it holds: LEVER_CACHE_DIR, else
    the user's cache folder of this version (~/.cache/lever-cosim/<version> on Linux).  An
    entry is kept for the code and versions that made it: after an upgrade or a change to
    the code the old entries are stale, never read again, and --clear-stale frees their space."""
    held = api.cache(clear or clear_stale, stale=clear_stale and not clear)
    click.echo(f"cache: {held['folder']}")
    for name, part in held["parts"].items():
        click.echo(f"  {name}: {_files(part['files'])}, {_size(part['bytes'])} ({part['holds']})")
    total = held["total"]
    stale = f" ({_files(total['stale_files'])}, {_size(total['stale_bytes'])} of them stale)" if total["stale_files"] else ""
    if held["cleared"] == "stale":
        click.echo(f"removed: {_files(total['stale_files'])}, {_size(total['stale_bytes'])} (stale)")
    else:
        click.echo(f"{'removed' if held['cleared'] else 'in all'}: {_files(total['files'])}, {_size(total['bytes'])}"
                   f"{stale}")


COMMANDS = (build, compliance, bad_inputs, cache)
