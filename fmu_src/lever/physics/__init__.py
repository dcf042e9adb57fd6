"""The physics of the driveline, in plain Python (no FMI here).

Sign conventions, stated once for the whole project (Modelica ``Rotational`` style):

* index 1 is the drive (engine) shaft, index 2 the driven (load) shaft;
* angles ``phi`` [rad], speeds ``w`` [rad/s], accelerations ``a`` [rad/s^2],
  torques [N*m], inertias [kg*m^2], all positive in the direction of rotation;
* a torque called ``tau`` is the torque an element applies to the named shaft
  (cut torque), so a shaft obeys ``I * a = (external torque) + tau``;
* the engine torque ``Mg`` drives its shaft (``I1*a1 = Mg + tau1``), the load's
  resistance ``Mc`` opposes its shaft (``I2*a2 = tau2 - Mc``).
"""
from .parameters import Parameter, ParameterError
from .kinematics import TransferFunction, half_coupling_ratio
from .elastic import LinearElasticLaw, TabulatedElasticLaw, elastic_law
from .coupling import LeverCoupling, CouplingResult
from .engine import LinearCharacteristic, TabulatedCharacteristic, engine_characteristic
from .load import ConstantLoad, RandomLoad, FourierLoad, TabulatedLoad, load_model
from .shaft import Shaft

__all__ = [
    "Parameter", "ParameterError", "TransferFunction", "half_coupling_ratio",
    "LinearElasticLaw", "TabulatedElasticLaw", "elastic_law", "LeverCoupling",
    "CouplingResult", "LinearCharacteristic", "TabulatedCharacteristic",
    "engine_characteristic", "ConstantLoad", "RandomLoad", "FourierLoad",
    "TabulatedLoad", "load_model", "Shaft",
]
