"""The misalignment source's Model Exchange edition (``me_base``): ``alpha(t)`` and its
rate from a time table, no states, no inputs.  Its only discontinuities (the rate's jumps)
are at the table's times: time events (``next_time_event``), not state events.
"""
from __future__ import annotations

from .me_base import ModelExchange
from .signals import TimeTable


class MisalignmentME(ModelExchange):
    OUTPUTS = ("misalignment", "misalignment_rate")

    def __init__(self, table: TimeTable):
        self.table = table

    def start(self):
        return []

    def derivatives(self, t, x, u):
        return []

    def outputs(self, t, x, u):
        return [self.table.value(t), self.table.rate(t)]

    def next_time_event(self, t: float) -> float | None:
        """The first time of the table after ``t`` (where the rate jumps), or None."""
        return self.table.next_time(t)

    @property
    def dependencies(self):
        return {"misalignment": (), "misalignment_rate": ()}

    def partials(self, t, x, u):
        return {}
