"""The marker of a formula: one plain function for numpy callers and for compiled loops."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from numba.extending import register_jitable

__all__ = ["formula"]

F = TypeVar("F", bound=Callable[..., object])


def formula(fn: F) -> F:
    """Mark ``fn`` as a formula: unchanged for Python and numpy callers, and compiled
    inline where a numba kernel calls it (``numba.extending.register_jitable``).

    A formula takes and returns numbers (or tuples of them) and allocates nothing, so
    numpy arrays take it elementwise with the same arithmetic as the compiled loops.
    """
    register_jitable(inline="always")(fn)
    return fn
