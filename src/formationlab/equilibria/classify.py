"""Classifying an equilibrium by the eigenvalues of the linearised closed loop.

For ``q_dot = u(q)`` linearised at an equilibrium, with the translation and
rotation modes removed (:mod:`formationlab.equilibria.jacobian`):

``stable``
    every remaining eigenvalue has a negative real part: nearby states return;
``saddle``
    some eigenvalues have positive real parts (``unstable_directions`` of them)
    and none is zero: almost every nearby state leaves, the equilibrium only
    delays a run that passes close to it;
``degenerate``
    some eigenvalue is zero to the tolerance: the linearisation does not decide
    (a continuum of equilibria, e.g. the flex of a non-rigid graph);
``filippov``
    the equilibrium lies on a switching surface of the angle-restricted law
    (eq. 14), where the field is discontinuous and the Jacobian does not exist.
    It is an equilibrium of the Filippov convex combination. Its eigenvalues
    are those of the sliding dynamics on the surface (the field with the
    equivalent-control weight, the surface normal removed as well), and
    ``attractive`` says whether both one-sided fields point into the surface.

**Relative equilibria** (a shape the field moves rigidly, ``u = v + omega k x
(q - q_bar)``: ``drifting`` or ``rotating``) are classified the same way in the
co-moving frame, where they are at rest: the Jacobian of ``u(q) - omega k x q``
(the translation ``v`` is constant), whose rigid-motion modes span an invariant
subspace (``J T = k x T`` maps translations and the rotation to translations),
removed as for static equilibria.

**In space** (positions ``(n, 3)``) the same classes, with the six rigid-motion modes
(three translations, three rotations; five on a line) removed
(:func:`~formationlab.equilibria.jacobian.rigid_modes_in_space`) and the chirality
restriction's surfaces in the place of the plane's; the outcome is judged by chirality
(``mirror``: every restricted tetrahedron reversed). Relative equilibria are refined in
the plane only (:func:`~formationlab.equilibria.refine`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..formation.spec import Formation
from ..outcomes.analysis import Tolerances, classify
from ..outcomes.rigid_motion import RigidMotion, field_motion
from .jacobian import jacobian, reduced_eigenvalues
from .refine import Refined
from .relative import rigid_field

__all__ = ["Equilibrium", "Stability", "classify_equilibrium", "restriction_labels"]

Stability = Literal["stable", "saddle", "degenerate", "filippov"]


@dataclass(frozen=True, kw_only=True, eq=False)
class Equilibrium:
    """A classified equilibrium of a law on a formation.

    Attributes
    ----------
    q : ndarray, shape (n, d)
        One representative (any translate, rotation or allowed relabelling is
        the same equilibrium).
    distances : ndarray, shape (m,)
        ``r_ij`` per edge, in the order of ``formation.edges``.
    residual : float
        Largest ``|u_i|`` at ``q``.
    stability : {"stable", "saddle", "degenerate", "filippov"}
    unstable_directions : int
        Eigenvalues with a positive real part (of the sliding dynamics for a
        Filippov equilibrium).
    eigenvalues : ndarray of complex, shape (2n - 3,) or (2n - 3 - r,)
        Decreasing real part; rigid-motion modes (and surface normals) removed.
    desired : bool
        Whether ``q`` is the desired formation (:func:`formationlab.classify`).
    outcome : str
        ``"desired"``, ``"mirror"`` (distances met, every restricted triple
        reversed) or ``"incorrect"``: what :func:`formationlab.classify` calls a
        run that stops here.
    zero_directions : int
        Eigenvalues with a zero real part to the tolerance (a continuum of
        equilibria, or a bifurcation point): why a state is ``degenerate``.
    active : tuple of str
        Labels (1-based, e.g. ``"alpha_123"``) of the restrictions whose step is on.
    surfaces : tuple of str
        Labels of the switching surfaces ``q`` lies on (Filippov equilibria only).
    weights : ndarray, shape (s,)
        Step of each surface (Filippov weight on the surfaces ``q`` lies on).
    attractive : bool or None
        Filippov equilibria: whether the surfaces attract from both sides
        (a sliding mode exists there). None otherwise.
    velocity : ndarray, shape (d,)
        Relative equilibria: velocity of the centroid, m/s (in the frame of ``q``).
    omega : float
        Relative equilibria: angular velocity, rad/s (counter-clockwise positive).
        (a sliding mode exists there); deadlocks of a safety filter: whether the
        active barriers attract (:mod:`formationlab.equilibria.constrained`). None otherwise.
    constraints : tuple of str
        Deadlocks of a safety filter: the active barrier constraints (``"pair 1-2"``,
        ``"robot 3 - obstacle 1"``); empty otherwise.
    multipliers : ndarray
        Their KKT multipliers (all positive at a deadlock).
    """

    q: NDArray[np.float64]
    distances: NDArray[np.float64]
    residual: float
    stability: Stability
    unstable_directions: int
    eigenvalues: NDArray[np.complex128]
    desired: bool
    outcome: str = "incorrect"
    zero_directions: int = 0
    active: tuple[str, ...] = ()
    surfaces: tuple[str, ...] = ()
    weights: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    attractive: bool | None = None
    velocity: NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))
    omega: float = 0.0
    axis: NDArray[np.float64] | None = None

    @property
    def moving(self) -> bool:
        """Whether this is a relative equilibrium (outcome ``drifting`` or ``rotating``)."""
        return self.outcome in ("drifting", "rotating")

    @property
    def speed(self) -> float:
        """Largest robot speed of the rigid motion, m/s (0 for a static equilibrium)."""
        return float(self.motion.speed)

    @property
    def centre(self) -> NDArray[np.float64] | None:
        """Centre of the rotation of a ``rotating`` equilibrium (None otherwise)."""
        if self.outcome != "rotating":
            return None
        return np.asarray(self.motion.centre)

    @property
    def motion(self) -> RigidMotion:
        """The rigid motion of the equilibrium (:func:`~formationlab.outcomes.field_motion`)."""
        space = self.q.shape[-1] == 3
        axis = (np.zeros(3) if self.axis is None else self.axis) if space else None
        return field_motion(self.q, self.velocity, self.omega, axis)

    constraints: tuple[str, ...] = ()
    multipliers: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    @property
    def growth_rate(self) -> float:
        """Largest real part of the eigenvalues, 1/s (> 0: a perturbation grows)."""
        return float(self.eigenvalues.real.max()) if self.eigenvalues.size else float("nan")


def restriction_labels(formation: Formation) -> list[str]:
    """1-based label of each switching surface, e.g. ``"alpha_123"`` (its first triple)."""
    return formation.surface_labels


def _zero_tol(lam: NDArray[np.complex128]) -> float:
    return 1e-6 * max(1.0, float(np.max(np.abs(lam)))) if lam.size else 1e-6


def _sliding_field(
    formation: Formation, law: Law, weights: NDArray, on: list[int]
) -> tuple[Callable[[NDArray], NDArray], Callable[[NDArray], NDArray]]:
    """The sliding field ``u_{w*(q)}(q)`` on the surfaces ``on``: ``grad sigma . u = 0``.

    ``u_w`` is affine in ``w``, so ``w*`` solves a small linear system at every ``q``.
    """

    def grad_sigma(q: NDArray) -> NDArray:  # (..., k, n, d), central differences
        h = 1e-7 * max(1.0, float(np.max(np.abs(q))))
        out = np.zeros((*q.shape[:-2], len(on), *q.shape[-2:]))
        for a in range(q.shape[-2]):
            for b in range(q.shape[-1]):
                e = np.zeros(q.shape[-2:])
                e[a, b] = h
                ds = (law.switching(formation, q + e) - law.switching(formation, q - e)) / (2 * h)
                out[..., :, a, b] = ds[..., on]
        return out

    def field(q: NDArray) -> NDArray:
        q = np.asarray(q, dtype=float)
        batch = q.shape[:-2]
        w = np.broadcast_to(weights, (*batch, weights.size)).copy()
        w[..., on] = 0.0
        base = law.control_with(formation, q, w)
        cols = []
        for s in on:
            ws = w.copy()
            ws[..., s] = 1.0
            cols.append(law.control_with(formation, q, ws) - base)
        d = np.stack(cols, axis=-3)  # (..., k, n, d)
        g = grad_sigma(q)
        a = np.einsum("...tnd,...snd->...ts", g, d)
        b = -np.einsum("...tnd,...nd->...t", g, base)
        wstar = np.linalg.solve(a, b[..., None])[..., 0]
        return base + np.einsum("...s,...snd->...nd", wstar, d)

    return field, grad_sigma


def classify_equilibrium(
    formation: Formation,
    law: Law,
    refined: Refined,
    tolerances: Tolerances | None = None,
) -> Equilibrium:
    """Classify a refined equilibrium (see the module docstring for the classes)."""
    q = refined.q
    w = refined.weights
    labels = restriction_labels(formation) if w.size else []
    sigma = np.asarray(law.switching(formation, q), dtype=float)
    active = tuple(lab for lab, s in zip(labels, sigma, strict=True) if s >= 0)
    on = list(refined.surfaces)
    attractive: bool | None = None
    omega = float(refined.omega)
    # the co-moving frame of a rotating equilibrium turns with it: d/dq of -omega k x q
    # (in space of -omega a x q)
    space = q.shape[-1] == 3
    a = (np.zeros(3) if refined.axis is None else refined.axis) if space else np.array([0, 0, 1.0])
    wx, wy, wz = omega * a  # the angular velocity
    spin = np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])  # its cross product
    turn = np.kron(np.eye(formation.n), spin if space else spin[:2, :2])
    if on:
        sliding, grad_sigma = _sliding_field(formation, law, w, on)
        jac = jacobian(sliding, q) - turn
        normals = grad_sigma(q).reshape(len(on), -1).T  # (dn, k)
        lam = reduced_eigenvalues(jac, q, extra=normals, invariance=law.invariance)
        wk = w.copy()
        wk[on] = 0.0
        below = law.control_with(formation, q, wk)
        wk[on] = 1.0
        above = law.control_with(formation, q, wk)
        g = normals.T
        attractive = bool(np.all(g @ below.ravel() > 0) and np.all(g @ above.ravel() < 0))
        active = tuple(lab for lab in active if lab not in {labels[s] for s in on})
    else:
        if w.size:
            ww = w

            def field(x: NDArray) -> NDArray:
                return law.control_with(formation, x, np.broadcast_to(ww, (*x.shape[:-2], ww.size)))
        else:

            def field(x: NDArray) -> NDArray:
                return law.control(formation, x)

        lam = reduced_eigenvalues(jacobian(field, q) - turn, q, invariance=law.invariance)
    ztol = _zero_tol(lam)
    lam = np.where(np.abs(lam.imag) <= ztol, lam.real, lam)  # round-off pairs of a real double
    unstable = int(np.sum(lam.real > ztol))
    if on:
        stability: Stability = "filippov"
    elif np.any(np.abs(lam.real) <= ztol):
        stability = "degenerate"
    elif unstable:
        stability = "saddle"
    else:
        stability = "stable"
    motion = field_motion(q, refined.velocity, omega, a if space else None)
    u = rigid_field(q, np.concatenate([refined.velocity, omega * a if space else [omega]]))
    outcome = classify(formation, q, u, tolerances, motion=motion)
    r = np.linalg.norm(q[formation.edges[:, 1]] - q[formation.edges[:, 0]], axis=-1)
    return Equilibrium(
        q=q,
        distances=r,
        residual=refined.residual,
        stability=stability,
        unstable_directions=unstable,
        eigenvalues=lam,
        desired=outcome == "desired",
        outcome=outcome,
        zero_directions=int(np.sum(np.abs(lam.real) <= ztol)),
        active=active,
        surfaces=tuple(labels[s] for s in on),
        weights=w,
        attractive=attractive,
        velocity=np.asarray(refined.velocity, dtype=float),
        omega=omega,
        axis=a if space else None,
    )
