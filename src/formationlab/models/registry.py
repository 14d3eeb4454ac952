"""The robot models by name (as in scenario files): ``MODELS``, :func:`register_model`."""

from __future__ import annotations

from typing import TypeVar

from ..registry import Registry
from .base import RobotModel

__all__ = ["MODELS", "get_model", "initial_keys", "register_model"]

#: The robot models by name; case-insensitive, with suggestions.
MODELS: Registry[RobotModel] = Registry("robot model")
M = TypeVar("M", bound=type[RobotModel])


def register_model(cls: M) -> M:
    """Class decorator: make a robot model available by its ``name``."""
    return MODELS.register(cls)


def get_model(name: str, **params: object) -> RobotModel:
    """The robot model registered as ``name`` (any case), built with ``params``."""
    return MODELS.build(name, **params)


def initial_keys() -> dict[str, tuple[str, ...]]:
    """Each key of a model's initial state (``headings``, ``velocities``) and the models
    that take it, for the scenario's ``[robots]`` and :func:`formationlab.simulate` alike."""
    owners: dict[str, list[str]] = {}
    for name in MODELS:
        for key in MODELS[name].initial_keys:
            owners.setdefault(key, []).append(name)
    return {k: tuple(v) for k, v in owners.items()}
