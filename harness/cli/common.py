"""What the command groups share: bad input as exit status 2 with its sentence, Ctrl-C as
exit status 130, the FMUs built before a command uses them."""
from __future__ import annotations

import contextlib
from pathlib import Path

import click

from harness import api
from harness.api import inputs as api_inputs
from harness.paths import FMUS

#: exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells report it)
INTERRUPTED_EXIT = 130
#: a run that completed but whose energy residual says its traces cannot be trusted
UNTRUSTED_EXIT = 3


class UserError(click.ClickException):
    """A problem with the user's input: shown as a message, exit code 2, no traceback."""

    exit_code = 2


#: the API's keywords the commands take as options: a refusal names the option the user typed
OPTIONS = {"overrides": "--set", "master": "--master", "masters": "--master", "step": "--step", "stop": "--stop",
           "tolerance": "--tolerance", "rtol": "--rtol", "signals": "--signals", "window": "--window",
           "result": "--result", "reference": "--reference", "out": "--out", "stream": "--stream",
           "latency": "--latency", "strict": "--strict", "repeats": "--repeats", "only": "--only",
           "stiffnesses": "--stiffness", "dampings": "--damping", "h_omegas": "--h-omega", "min_steps": "--min-steps",
           "jobs": "--jobs", "axes": "--axis", "thin": "--thin", "workers": "--workers", "lags": "--scan",
           "stiffness": "--stiffness", "engines": "--engine", "hosts": "--host", "native_env": "--native-env"}


@contextlib.contextmanager
def user_errors():
    """``api.InputError`` ends the command with exit code 2 and its message, which names
    the options the user typed (``OPTIONS``), not the API's keywords."""
    try:
        with api_inputs.named_as_options(OPTIONS):
            yield
    except api.InputError as error:
        raise UserError(str(error)) from None


class TimeType(click.ParamType):
    """A time option (``--step``, ``--stop``): seconds, or a value with a time unit as the
    API takes it (``"1 ms"``, ``500ms``); a wrong unit is refused naming the option."""

    name = "time"

    def convert(self, value, param, ctx):
        if value is None or isinstance(value, float):
            return value
        option = param.opts[0] if param is not None and param.opts else "time"
        try:
            with api_inputs.named_as_options({option: api_inputs.Argument(option, "=")}):      # --step='2 kg': ...
                return api_inputs.seconds(value, option)
        except api.InputError as error:
            self.fail(str(error), param, ctx)


#: a time option's type: "--step 0.001", "--step '1 ms'", "--stop 500ms"
TIME = TimeType()


def ensure_fmus(fmu_dir: Path = FMUS, force: bool = False, quiet: bool = False):
    """Build the FMUs when they are missing or older than their sources (``api.BuildError``,
    a RuntimeError, says why they could not be)."""
    api.build(force, fmu_dir, log=None if quiet else click.echo)

