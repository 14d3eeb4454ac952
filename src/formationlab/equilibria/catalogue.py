"""From end states to a catalogue of distinct, classified equilibria.

:func:`catalogue` takes candidate end states (from :func:`~.search.settle` or
from a study's trials), counts each against the equilibria already found,
refines the others with :func:`~.refine.refine`, classifies them with
:func:`~.classify.classify_equilibrium` and merges duplicates with
:func:`~.dedup.same_equilibrium`. Candidates whose run ended ``drifting`` or
``rotating`` are refined to relative equilibria (``refine(..., moving=True)``:
shape and rigid motion together; in space a screw), the others to static ones.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..dynamics import System
from ..formation.spec import Formation
from ..outcomes.analysis import Tolerances
from ..outcomes.rigid_motion import kabsch
from .classify import Equilibrium, classify_equilibrium
from .constrained import active_set, classify_deadlock, refine_deadlock
from .dedup import canonical_pose, same_equilibrium
from .refine import refine

__all__ = ["Catalogue", "catalogue"]

#: outcomes of the runs whose end states are refined to relative equilibria
MOVING = ("drifting", "rotating")


@dataclass(frozen=True, kw_only=True, eq=False)
class Catalogue:
    """Distinct equilibria of a law on a formation, and how many trials ended at each.

    Attributes
    ----------
    equilibria : list of Equilibrium
        The desired one first (if found), then by decreasing count.
    counts : list of int
        Trials that ended at each equilibrium.
    skipped : dict of str to int
        Candidates not attributed to an equilibrium, by reason
        (``"collision"``, ``"not-refined"``, ``"non-finite"``: the field overflows there).
    """

    formation: Formation
    law: Law
    equilibria: list[Equilibrium]
    counts: list[int]
    skipped: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"equilibria": [...], ...}`` (robot numbers 1-based in labels)."""
        edges = [f"{i + 1}-{j + 1}" for i, j in self.formation.edges]
        items = []
        for k, (eq, count) in enumerate(zip(self.equilibria, self.counts, strict=True)):
            lam = eq.eigenvalues
            items.append(
                {
                    "id": k + 1,
                    "positions": eq.q.tolist(),
                    "distances": dict(zip(edges, eq.distances.tolist(), strict=True)),
                    "residual": eq.residual,
                    "stability": eq.stability,
                    "unstable_directions": eq.unstable_directions,
                    "eigenvalues": (
                        lam.real.tolist()
                        if np.all(lam.imag == 0)
                        else [[z.real, z.imag] for z in lam]
                    ),
                    "desired": eq.desired,
                    "outcome": eq.outcome,
                    "zero_directions": eq.zero_directions,
                    "count": count,
                    "active_restrictions": list(eq.active),
                    "switching_surfaces": list(eq.surfaces),
                    "attractive": eq.attractive,
                    "safety_constraints": list(eq.constraints),
                    "multipliers": eq.multipliers.tolist(),
                    "growth_rate": eq.growth_rate,
                    "e_folding_time": (1.0 / eq.growth_rate if eq.growth_rate > 0 else None),
                    "velocity": eq.velocity.tolist(),
                    "speed": eq.speed,
                    "angular_velocity": eq.omega,
                    "axis": None if eq.axis is None else eq.axis.tolist(),
                    "centre": None if eq.centre is None else eq.centre.tolist(),
                }
            )
        return {
            "law": self.law.name,
            "equilibria": items,
            "candidates": int(sum(self.counts) + sum(self.skipped.values())),
            "skipped": dict(self.skipped),
        }


def catalogue(
    formation: Formation,
    law: Law,
    candidates: NDArray[np.float64],
    *,
    outcomes: NDArray[np.str_] | None = None,
    extra: list[NDArray[np.float64]] | None = None,
    tolerances: Tolerances | None = None,
    match_tol: float = 1e-3,
    moving_match_tol: float = 2e-2,
    system: System | None = None,
) -> Catalogue:
    """Refine, classify and merge the end states ``candidates`` (``(B, n, d)``).

    Parameters
    ----------
    outcomes : ndarray of str, shape (B,), optional
        Outcome of each trial; ``"collision"`` trials are skipped.
    extra : list of ndarray (n, d), optional
        States to refine and include with count 0 (e.g. seeds of saddles).
    match_tol : float
        A raw candidate within this (pairwise distances, RMS fit) of an
        equilibrium already found is counted there without refining it.
    moving_match_tol : float
        The same for the end states of ``drifting`` and ``rotating`` runs: explicit
        Euler leaves them within its chatter (about 5e-3) of the relative equilibrium.
    system : System, optional
        The closed loop with obstacles and a safety filter: a candidate where the
        filter holds a constraint active is refined and classified as a deadlock
        (:mod:`~formationlab.equilibria.constrained`); the others as equilibria of
        ``law``.
    """
    cand = np.asarray(candidates, dtype=float).reshape(-1, formation.n, formation.dim)
    outs = np.asarray(outcomes) if outcomes is not None else np.full(len(cand), "")
    found: list[Equilibrium] = []
    counts: list[int] = []
    skipped: Counter[str] = Counter()

    def attribute(q: NDArray, tol: float) -> int | None:
        for k, eq in enumerate(found):
            if same_equilibrium(formation, eq.q, q, tol=tol, invariance=law.invariance):
                return k
        return None

    with np.errstate(over="ignore", invalid="ignore"):  # a trial thrown far away overflows
        finite = np.array([bool(np.isfinite(law.control(formation, q)).all()) for q in cand])
    finite = finite.reshape(-1) if finite.size else np.zeros(0, bool)
    keep = (outs != "collision") & finite
    pending = [(q, 1, o in MOVING) for q, o, k in zip(cand, outs, keep, strict=True) if k]
    skipped["collision"] += int(np.sum(outs == "collision"))
    skipped["non-finite"] += int(np.sum((outs != "collision") & ~finite))
    pending += [(np.asarray(q, dtype=float), 0, False) for q in (extra or [])]
    for q, weight, moving in pending:
        k = attribute(q, moving_match_tol if moving else match_tol) if weight else None
        if k is None:
            eq_or_none = _refined(formation, law, q, tolerances, system, moving)
            if eq_or_none is None:
                skipped["not-refined"] += weight
                continue
            eq = eq_or_none
            k = attribute(eq.q, 1e-6)
            if k is None:
                found.append(_posed(eq, law.invariance))
                counts.append(0)
                k = len(found) - 1
        counts[k] += weight
    order = sorted(range(len(found)), key=lambda k: (not found[k].desired, -counts[k]))
    return Catalogue(
        formation=formation,
        law=law,
        equilibria=[found[k] for k in order],
        counts=[counts[k] for k in order],
        skipped={k: v for k, v in skipped.items() if v},
    )


def _refined(
    formation: Formation,
    law: Law,
    q: NDArray[np.float64],
    tolerances: Tolerances | None,
    system: System | None,
    moving: bool = False,
) -> Equilibrium | None:
    """The classified equilibrium near ``q``, a deadlock if the filter is active there
    (a relative equilibrium for the end state of a moving run)."""
    if system is not None and system.filtered:
        if len(active_set(system, q)):
            dead = refine_deadlock(system, q)
            return classify_deadlock(system, dead, tolerances) if dead.success else None
    ref = refine(formation, law, q, moving=moving)
    if not ref.success:
        return None
    return classify_equilibrium(formation, law, ref, tolerances)


def _posed(eq: Equilibrium, invariance: str = "rotation") -> Equilibrium:
    """``eq`` in its canonical pose, its velocity turned with it (scaled: left as it is)."""
    if invariance == "scale":
        return replace(eq, q=canonical_pose(eq.q, "scale"))
    if eq.q.shape[-1] == 3:  # the velocity and the axis turned with the shape
        posed = canonical_pose(eq.q)
        rot, _ = kabsch(eq.q - eq.q.mean(axis=0), posed - posed.mean(axis=0))
        axis = None if eq.axis is None else rot @ eq.axis
        return replace(eq, q=posed, velocity=rot @ eq.velocity, axis=axis)
    d = eq.q[1] - eq.q[0]
    c, s = d / max(float(np.hypot(*d)), 1e-300)
    v = np.array(
        [c * eq.velocity[0] + s * eq.velocity[1], -s * eq.velocity[0] + c * eq.velocity[1]]
    )
    return replace(eq, q=canonical_pose(eq.q), velocity=v)
