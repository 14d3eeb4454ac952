"""Equilibria of the filtered closed loop: deadlocks held by active barrier constraints.

A safety filter (:mod:`formationlab.safety`) makes the closed loop's field continuous
but only piecewise smooth: the filtered command is the projection of the law's command
``u_hat`` onto the set the barrier rows allow, and that projection changes its formula
wherever the set of active rows changes. An equilibrium where no row is active is an
equilibrium of the law (plus obstacle repulsion) and is refined and classified as
usual. An equilibrium *with* active rows is a **deadlock**: ``u = 0`` although
``u_hat != 0``. There, with ``u = 0``, every active row ``-grad h_c . u <= gamma h_c^3``
holds with equality, so ``h_c = 0`` (for ``gamma > 0``), and the KKT condition of the
filter's QP at ``u = 0`` says

    ``u_hat(q) = sum_c lambda_c G_c(q)^T``,  ``h_c(q) = 0``,  ``lambda_c >= 0``,

with ``G_c`` the row (``-grad h_c``, one multiplier per pair for the centralized QP;
one per robot and pair for the decentralized filter, each robot's half). That square
(or underdetermined) smooth system in ``(q, lambda)`` is what :func:`refine_deadlock`
solves (scipy's ``least_squares``), starting from a settled end state. A settled state
approaches a deadlock only polynomially (``h ~ (gamma t)^(-1/2)``), so its active set
may still lack constraints that will bind: the candidates are the active rows plus
the rows with ``h <= D^2`` (``D = D_s`` or ``D_o``) into which ``u_hat`` pushes; a
candidate whose multiplier comes out ``<= 0`` is dropped and the system solved again.

Classification (:func:`classify_deadlock`). Near a deadlock with strictly positive
multipliers the active set does not change, so the motion splits into

* the **transverse** directions ``grad h_c``: the filter imposes ``h_dot = -gamma h^3``
  exactly, so ``h -> 0`` from both sides, attracting but not exponentially (the
  linearisation has a zero there: it is non-hyperbolic by construction of the cubic
  class-K function), and
* the **tangential** directions of the manifold ``{h_c = 0}``, minus the rigid motions
  when no obstacle acts on the state (none, or every robot beyond Khatib's range and no
  active obstacle row): the Jacobian of the filtered field restricted to them
  (central differences along an orthonormal basis) gives eigenvalues, and the deadlock
  is ``stable``, a ``saddle`` or ``degenerate`` by their real parts, as for the laws'
  equilibria (:mod:`formationlab.equilibria.classify`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..dynamics import System
from ..outcomes.analysis import Tolerances, classify
from ..safety import obstacle_barrier_rows
from .classify import Equilibrium, Stability
from .jacobian import complement, rigid_modes

__all__ = ["ActiveSet", "active_set", "classify_deadlock", "refine_deadlock"]


@dataclass(frozen=True, kw_only=True)
class ActiveSet:
    """The active barrier constraints of a state: pairs ``(i, j)`` and ``(robot, obstacle)``."""

    pairs: tuple[tuple[int, int], ...]
    obstacles: tuple[tuple[int, int], ...]

    def __len__(self) -> int:
        return len(self.pairs) + len(self.obstacles)

    def labels(self) -> tuple[str, ...]:
        """``"pair 1-2"``, ``"robot 3 - obstacle 1"`` (1-based)."""
        return tuple(f"pair {i + 1}-{j + 1}" for i, j in self.pairs) + tuple(
            f"robot {i + 1} - obstacle {o + 1}" for i, o in self.obstacles
        )


def active_set(system: System, q: NDArray[np.float64]) -> ActiveSet:
    """The constraints the filter holds active at ``q`` (``(n, 2)``)."""
    res = system.filter_result(q)
    return ActiveSet(
        pairs=tuple(sorted({(int(i), int(j)) for _, i, j in res.active_pairs})),
        obstacles=tuple(sorted({(int(i), int(o)) for _, i, o in res.active_obstacles})),
    )


def _candidates(system: System, q: NDArray[np.float64]) -> ActiveSet:
    """Active rows, plus rows with ``h <= D^2`` that ``u_hat`` pushes into (module docstring)."""
    act = active_set(system, q)
    assert system.safety is not None
    cfg = system.safety
    u = _u_hat(system, q)
    pairs, obs = set(act.pairs), set(act.obstacles)
    n = q.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            w = q[i] - q[j]
            if w @ w - cfg.distance**2 <= cfg.distance**2 and -2 * w @ (u[i] - u[j]) > 0:
                pairs.add((i, j))
    for o in range(len(system.obstacles)):
        for i in range(n):
            probe = ActiveSet(pairs=(), obstacles=((i, o),))
            grads, h = _rows(system, q, probe)
            if h[0] <= cfg.d_obstacle**2 and -np.sum(grads[0] * u) > 0:
                obs.add((i, o))
    return ActiveSet(pairs=tuple(sorted(pairs)), obstacles=tuple(sorted(obs)))


def _u_hat(system: System, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The law's command plus obstacle repulsion (what the filter receives)."""
    u = system.law.control(system.formation, q)
    return system._repelled(q, u) if system.obstacles else u


def _rows(
    system: System, q: NDArray[np.float64], act: ActiveSet
) -> tuple[list[NDArray[np.float64]], NDArray[np.float64]]:
    """Per constraint: the gradient ``grad h_c`` ``(n, 2)``, and ``h_c``; ``(len(act),)``."""
    assert system.safety is not None
    cfg = system.safety
    grads, hs = [], []
    for i, j in act.pairs:
        w = q[i] - q[j]
        g = np.zeros_like(q)
        g[i], g[j] = 2 * w, -2 * w
        grads.append(g)
        hs.append(w @ w - cfg.distance**2)
    for i, o in act.obstacles:
        rows = obstacle_barrier_rows(
            q[i : i + 1], [system.obstacles[o]], distance=cfg.d_obstacle, gamma=cfg.gamma
        )
        k = int(np.argmin(rows.h[0]))  # the nearest piece (a circle, or a polygon's edge)
        g = np.zeros_like(q)
        g[i] = -rows.a[0, k]  # a = -2 (q_i - p*) = -grad h
        grads.append(g)
        hs.append(rows.h[0, k])
    return grads, np.asarray(hs, dtype=float)


def _split(system: System) -> bool:
    """Whether each robot of a pair carries its own multiplier (the decentralized filter)."""
    return system.safety is not None and system.safety.filter == "barrier-decentralized"


def _kkt(system: System, q: NDArray, lam: NDArray, act: ActiveSet) -> NDArray[np.float64]:
    """``u_hat - sum lambda G^T`` (``2n``) and ``h_c`` (``len(act)``), stacked."""
    grads, h = _rows(system, q, act)
    force = np.zeros_like(q)
    k = 0
    for c, g in enumerate(grads):
        if _split(system) and c < len(act.pairs):
            i, j = act.pairs[c]
            force[i] -= lam[k] * g[i]
            force[j] -= lam[k + 1] * g[j]
            k += 2
        else:
            force -= lam[k] * g  # G_c = -grad h_c
            k += 1
    return np.concatenate([(_u_hat(system, q) - force).ravel(), h])


def _n_multipliers(system: System, act: ActiveSet) -> int:
    return len(act) + (len(act.pairs) if _split(system) else 0)


@dataclass(frozen=True, kw_only=True, eq=False)
class Deadlock:
    """A refined deadlock: state, active set, multipliers and the KKT residual."""

    q: NDArray[np.float64]
    active: ActiveSet
    multipliers: NDArray[np.float64]
    residual: float
    success: bool
    message: str = ""


def refine_deadlock(system: System, q0: NDArray[np.float64], *, tol: float = 1e-9) -> Deadlock:
    """Solve the KKT system of a deadlock (module docstring) from ``q0`` ``(n, 2)``.

    ``success`` when the residual is below ``tol`` times the size of ``u_hat`` (at
    least 1) and every free multiplier is positive. Under the decentralized filter each
    robot's half of a pair row has its own multiplier; a half whose multiplier comes out
    negative is fixed at zero (that robot moves away: only its partner's half binds).
    """
    q0 = np.asarray(q0, dtype=float)
    act = _candidates(system, q0)
    free = np.ones(_n_multipliers(system, act), bool)
    dead = Deadlock(
        q=q0, active=act, multipliers=np.zeros(0), residual=np.inf, success=False,
        message="no active constraint",
    )  # fmt: skip
    while len(act) and free.any():
        dead = _solve(system, q0, act, free, tol)
        lam = np.where(free, dead.multipliers, np.inf)
        if dead.success or np.all(lam > 0):
            return dead
        k = int(np.argmin(lam))
        free[k] = False
        split = _split(system)
        pairs, p = list(act.pairs), len(act.pairs)
        if split and k < 2 * p and free[2 * (k // 2) : 2 * (k // 2) + 2].any():
            continue  # the other half of the pair still binds
        drop = k // 2 if split and k < 2 * p else k if k < p else None
        if drop is not None and drop < p:
            lo = 2 * drop if split else drop
            free = np.delete(free, slice(lo, lo + (2 if split else 1)))
            pairs.pop(drop)
            act = ActiveSet(pairs=tuple(pairs), obstacles=act.obstacles)
        else:
            o = k - (2 * p if split else p)
            free = np.delete(free, k)
            act = ActiveSet(
                pairs=act.pairs, obstacles=tuple(x for c, x in enumerate(act.obstacles) if c != o)
            )
    return dead


def _solve(
    system: System, q0: NDArray[np.float64], act: ActiveSet, free: NDArray[np.bool_], tol: float
) -> Deadlock:
    """The KKT system of the constraints ``act`` (free multipliers ``free``) solved from ``q0``."""
    shape, m = q0.shape, int(free.sum())

    def full(lam: NDArray) -> NDArray:
        out = np.zeros(free.size)
        out[free] = lam
        return out

    # initial multipliers: least squares of u_hat = sum lambda G^T at q0
    offset = _kkt(system, q0, np.zeros(free.size), act)[: q0.size]
    basis = np.stack([_kkt(system, q0, full(e), act)[: q0.size] for e in np.eye(m)], axis=1)
    lam0 = np.linalg.lstsq(basis - offset[:, None], -offset, rcond=None)[0]
    scale = max(1.0, float(np.max(np.abs(_u_hat(system, q0)))))

    def fun(x: NDArray) -> NDArray:
        return _kkt(system, x[: q0.size].reshape(shape), full(x[q0.size :]), act) / scale

    sol = least_squares(fun, np.concatenate([q0.ravel(), lam0]), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    q = sol.x[: q0.size].reshape(shape)
    lam = full(sol.x[q0.size :])
    res = float(np.max(np.abs(fun(sol.x)))) * scale
    positive = bool(np.all(lam[free] > 0))
    ok = res <= tol * scale and positive
    why = "" if ok else f"KKT residual {res:.3g}" + ("" if positive else "; a multiplier <= 0")
    return Deadlock(q=q, active=act, multipliers=lam, residual=res, success=ok, message=why)


def classify_deadlock(
    system: System, dead: Deadlock, tolerances: Tolerances | None = None
) -> Equilibrium:
    """Stability of a refined deadlock (module docstring) as an :class:`Equilibrium`.

    ``eigenvalues`` are those of the filtered field on the tangent space of the active
    constraints (rigid motions removed without obstacles); ``constraints`` labels the
    active set and ``multipliers`` its KKT multipliers; ``attractive`` says the
    transverse motion ``h_dot = -gamma h^3`` attracts (``gamma > 0``, multipliers > 0).
    """
    q = dead.q
    grads, _ = _rows(system, q, dead.active)
    normals = np.stack([g.ravel() for g in grads], axis=1)
    modes = normals
    if _rigid_invariant(system, q, dead.active):
        modes = np.concatenate([normals, rigid_modes(q, system.law.invariance)], axis=1)
    basis = complement(modes)
    step = 1e-6 * max(1.0, float(np.max(np.abs(q))))
    cols = []
    for v in basis.T:
        dq = step * v.reshape(q.shape)
        cols.append(basis.T @ ((system.rhs(q + dq) - system.rhs(q - dq)).ravel() / (2 * step)))
    jac = np.array(cols).T if cols else np.zeros((0, 0))
    lam = np.linalg.eigvals(jac).astype(np.complex128) if jac.size else np.zeros(0, complex)
    lam = lam[np.argsort(-lam.real, kind="stable")]
    scale = max(1.0, float(np.max(np.abs(lam)))) if lam.size else 1.0
    ztol = 1e-6 * scale
    unstable = int(np.sum(lam.real > ztol))
    zero = int(np.sum(np.abs(lam.real) <= ztol))
    stability: Stability = "degenerate" if zero else "saddle" if unstable else "stable"
    assert system.safety is not None
    outcome = classify(system.formation, q, np.zeros_like(q), tolerances)
    f = system.formation
    r = np.linalg.norm(q[f.edges[:, 1]] - q[f.edges[:, 0]], axis=-1)
    return Equilibrium(
        q=q, distances=r, residual=dead.residual, stability=stability,
        unstable_directions=unstable, eigenvalues=lam, desired=outcome == "desired",
        outcome=outcome, zero_directions=zero,
        attractive=bool(
            system.safety.gamma > 0
            and np.all(dead.multipliers >= 0)
            and _per_pair_positive(system, dead)
        ),
        constraints=dead.active.labels(), multipliers=dead.multipliers,
    )  # fmt: skip


def _rigid_invariant(system: System, q: NDArray[np.float64], act: ActiveSet) -> bool:
    """Whether rigid motions are neutral at ``q``: no obstacles, or none within reach.

    The laws are invariant under translations and rotations; obstacles break that only
    where they act, through Khatib's repulsion (clearance below its ``influence``) or an
    active obstacle constraint.
    """
    if not system.obstacles:
        return True
    if act.obstacles:
        return False
    reach = system.law.obstacle_repulsion().repulsion.influence
    return bool(system.obstacle_clearances(q).min() > reach)


def _per_pair_positive(system: System, dead: Deadlock) -> bool:
    """Every active constraint has a positive multiplier (one of a pair's halves at least)."""
    lam = dead.multipliers
    if not _split(system):
        return bool(np.all(lam > 0))
    p = len(dead.active.pairs)
    halves = lam[: 2 * p].reshape(p, 2)
    return bool(np.all(halves.max(axis=1) > 0) and np.all(lam[2 * p :] > 0))
