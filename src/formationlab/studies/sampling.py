"""Random initial states for Monte-Carlo studies.

Trials are seeded in fixed blocks of :data:`SEED_BLOCK` consecutive trial
numbers: block ``b`` (trials ``64 b ... 64 b + 63``) draws from
``numpy.random.default_rng(SeedSequence(S, spawn_key=(b,)))``, the ``b``-th
child of ``SeedSequence(S).spawn``, first one state per trial, then again for
the trials whose draw was rejected, in trial order. Trial ``t``'s initial
state therefore depends on the study's seed ``S`` and ``t`` only: not on the
number of workers, the chunk size, nor the order in which chunks run; and
every group of a study (law x sweep point) starts trial ``t`` from the same
state, which makes comparisons between laws paired. (With a diameter sweep a
draw may be rejected for the larger robots only; then the redraws of that
block differ.) A trial is rerun from its ``seed`` and ``trial`` columns with
:func:`trial_initial_states`.

Drawing per block rather than per trial keeps the cost of seeding below a
microsecond per trial.

A draw in which two robots overlap (``r_ij <= a_ij``), or, in a study with
obstacles, a robot touches an obstacle (clearance ``<= 0``), is rejected and
drawn again. Without obstacles the draws are exactly those of before obstacles
existed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError
from ..formation.spec import Formation
from ..models import RobotModel
from ..safety import obstacle_contacts
from ..validation import seed as check_seed
from .config import BoxInitial, GaussianInitial

__all__ = [
    "MAX_DRAWS",
    "SEED_BLOCK",
    "block_generator",
    "draw_block",
    "model_initial_states",
    "overlapping",
    "trial_initial_states",
]

#: Rounds of redrawing rejected states before giving up (the box is too small).
MAX_DRAWS = 1000
#: Trials per seed block: part of the reproducibility contract, never change it.
SEED_BLOCK = 64


def block_generator(seed: int, block: int) -> np.random.Generator:
    """The generator of seed block ``block``: child ``block`` of ``SeedSequence(seed)``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(block,)))


def overlapping(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether some pair overlaps (``r_ij <= a_ij``): ``q (..., n, 2)`` -> ``(...)`` bool."""
    iu, ju = np.triu_indices(formation.n, k=1)
    r = np.linalg.norm(q[..., ju, :] - q[..., iu, :], axis=-1)
    return np.any(r <= formation.contact_matrix[iu, ju], axis=-1)


def _rejected(
    formation: Formation, q: NDArray[np.float64], obstacles: Sequence[Any]
) -> NDArray[np.bool_]:
    """Overlapping robots, or (with obstacles) a robot on an obstacle; ``(...)`` bool."""
    bad = overlapping(formation, q)
    if obstacles:
        bad |= obstacle_contacts(q, formation.diameters / 2, obstacles).any(axis=(-2, -1))
    return bad


def _draw(
    initial: BoxInitial | GaussianInitial,
    rng: np.random.Generator,
    shape: tuple[int, ...],
    center: NDArray[np.float64] | None,
) -> NDArray[np.float64]:
    if isinstance(initial, BoxInitial):
        return rng.uniform(-initial.half_width, initial.half_width, size=shape)
    assert center is not None  # checked by the caller
    return center + initial.sigma * rng.standard_normal(shape)


def draw_block(
    formation: Formation,
    initial: BoxInitial | GaussianInitial,
    rng: np.random.Generator,
    size: int = SEED_BLOCK,
    *,
    center: NDArray[np.float64] | None = None,
    obstacles: Sequence[Any] = (),
) -> NDArray[np.float64]:
    """``size`` initial states ``(size, n, dim)`` without overlapping robots, from ``rng``.

    All states are drawn at once; the rejected ones are drawn again (in order)
    until none is left.

    Raises
    ------
    ParameterError
        When a state is still overlapping after :data:`MAX_DRAWS` rounds.
    """
    n = formation.n
    q = _draw(initial, rng, (size, n, formation.dim), center)
    bad = np.flatnonzero(_rejected(formation, q, obstacles))
    for _ in range(MAX_DRAWS):
        if bad.size == 0:
            return q
        q[bad] = _draw(initial, rng, (bad.size, n, formation.dim), center)
        bad = bad[_rejected(formation, q[bad], obstacles)]
    what = (
        f"box half_width = {initial.half_width:g}"
        if isinstance(initial, BoxInitial)
        else f"gaussian sigma = {initial.sigma:g}"
    )
    raise ParameterError(
        f"{MAX_DRAWS} draws in a row from the {what} put two robots on top of each other "
        + ("or a robot on an obstacle " if obstacles else "")
        + f"(n = {n}, largest diameter {formation.diameters.max():g}); widen study.initial"
    )


def trial_initial_states(
    formation: Formation,
    initial: BoxInitial | GaussianInitial,
    seed: int,
    trials: ArrayLike,
    *,
    center: ArrayLike | None = None,
    obstacles: Sequence[Any] = (),
) -> NDArray[np.float64]:
    """Initial states of the given trial numbers of a study with ``seed``; ``(B, n, 2)``.

    Parameters
    ----------
    formation : Formation
        Gives ``n`` and the contact distances ``a_ij``.
    initial : BoxInitial or GaussianInitial
        The distribution (see :mod:`formationlab.studies.config`).
    seed : int
        The study's seed, >= 0.
    trials : array_like of int
        0-based trial numbers, any order.
    center : array_like, shape (n, 2), optional
        Centre of a gaussian distribution (required for it).
    obstacles : sequence of Circle or Polygon
        Draws with a robot touching one are rejected too.

    Examples
    --------
    >>> from formationlab import Formation
    >>> f = Formation.from_distances(3, distances=1.0, diameters=0.2)
    >>> q = trial_initial_states(f, BoxInitial(half_width=3.0), seed=7, trials=[0, 5])
    >>> q.shape, bool(abs(q).max() <= 3.0)
    ((2, 3, 2), True)
    """
    check_seed(seed)
    c = None
    if isinstance(initial, GaussianInitial):
        if center is None:
            raise ParameterError("a gaussian initial distribution needs a centre shape")
        c = np.asarray(center, dtype=float)
        if c.shape != (formation.n, formation.dim):
            raise ParameterError(
                f"the centre shape must be ({formation.n}, {formation.dim}), got {c.shape}"
            )
    idx = np.asarray(trials, dtype=np.int64).reshape(-1)
    if idx.size and idx.min() < 0:
        raise ParameterError("trial numbers are >= 0")
    out = np.empty((idx.size, formation.n, formation.dim))
    blocks = idx // SEED_BLOCK
    for b in np.unique(blocks):
        rng = block_generator(int(seed), int(b))
        states = draw_block(formation, initial, rng, center=c, obstacles=obstacles)
        sel = blocks == b
        out[sel] = states[idx[sel] % SEED_BLOCK]
    return out


#: spawn key of the extra state's generators (distinct from the positions' blocks)
_EXTRA_STREAM = 2**32 + 1


def model_initial_states(
    formation: Formation,
    model: RobotModel,
    q0: NDArray[np.float64],
    seed: int,
    trials: ArrayLike,
) -> NDArray[np.float64]:
    """The robot model's initial states ``(B, n, k)`` of trials starting at ``q0`` ``(B, n, 2)``.

    Unicycles get headings uniform in ``[-pi, pi)``, drawn per seed block like the
    positions (so a trial's headings depend on ``(seed, trial)`` only) and drawn
    again while two of the law's points (near-identity hand points) overlap;
    double integrators start at rest. Single integrators: ``q0`` itself.
    """
    if len(model.names_in(formation.dim)) == formation.dim:  # the state is the positions
        return q0
    if "theta" not in type(model).state_names:
        return model.initial_state(q0)  # at rest
    idx = np.asarray(trials, dtype=np.int64).reshape(-1)
    theta = np.empty(q0.shape[:2])
    blocks = idx // SEED_BLOCK
    for b in np.unique(blocks):
        rng = np.random.default_rng(
            np.random.SeedSequence(int(seed), spawn_key=(_EXTRA_STREAM, int(b)))
        )
        block = rng.uniform(-np.pi, np.pi, size=(SEED_BLOCK, formation.n))
        sel = blocks == b
        theta[sel] = block[idx[sel] % SEED_BLOCK]
    x = model.initial_state(q0, headings=theta)
    for draw in range(MAX_DRAWS):
        bad = np.flatnonzero(overlapping(formation, model.points(x)))
        if bad.size == 0:
            return x
        for t in bad:  # rare: per trial, from its own stream
            rng = np.random.default_rng(
                np.random.SeedSequence(int(seed), spawn_key=(_EXTRA_STREAM, int(idx[t]), draw + 1))
            )
            x[t, :, 2] = rng.uniform(-np.pi, np.pi, size=formation.n)
    raise ParameterError(
        f"{MAX_DRAWS} draws of headings in a row put two hand points on top of each other; "
        "use a smaller offset or widen study.initial"
    )
