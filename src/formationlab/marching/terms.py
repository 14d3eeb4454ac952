"""Marching as plain numbers: what the compiled loop's marching stage adds (:mod:`.stage`).

:func:`march_terms` turns a :data:`~.config.March` into a :class:`MarchTerms`. A reference
velocity that is a function of time is tabulated by the host, block by block of steps
(:func:`with_references`): the loop reads ``v_ref(k dt)`` of step ``k`` from the table,
the value the stepping driver's ``System.rhs(x, k dt)`` computes.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import Formation
from .config import March, Marching

__all__ = [
    "EVERY",
    "LEADER",
    "MOTION",
    "STILL",
    "MarchTerms",
    "march_terms",
    "with_references",
]

#: Kinds of marching: none, every robot given v_ref, a leader given it alone, motion
#: parameters. (A run that does not march has kind STILL: the stage is small, and one
#: compiled loop serves runs with and without it; see :mod:`formationlab.engine.loop`.)
STILL, EVERY, LEADER, MOTION = 0, 1, 2, 3


class MarchTerms(NamedTuple):
    """A run's marching for the loop (robots in the loop's numbers)."""

    kind: int
    gain: float  #: the robot model's velocity_gain
    leaders: NDArray[np.int64]  #: the leaders' numbers in the loop (0-based; none: empty)
    #: (S, m, d) v_ref of steps k0 .. k0 + S - 1 (S = 1: constant); m = 1, or one row per
    #: leader (in the order of ``leaders``)
    v: NDArray[np.float64]
    k0: int  #: the step of the table's first row
    edge_i: NDArray[np.int64]  #: (m,) motion parameters' edges, first robot
    edge_j: NDArray[np.int64]  #: (m,) second robot
    mu: NDArray[np.float64]  #: (m,) the first robot's gain of z_k = p_i - p_j
    mu_tilde: NDArray[np.float64]  #: (m,) the second robot's


def march_terms(
    march: March | None, formation: Formation | None = None, gain: float = 1.0,
    perm: NDArray[np.integer] | None = None,
) -> MarchTerms:  # fmt: skip
    """The :class:`MarchTerms` of ``march`` (None: kind STILL); ``perm``: the robot each
    number of the loop is (a run whose robots the loop renumbers), or None when they are
    the same."""
    none_i, none_f = np.zeros(0, np.int64), np.zeros(0)
    if march is None:
        return MarchTerms(
            kind=STILL, gain=float(gain), leaders=none_i, v=np.zeros((1, 1, 2)), k0=0,
            edge_i=none_i, edge_j=none_i, mu=none_f, mu_tilde=none_f,
        )  # fmt: skip
    assert formation is not None
    n = formation.n
    where = np.arange(n)  # the loop's number of each robot
    if perm is not None and len(perm):
        where[np.asarray(perm)] = np.arange(n)
    if isinstance(march, Marching):
        v = np.array(march.reference(0.0), dtype=float).reshape(1, -1, formation.dim)
        if march.time_dependent:  # (tabulated block by block: with_references)
            v = np.zeros_like(v)
        leaders = where[np.array(march.leaders, dtype=np.int64) - 1].astype(np.int64)
        return MarchTerms(
            kind=LEADER if leaders.size else EVERY, gain=float(gain), leaders=leaders, v=v, k0=0,
            edge_i=none_i, edge_j=none_i, mu=none_f, mu_tilde=none_f,
        )  # fmt: skip
    edges = formation.edges
    return MarchTerms(
        kind=MOTION, gain=float(gain), leaders=none_i, v=np.zeros((1, 1, 2)), k0=0,
        edge_i=where[edges[:, 0]].astype(np.int64), edge_j=where[edges[:, 1]].astype(np.int64),
        mu=np.array(march.mu, dtype=float), mu_tilde=np.array(march.mu_tilde, dtype=float),
    )  # fmt: skip


def with_references(
    terms: MarchTerms, march: March | None, k0: int, k1: int, dt: float
) -> MarchTerms:
    """``terms`` with ``v_ref(k dt)`` of steps ``k0`` to ``k1`` when it is a function of
    time (the driver's time of step ``k``), else ``terms`` itself."""
    if not (isinstance(march, Marching) and march.time_dependent):
        return terms
    v = np.array([march.reference(k * dt) for k in range(k0, k1 + 1)], dtype=float)
    return terms._replace(v=v.reshape(k1 - k0 + 1, -1, v.shape[-1]), k0=int(k0))
