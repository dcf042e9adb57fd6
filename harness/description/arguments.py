"""How a refusal names the argument it refuses, as its caller wrote it: the command line's
option (``--set coupling.k``, ``--rtol 'x'``) or the Python API's keyword
(``overrides['coupling.k']``, ``rtol='x'``).  The parsers below the API take an ``Argument``
and name it so; the API says which (``harness.api.inputs.argument``)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Argument:
    """An argument as its caller names it: an option (``--rtol``, starts with a dash) or a
    keyword (``rtol``)."""
    name: str
    #: between the name and a value given (None: a space after an option, "=" after a keyword)
    separator: str | None = None

    @property
    def is_option(self) -> bool:
        return self.name.startswith("-")

    def given(self, shown: str) -> str:
        """The argument with the value as given (``shown``, already written out):
        ``--rtol 'x'`` or ``rtol='x'``."""
        separator = self.separator if self.separator is not None else " " if self.is_option else "="
        return f"{self.name}{separator}{shown}"

    def typed(self, text: str) -> str:
        """The argument with a text as typed: ``--window 0:2 kg`` or ``window='0:2 kg'``."""
        return self.given(text if self.is_option else repr(text))

    def on(self) -> str:
        """A switch turned on: ``--stream`` or ``stream=True``."""
        return self.name if self.is_option else f"{self.name}=True"

    def item(self, key: str) -> str:
        """One entry of it, by its key: ``--set coupling.k`` or ``overrides['coupling.k']``."""
        return f"{self.name} {key}" if self.is_option else f"{self.name}[{key!r}]"

    def __str__(self) -> str:
        return self.name


#: the command line's ``--set``, the default of the scene's overrides
SET = Argument("--set")
