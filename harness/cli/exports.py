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
        path, how_to_run = api.export(scene, to, list(assignments), out=out)
    click.echo(f"written: {path}")
    if how_to_run:
        click.echo("runs with its parameter values in:")
        for engine, how in how_to_run.items():
            click.echo(f"  {engine + ':':10s} {how}")


@_export_command("export-ssp", "archive", "results/ssp/<scene>.ssp", "Write a scene as an SSP archive.")
def export_ssp(scene, assignments, out):
    """Write SCENE as an SSP archive: SystemStructure.ssd, the FMUs (with their OSP model
    descriptions), each component's parameter set (.ssv, bound to it) and all of them in
    one set with qualified names (resources/qualified/parameters.ssv).  With its values it
    runs in `lever run ARCHIVE` and libcosim (they read the bindings), in ecos with
    `--parameterSet scene` (ecos applies only the set it is told to), and in fmpy.ssp
    only with `parameter_set=read_ssv(ARCHIVE, resource='resources/qualified/parameters.ssv')`:
    fmpy 0.3's simulate_ssp applies no binding of the SSD and, without that argument, runs
    every FMU on its defaults without a word."""
    _export(scene, assignments, out, "ssp")


@_export_command("export-container", "FMU", "results/container/<scene>.fmu",
                 "Write a scene as one container FMU.")
def export_container(scene, assignments, out):
    """Write SCENE as one FMU (fmpy's container FMU holding the scene's FMUs): its
    parameters are the scene's values, its outputs the scene's recorded variables, its
    internal step the scene's step (Jacobi, as the harness's `jacobi` master)."""
    _export(scene, assignments, out, "container")


COMMANDS = (export_ssp, export_container)
