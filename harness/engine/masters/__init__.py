"""Co-simulation masters, a family in the manner of scipy's ``integrate._ivp``: the
contract every master keeps (``base``), the explicit masters, the iterative ones, the
adaptive ones, the Model Exchange one, and the registry - the one place a master's name is checked.  See
``harness.engine.masters.base`` for the contract."""
from harness.engine.masters.adaptive import AdaptiveMaster, AdaptiveTrapezoidalMaster, StepControl
from harness.engine.masters.base import Master, MasterFailure
from harness.engine.masters.explicit import (ExtrapolatingJacobiMaster, GaussSeidelMaster, JacobiMaster,
                                             LinearExtrapolationMaster, MidpointPredictionMaster,
                                             QuadraticExtrapolationMaster, derivative_weights, extrapolation_weights,
                                             lagrange_weights)
from harness.engine.masters.iterative import (ImplicitFixedPointMaster, ImplicitNewtonMaster, InterfaceJacobian,
                                              IterativeMaster, TrapezoidalFixedPointMaster, TrapezoidalNewtonMaster)
from harness.engine.masters.model_exchange import ModelExchangeCvodeMaster, choose_method
from harness.engine.masters.registry import (MASTERS, TakesNoTolerance, UnknownMaster, check, make, master_class,
                                             stated_options, takes_tolerance)

__all__ = ["AdaptiveMaster", "AdaptiveTrapezoidalMaster", "StepControl", "Master", "MasterFailure",
           "ExtrapolatingJacobiMaster", "GaussSeidelMaster", "JacobiMaster", "LinearExtrapolationMaster",
           "MidpointPredictionMaster", "QuadraticExtrapolationMaster", "derivative_weights", "extrapolation_weights",
           "lagrange_weights",
           "ImplicitFixedPointMaster", "ImplicitNewtonMaster", "InterfaceJacobian", "IterativeMaster",
           "TrapezoidalFixedPointMaster", "TrapezoidalNewtonMaster", "ModelExchangeCvodeMaster", "choose_method", "MASTERS", "UnknownMaster", "check", "make",
           "master_class", "stated_options", "takes_tolerance", "TakesNoTolerance"]
