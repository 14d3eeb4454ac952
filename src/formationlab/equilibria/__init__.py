"""Equilibria of the closed loop: find, refine, classify and de-duplicate them.

"Local minima" are the paper's subject; this package finds the equilibria a
law can end in, where they are, and whether they attract (``stable``) or only
delay (``saddle``). See ``docs/equilibria.md``.

Pipeline: :func:`random_starts` / a study's end states -> :func:`settle` ->
:func:`catalogue` (:func:`refine` each, :func:`classify_equilibrium`, merge
with :func:`same_equilibrium`). :func:`follow` continues one equilibrium in a
law's gain. :func:`find_equilibria` runs the whole pipeline on a scenario (what
the ``equilibria`` command reports).
"""

from .catalogue import Catalogue, catalogue
from .classify import Equilibrium, Stability, classify_equilibrium, restriction_labels
from .continuation import Branch, follow
from .dedup import canonical_pose, group_equilibria, same_equilibrium
from .jacobian import jacobian, reduced_eigenvalues, rigid_modes
from .refine import Refined, refine
from .report import EquilibriaConfig, EquilibriaReport, find_equilibria, parse_equilibria
from .search import random_starts, settle

__all__ = [
    "Branch",
    "Catalogue",
    "EquilibriaConfig",
    "EquilibriaReport",
    "Equilibrium",
    "Refined",
    "Stability",
    "canonical_pose",
    "catalogue",
    "classify_equilibrium",
    "find_equilibria",
    "follow",
    "group_equilibria",
    "jacobian",
    "parse_equilibria",
    "random_starts",
    "reduced_eigenvalues",
    "refine",
    "restriction_labels",
    "rigid_modes",
    "same_equilibrium",
    "settle",
]
