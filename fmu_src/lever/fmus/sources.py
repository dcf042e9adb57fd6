"""``MisalignmentSource`` FMU: a prescribed misalignment angle alpha(t), to drive the
coupling's ``misalignment`` input (like the angle input of Simscape's universal joint).
No inputs; its output depends on time only."""
from __future__ import annotations

from ..physics import component_parameters
from ..physics.me_misalignment import MisalignmentME
from .declarations import Output
from .model_exchange import ModelExchangeSlave


class MisalignmentSource(ModelExchangeSlave):
    DESCRIPTION = "Prescribed misalignment angle alpha(t) from a time table (linear, end values held)"
    PARAMETERS = component_parameters.MISALIGNMENT_SOURCE
    OUTPUTS = (
        Output("misalignment", "rad", "misalignment angle alpha(t)"),
        Output("misalignment_rate", "rad/s", "rate of change of the misalignment angle", derivative_of="misalignment"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._table = None

    def _build(self):
        self._table = component_parameters.misalignment_source_from(self._values())

    def _me_physics(self):
        return MisalignmentME(self._table)

    def _physics_key(self):
        return self._table

    def _compute_outputs(self):
        self.misalignment = self._table.value(self._time)
        self.misalignment_rate = self._table.rate(self._time)

    def _advance(self, t, h):
        return None  # the output is a function of time
