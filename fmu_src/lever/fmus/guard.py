"""FMI entry points that never raise into the host.

pythonfmu 0.7 turns any Python exception into fmi2Fatal and frees the Python instance while
keeping a dangling pointer to it, so an exception could crash the importer on its next call.
Instead a refused call logs an error (the native entry that our build puts in front of
pythonfmu's library returns it as fmi2Error) and leaves the instance usable.
"""
from __future__ import annotations

import functools
import inspect
import traceback

from ..physics.parameters import ParameterError


def guarded(default=None):
    """Run an FMI entry point so that no exception escapes: it is logged as an error
    naming the call, and ``default`` (or ``default(self, *args)`` when callable) is
    returned instead."""

    def wrap(method):
        def refused(self, args, error):
            if isinstance(error, ParameterError):
                self._error(f"{method.__name__}: {error}")
            else:
                where = traceback.extract_tb(error.__traceback__)[-1]
                self._error(f"{method.__name__}: internal error {type(error).__name__}: {error} "
                            f"(at {where.name}, line {where.lineno})")
            return default(self, *args) if callable(default) else default

        # The value getters and setters run at every right-hand side of a host's solver:
        # for them (self and one or two arguments, no defaults) a wrapper without packing.
        parameters = inspect.signature(method).parameters.values()
        plain = all(p.kind is p.POSITIONAL_OR_KEYWORD and p.default is p.empty for p in parameters)
        if plain and len(parameters) == 2:
            @functools.wraps(method)
            def call(self, a):
                try:
                    return method(self, a)
                except Exception as error:  # noqa: BLE001 - the importer must survive anything
                    return refused(self, (a,), error)
        elif plain and len(parameters) == 3:
            @functools.wraps(method)
            def call(self, a, b):
                try:
                    return method(self, a, b)
                except Exception as error:  # noqa: BLE001
                    return refused(self, (a, b), error)
        else:
            @functools.wraps(method)
            def call(self, *args):
                try:
                    return method(self, *args)
                except Exception as error:  # noqa: BLE001
                    return refused(self, args, error)

        return call

    return wrap
