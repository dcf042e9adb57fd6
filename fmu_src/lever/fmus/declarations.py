"""What an adapter declares besides its parameters and inputs (``physics.parameters.Parameter``):
its outputs and its mechanical ports."""
from __future__ import annotations

from typing import NamedTuple


class Output(NamedTuple):
    name: str
    unit: str
    description: str
    #: the output this one is the time derivative of (our vendor annotation; FMI's
    #: ``derivative`` attribute where it is a state derivative): lets a master predict
    #: connected outputs by Taylor expansion
    derivative_of: str = ""
    #: inputs this output depends on directly; None: all inputs if the model has direct
    #: feedthrough (``FEEDTHROUGH``), else none
    depends_on: tuple | None = None


class MechanicalPort(NamedTuple):
    """A rotational flange of the model, as the OSP Interface Specification describes it
    (``AngularMechanicalPort``: a torque and an angular velocity of opposite causality, a
    power bond), with the flange's angle beside it (``AngularDisplacement``: our compliant
    coupling needs angles as well as speeds)."""
    name: str
    torque: str
    angular_velocity: str
    angle: str
    description: str
