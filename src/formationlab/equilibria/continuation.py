"""Following an equilibrium as a gain changes (natural-parameter continuation).

Each step refines the previous equilibrium under the law with the next value
of the parameter, starting from the previous position; the branch ends where
the refinement fails (a fold, or the equilibrium reaches a switching surface
and leaves its smooth region) or the classification changes in a way the
caller can read from the returned list.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..formation.spec import Formation
from ..outcomes.analysis import Tolerances
from .classify import Equilibrium, classify_equilibrium
from .refine import refine

__all__ = ["Branch", "follow"]


@dataclass(frozen=True, kw_only=True, eq=False)
class Branch:
    """An equilibrium followed along a parameter.

    Attributes
    ----------
    parameter : str
        The law's parameter that was varied (e.g. ``"k_a"``).
    values : ndarray, shape (K,)
        The values at which the equilibrium was found (the branch may stop early).
    equilibria : list of Equilibrium
        One per value.
    end : str
        Why the branch ended (``"end of range"`` or what the refinement said).
    """

    parameter: str
    values: NDArray[np.float64]
    equilibria: list[Equilibrium]
    end: str


def follow(
    formation: Formation,
    law: Law,
    q: NDArray[np.float64],
    parameter: str,
    values: Sequence[float],
    *,
    tolerances: Tolerances | None = None,
    moving: bool = False,
) -> Branch:
    """Follow the equilibrium near ``q`` (``(n, 2)``) along ``law.<parameter> = values``.

    ``moving`` follows a relative equilibrium (a drifting or rotating shape): each step
    solves for the shape and its rigid motion together (``refine(..., moving=True)``).
    """
    found: list[Equilibrium] = []
    done: list[float] = []
    end = "end of range"
    prev = np.asarray(q, dtype=float)
    surfaces: tuple[str, ...] | None = None
    for v in values:
        lw = law.with_params(**{parameter: float(v)})
        ref = refine(formation, lw, prev, moving=moving)
        if not ref.success:
            end = f"{parameter} = {v:g}: {ref.message}"
            break
        eq = classify_equilibrium(formation, lw, ref, tolerances)
        if surfaces is not None and eq.surfaces != surfaces:
            end = f"{parameter} = {v:g}: the equilibrium moved onto or off a switching surface"
            break
        surfaces = eq.surfaces
        found.append(eq)
        done.append(float(v))
        prev = ref.q
    return Branch(parameter=parameter, values=np.asarray(done), equilibria=found, end=end)
