"""Where runs end: candidate end states from random starts or from a study.

Random starts alone almost never end at a saddle (its stable manifold has
measure zero), yet saddles are what delay runs. Invariant subspaces of the
closed loop hold them: for laws along the lines joining robots (the distance
law of eq. 8 and Khatib's repulsion) every line is invariant, so starts with
all robots on one line end at a *collinear* equilibrium. :func:`random_starts`
therefore mixes a fraction of collinear starts with starts spread in a square.

:func:`settle` integrates a batch of starts together with a fixed-step
integrator (every law takes positions of shape ``(..., n, 2)``); a trial whose
step would bring two robots to contact is frozen and marked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..analysis import Tolerances, classify
from ..controllers import Law
from ..dynamics import System
from ..errors import ParameterError
from ..integrators import RK4, FixedStepIntegrator, ImplicitEuler
from ..spec import Formation
from ..validation import fraction, whole

__all__ = ["Settled", "random_starts", "settle"]


def random_starts(
    formation: Formation,
    count: int,
    rng: np.random.Generator,
    *,
    half_width: float | None = None,
    collinear: float = 0.2,
) -> NDArray[np.float64]:
    """``count`` random initial states, shape ``(count, n, 2)``, none overlapping.

    Parameters
    ----------
    half_width : float, optional
        Starts are uniform in ``[-L, L]^2``; default ``L = 3 max d_ij``, the
        spread of the paper's section 4 (``(-3, -3), (3, -3), (0, 3)``, ``d = 1``).
    collinear : float
        Fraction of the starts with all robots on one random line through the
        origin (uniform in ``[-L, L]`` along it).
    """
    count, collinear = whole(count, "starts", minimum=0), fraction(collinear, "collinear")
    n = formation.n
    L = float(half_width if half_width is not None else 3.0 * formation.distances.max())
    gap = 2.0 * formation.contact_matrix.max()
    n_line = round(collinear * count)
    out = np.empty((count, n, 2))
    iu, ju = np.triu_indices(n, k=1)
    for b in range(count):
        for _ in range(1000):
            if b < n_line:
                ang = rng.uniform(0.0, np.pi)
                s = rng.uniform(-L, L, size=n)
                q = s[:, None] * np.array([np.cos(ang), np.sin(ang)])
            else:
                q = rng.uniform(-L, L, size=(n, 2))
            r = np.linalg.norm(q[ju] - q[iu], axis=-1)
            if np.all(r > gap):
                break
        else:  # pragma: no cover - only for absurdly crowded formations
            raise ParameterError(
                f"could not place {n} robots without overlap in [-{L:g}, {L:g}]^2; "
                "use a larger half_width"
            )
        out[b] = q
    return out


@dataclass(frozen=True, kw_only=True, eq=False)
class Settled:
    """End states of a batch of runs.

    Attributes
    ----------
    q : ndarray, shape (B, n, 2)
        Final (or last accepted, for collisions) positions.
    u : ndarray, shape (B, n, 2)
        Velocities of the last step (the Filippov velocity on a surface).
    outcome : ndarray of str, shape (B,)
        :data:`formationlab.OUTCOMES` of each trial.
    """

    q: NDArray[np.float64]
    u: NDArray[np.float64]
    outcome: NDArray[np.str_]


def settle(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    *,
    duration: float = 60.0,
    integrator: FixedStepIntegrator | None = None,
    speed: float = 1e-6,
    tolerances: Tolerances | None = None,
) -> Settled:
    """Integrate a batch of starts ``q0`` (``(B, n, 2)``) until they stop or ``duration``.

    The batch is stepped together. A step is split into up to 256 substeps
    where the robots would otherwise move more than 5% of the shortest desired
    distance (far from the formation the cubic laws, e.g. ``squared-distance``,
    are fast and stiff; this keeps any fixed-step scheme stable there without
    slowing the rest of the batch). A trial stops once its robots move slower
    than ``speed`` (displacement per step over ``dt``, checked every 10 steps:
    on a sliding-mode equilibrium the one-sided fields do not vanish, the
    motion does). A step that would reach contact is retried in 50 substeps
    (the field is stiff near contact, the exact flow never touches); if that
    fails too the trial stops with outcome ``"collision"``.

    The default integrator is ``RK4(dt=0.01)`` for a smooth law and
    ``ImplicitEuler(dt=0.01)`` for a switching one: explicit schemes chatter
    across an attractive switching surface and can both miss a sliding
    equilibrium and leave it by a spurious drift, the implicit one lands on
    the surface and slides (``formationlab.integrators.implicit``).

    Returns
    -------
    Settled
        ``u`` is the velocity of the last step (the Filippov velocity on a
        surface), which the outcome classification uses.
    """
    q = formation.check_positions(q0).copy()
    if q.ndim != 3:
        raise ParameterError(f"settle takes starts of shape (B, n, 2), got {q.shape}")
    if integrator is None:
        integrator = RK4(dt=0.01) if law.smooth else ImplicitEuler(dt=0.01)
    integ = integrator
    system = System(formation=formation, law=law)
    iu, ju = np.triu_indices(formation.n, k=1)
    contact = formation.contact_matrix[iu, ju]
    live = np.ones(len(q), bool)
    hit = np.zeros(len(q), bool)
    vel = np.zeros_like(q)
    steps = int(np.ceil(duration / integ.dt))
    reach = 0.05 * float(formation.distances.min())
    for k in range(steps):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        new = _limited_step(integ, system, q[idx], integ.dt, reach)
        bad = _rejected(new, iu, ju, contact)
        if bad.any():  # near contact the field is stiff: retry those trials in substeps
            new[bad] = _step(integ, system, q[idx[bad]], integ.dt, 50)
            bad = _rejected(new, iu, ju, contact)
        hit[idx[bad]] = True
        live[idx[bad]] = False
        good = idx[~bad]
        vel[good] = (new[~bad] - q[good]) / integ.dt
        q[good] = new[~bad]
        if k % 10 == 0 and good.size:
            v = np.max(np.linalg.norm(vel[good], axis=-1), axis=-1)
            live[good[v < speed]] = False
    outcome = np.array(
        [classify(formation, q[b], vel[b], tolerances, contact=bool(hit[b])) for b in range(len(q))]
    )
    return Settled(q=q, u=vel, outcome=outcome)


def _limited_step(
    integ: FixedStepIntegrator, system: System, q: NDArray, dt: float, reach: float
) -> NDArray:
    """One step of ``dt`` per trial, in ``2^k`` substeps where a trial is fast."""
    with np.errstate(all="ignore"):
        speed = np.max(np.linalg.norm(system.rhs(q), axis=-1), axis=-1)
    need = np.clip(np.ceil(np.log2(np.maximum(speed * dt / reach, 1.0))), 0, 8).astype(int)
    out = np.empty_like(q)
    for k in np.unique(need):
        sel = need == k
        out[sel] = _step(integ, system, q[sel], dt, 2**k)
    return out


def _step(integ: FixedStepIntegrator, system: System, q: NDArray, dt: float, sub: int) -> NDArray:
    with np.errstate(all="ignore"):
        for _ in range(sub):
            q = integ.step(system, q, dt / sub)
    return q


def _rejected(q: NDArray, iu: NDArray, ju: NDArray, contact: NDArray) -> NDArray[np.bool_]:
    with np.errstate(all="ignore"):
        r = np.linalg.norm(q[:, ju] - q[:, iu], axis=-1)
    return ~np.all(np.isfinite(q), axis=(-2, -1)) | np.any(r <= contact, axis=-1)
