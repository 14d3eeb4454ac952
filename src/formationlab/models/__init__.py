"""Robot motion models: how a law's control becomes the motion of a robot.

``MODELS`` maps a model's name (as in scenario files) to its class; the
contract a model implements is in :mod:`formationlab.models.base`. Models:
:class:`SingleIntegrator` (the paper's), :class:`Unicycle` (with the transforms
of :mod:`~formationlab.models.transforms`), :class:`DoubleIntegrator` and
:class:`Quadrotor` (a velocity lag with limits); every one takes ``max_speed``
(:mod:`~formationlab.models.limits`). Single and double integrators and quadrotors also
move in space (``dims``).
"""

from .base import RobotModel
from .double_integrator import DoubleIntegrator, energy
from .limits import limit_speed, limit_unicycle
from .quadrotor import Quadrotor, quadrotor_energy
from .registry import MODELS, get_model, register_model
from .single_integrator import SingleIntegrator
from .transforms import TRANSFORMS, HeadingTransform, NearIdentity, Transform
from .unicycle import Unicycle

__all__ = [
    "MODELS",
    "TRANSFORMS",
    "DoubleIntegrator",
    "HeadingTransform",
    "NearIdentity",
    "Quadrotor",
    "RobotModel",
    "SingleIntegrator",
    "Transform",
    "Unicycle",
    "energy",
    "get_model",
    "limit_speed",
    "limit_unicycle",
    "quadrotor_energy",
    "register_model",
]
