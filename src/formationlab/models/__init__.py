"""Robot motion models: how a law's control becomes the motion of a robot.

``MODELS`` maps a model's name (as in scenario files) to its class; the
contract a model implements is in :mod:`formationlab.models.base`. Models:
:class:`SingleIntegrator` (the paper's), :class:`Unicycle` (with the transforms
of :mod:`~formationlab.models.transforms`) and :class:`DoubleIntegrator`; every
one takes ``max_speed`` (:mod:`~formationlab.models.limits`).
"""

from .base import RobotModel
from .double_integrator import DoubleIntegrator, energy
from .limits import limit_speed, limit_unicycle
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
    "RobotModel",
    "SingleIntegrator",
    "Transform",
    "Unicycle",
    "energy",
    "get_model",
    "limit_speed",
    "limit_unicycle",
    "register_model",
]
