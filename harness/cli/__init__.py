"""The ``lever`` command line: the group ``main`` and the console entry.  Each command
group lives in its own module (``running``, ``studies``, ``exports``, ``fmus``); a command
parses its options, calls ``harness.api`` and prints what it returns."""
from __future__ import annotations

import click

from harness.cli import exports, fmus, running, studies
from harness.cli.common import INTERRUPTED_EXIT, UserError, ensure_fmus

__all__ = ["main", "entry", "ensure_fmus", "UserError", "INTERRUPTED_EXIT"]


class _Lever(click.Group):
    """The command group: Ctrl-C anywhere a command does not take it itself ends with
    "interrupted" (or what the interrupted study kept) and exit status 130, not click's
    "Aborted!" and 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as error:
            click.echo(f"\n{error or 'interrupted'}", err=True)
            raise click.exceptions.Exit(INTERRUPTED_EXIT) from None


@click.group(cls=_Lever, context_settings={"help_option_names": ["-h", "--help"]})
def main():
    """Co-simulation of lever-articulated drive-shaft couplings (FMI 2.0, fmpy)."""


for _command in (*fmus.COMMANDS, *running.COMMANDS, *studies.COMMANDS, *exports.COMMANDS):
    main.add_command(_command)


def entry():
    """Console entry point."""
    main.main(standalone_mode=True)
