"""The robot models by name (as in scenario files): ``MODELS``, :func:`register_model`."""

from __future__ import annotations

from typing import TypeVar

from ..errors import ParameterError
from .base import RobotModel

__all__ = ["MODELS", "get_model", "register_model"]

MODELS: dict[str, type[RobotModel]] = {}
M = TypeVar("M", bound=type[RobotModel])


def register_model(cls: M) -> M:
    """Class decorator: make a robot model available by its ``name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    MODELS[cls.name] = cls
    return cls


def get_model(name: str, **params: object) -> RobotModel:
    """The robot model registered as ``name``, built with ``params``."""
    try:
        cls = MODELS[name]
    except KeyError:
        known = ", ".join(sorted(MODELS))
        raise ParameterError(f"unknown robot model {name!r}; known models: {known}") from None
    return cls(**params)  # type: ignore[arg-type]
