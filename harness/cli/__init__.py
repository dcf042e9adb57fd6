"""The ``lever`` command line: the group ``main`` and the console entry.  Each command
group lives in its own module (``running``, ``studies``, ``exports``, ``fmus``); a command
parses its options, calls ``harness.api`` and prints what it returns."""
from __future__ import annotations

import click

from harness.cli import exports, fmus, running, studies
from harness.cli.common import INTERRUPTED_EXIT, UserError, ensure_fmus

__all__ = ["main", "entry", "ensure_fmus", "UserError", "INTERRUPTED_EXIT", "DEVELOPER_COMMANDS"]


#: the commands for the project's own developers (checks of the FMUs and references, the
#: numbers behind its documents), listed apart from the user's in ``lever --help``
DEVELOPER_COMMANDS = ("badinputs", "compliance", "fingerprint", "reference", "study")


class _Lever(click.Group):
    """The command group: the user's commands listed apart from the developers'; Ctrl-C
    anywhere a command does not take it itself ends with "interrupted" (or what the
    interrupted study kept) and exit status 130, not click's "Aborted!" and 1."""

    def format_commands(self, ctx, formatter):
        listed = [(name, self.get_command(ctx, name)) for name in self.list_commands(ctx)]
        listed = [(name, command) for name, command in listed if command is not None and not command.hidden]
        if not listed:
            return
        limit = formatter.width - 6 - max(len(name) for name, _ in listed)
        for title, developers in (("Commands", False), ("Developer commands (checks of the project itself)", True)):
            rows = [(name, command.get_short_help_str(limit)) for name, command in listed
                    if (name in DEVELOPER_COMMANDS) == developers]
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)

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
