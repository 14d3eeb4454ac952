"""Where runs end: candidate end states from random starts or from a study.

Random starts alone almost never end at a saddle (its stable manifold has
measure zero), yet saddles are what delay runs. Invariant subspaces of the
closed loop hold them: for laws along the lines joining robots (the distance
law of eq. 8 and Khatib's repulsion) every line is invariant, so starts with
all robots on one line end at a *collinear* equilibrium. :func:`random_starts`
therefore mixes a fraction of collinear starts with starts spread in a square.
In space every plane is invariant too (the distance laws' terms lie along the lines
joining robots), so a further fraction of the starts has all robots on one random plane
(the chirality restriction pushes across the planes of its tetrahedra, and takes such
starts out of their plane).

:func:`settle` integrates a batch of starts together with a fixed-step
integrator through the stepping driver; a trial whose step the contact rule
rejects is frozen and marked.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..dynamics import System
from ..errors import ParameterError
from ..formation.spec import Formation
from ..integrators import RK4, FixedStepIntegrator, ImplicitEuler, StopRule, drive
from ..integrators.substeps import Substepped
from ..outcomes.analysis import Tolerances
from ..outcomes.batch import BatchResult
from ..validation import fraction, whole

__all__ = ["random_starts", "settle"]


def random_starts(
    formation: Formation,
    count: int,
    rng: np.random.Generator,
    *,
    half_width: float | None = None,
    collinear: float = 0.2,
    coplanar: float = 0.2,
) -> NDArray[np.float64]:
    """``count`` random initial states, shape ``(count, n, d)``, none overlapping.

    Parameters
    ----------
    half_width : float, optional
        Starts are uniform in ``[-L, L]^d``; default ``L = 3 max d_ij``, the
        spread of the paper's section 4 (``(-3, -3), (3, -3), (0, 3)``, ``d = 1``).
    collinear : float
        Fraction of the starts with all robots on one random line through the
        origin (uniform in ``[-L, L]`` along it).
    coplanar : float
        In space (``formation.dim == 3``), the fraction of the starts, after the collinear
        ones, with all robots on one random plane through the origin (uniform in
        ``[-L, L]^2`` in it); not used in the plane.
    """
    count, collinear = whole(count, "starts", minimum=0), fraction(collinear, "collinear")
    coplanar = fraction(coplanar, "coplanar")
    if formation.dim == 3:
        return _starts_in_space(formation, count, rng, half_width, collinear, coplanar)
    n = formation.n
    L = float(half_width if half_width is not None else 3.0 * formation.distances.max())
    n_line = round(collinear * count)

    def draw(b: int) -> NDArray[np.float64]:
        if b < n_line:
            ang = rng.uniform(0.0, np.pi)
            s = rng.uniform(-L, L, size=n)
            return s[:, None] * np.array([np.cos(ang), np.sin(ang)])
        return rng.uniform(-L, L, size=(n, 2))

    return _apart(formation, count, L, 2, draw)


def _starts_in_space(
    formation: Formation,
    count: int,
    rng: np.random.Generator,
    half_width: float | None,
    collinear: float,
    coplanar: float,
) -> NDArray[np.float64]:
    """:func:`random_starts` in space: ``(count, n, 3)``, in ``[-L, L]^3``, a fraction on a
    line and one on a plane (through the origin, of directions uniform on the sphere)."""
    n = formation.n
    L = float(half_width if half_width is not None else 3.0 * formation.distances.max())
    n_line = round(collinear * count)
    n_plane = min(round(coplanar * count), count - n_line)

    def draw(b: int) -> NDArray[np.float64]:
        if b < n_line:
            axis = rng.standard_normal(3)
            return rng.uniform(-L, L, size=n)[:, None] * (axis / np.linalg.norm(axis))
        if b < n_line + n_plane:  # an orthonormal pair spanning a random plane
            frame, _ = np.linalg.qr(rng.standard_normal((3, 2)))
            return rng.uniform(-L, L, size=(n, 2)) @ frame.T
        return rng.uniform(-L, L, size=(n, 3))

    return _apart(formation, count, L, 3, draw)


def _apart(
    formation: Formation,
    count: int,
    L: float,
    dim: int,
    draw: Callable[[int], NDArray[np.float64]],
) -> NDArray[np.float64]:
    """``count`` starts ``(count, n, dim)``, start ``b`` drawn by ``draw(b)`` again until no
    two robots are closer than twice the largest contact distance."""
    n = formation.n
    gap = 2.0 * formation.contact_matrix.max()
    out = np.empty((count, n, dim))
    iu, ju = np.triu_indices(n, k=1)
    for b in range(count):
        for _ in range(1000):
            q = draw(b)
            r = np.linalg.norm(q[ju] - q[iu], axis=-1)
            if np.all(r > gap):
                break
        else:  # pragma: no cover - only for absurdly crowded formations
            raise ParameterError(
                f"could not place {n} robots without overlap in [-{L:g}, {L:g}]^{dim}; "
                "use a larger half_width"
            )
        out[b] = q
    return out


def settle(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    *,
    duration: float = 60.0,
    integrator: FixedStepIntegrator | None = None,
    speed: float = 1e-6,
    tolerances: Tolerances | None = None,
    system: System | None = None,
) -> BatchResult:
    """Integrate a batch of starts ``q0`` (``(B, n, d)``) until they stop or ``duration``.

    The stepping driver (:func:`formationlab.integrators.drive`) with the
    scheme wrapped in :class:`~formationlab.integrators.substeps.Substepped`:
    a step is split into up to 256 substeps where the robots would otherwise
    move more than 5% of the shortest desired distance (far from the formation
    the cubic laws, e.g. ``squared-distance``, are fast and stiff), and a step
    the contact rule rejects is retried in 50 substeps (the field is stiff near
    contact, the exact flow never touches); if that fails too the trial stops
    with outcome ``"collision"``. A trial stops once its robots move slower than
    ``speed`` (the driver's stop rule, checked every 10 steps: on a sliding-mode
    equilibrium the one-sided fields do not vanish, the motion does). A trial that
    never stops but keeps its shape over the last ``tolerances.drift_window`` seconds
    is ``drifting`` or ``rotating`` (:mod:`formationlab.outcomes.rigid_motion`).

    The default integrator is ``RK4(dt=0.01)`` for a smooth law and
    ``ImplicitEuler(dt=0.01)`` for a switching one: explicit schemes chatter
    across an attractive switching surface and can both miss a sliding
    equilibrium and leave it by a spurious drift, the implicit one lands on
    the surface and slides (``formationlab.integrators.implicit``).

    ``system`` (default ``System(formation, law)``) is the closed loop to settle, e.g.
    with obstacles and a safety filter.

    Returns
    -------
    BatchResult
        ``u_final`` is the velocity of the last step (the Filippov velocity on a
        surface), which the outcome classification uses.
    """
    q = formation.check_positions(q0)
    if q.ndim != 3:
        raise ParameterError(f"settle takes starts of shape (B, n, d), got {q.shape}")
    if integrator is None:
        integrator = RK4(dt=0.01) if law.smooth else ImplicitEuler(dt=0.01)
    stepper = Substepped(inner=integrator, reach=0.05 * float(formation.distances.min()))
    tol = tolerances or Tolerances()
    out = drive(
        system or System(formation=formation, law=law), stepper, q,
        n_steps=int(np.ceil(duration / integrator.dt)), stop=StopRule(speed=speed, check_every=10),
        window=tol.drift_steps(integrator.dt),
    )  # fmt: skip
    return BatchResult.from_final(
        formation, x=out.x, v=out.v, status=out.status, steps=out.steps,
        min_clearance=out.min_clearance, min_obstacle_clearance=out.min_obstacle_clearance,
        net_speed=out.net_speed, dt=integrator.dt,
        tolerances=tol, q_window=out.q_window, window_step=out.window_step,
    )  # fmt: skip
