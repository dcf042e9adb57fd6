"""``lever export-ssp``, ``lever export-container``: a scene written for other tools."""
from __future__ import annotations

from pathlib import Path

import click

from harness import api
from harness.cli.common import user_errors


def _export_command(name: str, written: str, default: str, short_help: str):
    """A ``lever export-*`` command: SCENE, ``--set`` overrides and ``--out`` (the
    ``written`` file; ``default``: where it goes without one)."""
    def wrap(function):
        function = click.option("--out", type=click.Path(path_type=Path), default=None,
                                help=f"The {written} to write (default {default}).")(function)
        function = click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE",
                                help="Override a parameter before exporting (as for `lever run`).")(function)
        function = click.argument("scene", default="kavz685")(function)
        return click.command(name, short_help=short_help)(function)
    return wrap


def _export(scene, assignments, out, to: str):
    """Write SCENE (with the --set overrides) as ``to`` to OUT; then say what each engine
    needs to run it."""
    with user_errors():
        path, how_to_run, notes = api.export(scene, to, list(assignments), out=out)
    click.echo(f"written: {path}")
    if how_to_run:
        click.echo("runs with its parameter values in:")
        for engine, how in how_to_run.items():
            click.echo(f"  {engine + ':':10s} {how}")
    for note in notes:
        click.echo(f"warning: {note}", err=True)


@_export_command("export-ssp", "archive", "results/ssp/<scene>.ssp", "Write a scene as an SSP archive.")
def export_ssp(scene, assignments, out):
    """Write SCENE as an SSP archive: SystemStructure.ssd, the FMUs (with their OSP model
    descriptions), each component's parameter set (.ssv, bound to it) and all of them in
    one set with qualified names (resources/qualified/parameters.ssv).  The FMUs in it are
    configured to start at the scene's values (their model descriptions' start values, and
    a GUID of their own), so it runs the scene also in an engine that applies no binding
    (fmpy.ssp's simulate_ssp without parameter_set) or drops some (OMSimulator: Strings);
    where an FMU cannot carry its values (a foreign one, or one used by two components with
    different values) the command says so.  Prints the command line that runs it in each
    engine we name."""
    _export(scene, assignments, out, "ssp")


@_export_command("export-container", "FMU", "results/container/<scene>.fmu",
                 "Write a scene as one container FMU.")
def export_container(scene, assignments, out):
    """Write SCENE as one FMU (fmpy's container FMU holding the scene's FMUs): its
    parameters are the scene's values, its outputs the scene's recorded variables, its
    internal step the scene's step (Jacobi, as the harness's `jacobi` master)."""
    _export(scene, assignments, out, "container")


COMMANDS = (export_ssp, export_container)
