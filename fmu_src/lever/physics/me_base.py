"""What a Model Exchange edition of a model needs from the physics, as one small contract
(docs/physics.md#model-exchange-interface).

A model has continuous states ``x``, inputs ``u`` and outputs ``y``, each a tuple of names,
and a discrete mode (stick/slip, a freewheel's contacts...) that changes only at events:

* ``start()``: the states at the start, the mode set;
* ``derivatives(t, x, u)``: ``dx/dt`` in the order of ``STATES`` (names ``der(x)``);
* ``outputs(t, x, u)``: ``y`` in the order of ``OUTPUTS``;
* ``event_indicators(t, x, u)``: functions positive while the mode holds (or on one
  side of an edge), whose sign change is an event - never zero where a mode is entered
  or an edge just crossed (``banded``): a host with its own root finding (CVODE) stops
  with "root found at and very near t" where an indicator is still zero just after the
  event it has handled;
* ``event_update(t, x, u)``: at an event, the states after it (the mode switched);
* ``modes()``: the discrete state that picks the right-hand side's branch (default none):
  an event that changes it is reported to the host as one that changed the states
  (``valuesOfContinuousStatesChanged``), since the right-hand side jumps there and an
  integrator that went on from its history past the event would follow the old mode;
* ``partials(t, x, u)``: the analytic partial derivatives as ``{(of, wrt): value}`` with
  ``of`` a derivative (``der(x)``) or an output and ``wrt`` a state or an input; a pair
  that ``dependencies`` does not declare is zero;
* ``dependencies``: ``{of: (wrt, ...)}`` - what each derivative and output depends on, for
  a modelDescription's ``<ModelStructure>``.  Declared per instance (its parameters):
  a linear engine's derivative depends on its speed, a constant load's does not.

Everything is plain Python on floats (it runs inside FMUs).
"""
from __future__ import annotations


#: hysteresis bands of the event indicators (``banded``, ``edge_side``), in the units of
#: what they measure: far above the round-off of the quantities (a relative speed of two
#: speeds of 1e3 rad/s is exact to 1e-13 rad/s), far below what the physics resolves (a
#: slip ending 1e-6 rad/s late loses 1e-12 J of a reduced inertia of 1 kg*m^2)
ANGLE_BAND = 1e-9         # rad
SPEED_BAND = 1e-6         # rad/s
TORQUE_BAND = 1e-6        # N*m


def edge_side(value: float) -> float:
    """The side of an edge ``value = 0`` a state is on (+1 at and above it, -1 below)."""
    return 1.0 if value >= 0.0 else -1.0


def banded(value: float, side: float, band: float) -> float:
    """The event indicator of an edge crossed both ways, with hysteresis: on side ``side``
    (``edge_side`` at the last event) it is ``value + side * band``, so it is ``band`` away
    from zero where the edge was just crossed and changes sign only once ``value`` is
    ``band`` beyond the edge on the other side.  A mode function (positive while the mode
    holds) is ``banded(value, 1.0, band)``: a mode entered where it is zero (a slip at
    equal speeds) starts at ``band``, and ends once the function is ``-band``."""
    return value + side * band


def der(name: str) -> str:
    """The name FMI gives the derivative of state ``name``."""
    return f"der({name})"


class ModelExchange:
    """The contract (see the module docstring); a model sets the name tuples."""

    STATES: tuple[str, ...] = ()
    INPUTS: tuple[str, ...] = ()
    OUTPUTS: tuple[str, ...] = ()
    EVENTS: tuple[str, ...] = ()

    def start(self) -> list[float]:
        raise NotImplementedError

    def derivatives(self, t: float, x, u) -> list[float]:
        raise NotImplementedError

    def outputs(self, t: float, x, u) -> list[float]:
        raise NotImplementedError

    def event_indicators(self, t: float, x, u) -> list[float]:
        return []

    def event_update(self, t: float, x, u) -> list[float]:
        return list(x)

    def modes(self) -> tuple:
        return ()

    def partials(self, t: float, x, u) -> dict[tuple[str, str], float]:
        raise NotImplementedError

    @property
    def dependencies(self) -> dict[str, tuple[str, ...]]:
        raise NotImplementedError

    # -- derived, the same for every model -------------------------------------------------
    @property
    def unknowns(self) -> tuple[str, ...]:
        """The derivatives' names, then the outputs'."""
        return tuple(der(s) for s in self.STATES) + self.OUTPUTS

    def jacobian(self, t: float, x, u) -> tuple[list[list[float]], list[list[float]]]:
        """``(d unknowns / dx, d unknowns / du)`` as dense rows in the order of ``unknowns``
        (states, then inputs, as columns): the blocks a directional derivative multiplies."""
        values = self.partials(t, x, u)
        rows = self.unknowns
        return ([[values.get((r, s), 0.0) for s in self.STATES] for r in rows],
                [[values.get((r, i), 0.0) for i in self.INPUTS] for r in rows])

    def directional_derivative(self, t: float, x, u, dx, du) -> list[float]:
        """``d unknowns = J_x dx + J_u du``, as ``fmi2GetDirectionalDerivative`` gives it."""
        jx, ju = self.jacobian(t, x, u)
        return [sum(a * b for a, b in zip(row_x, dx)) + sum(a * b for a, b in zip(row_u, du))
                for row_x, row_u in zip(jx, ju)]
