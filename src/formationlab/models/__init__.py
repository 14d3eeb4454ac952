"""Robot motion models: how a law's control becomes the motion of a robot.

``MODELS`` maps a model's name (as in scenario files) to its class; the
contract a model implements is in :mod:`formationlab.models.base`.
"""

from .base import RobotModel
from .registry import MODELS, get_model, register_model
from .single_integrator import SingleIntegrator

__all__ = ["MODELS", "RobotModel", "SingleIntegrator", "get_model", "register_model"]
