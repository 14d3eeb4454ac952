"""Refining an end state to an equilibrium of the closed loop, with a root finder.

A simulation stops *near* an equilibrium (or chatters across a switching
surface near one); :func:`refine` solves ``u(q) = 0`` from there with
:func:`scipy.optimize.least_squares`.

* **Smooth pieces.** The angle-restricted law (eq. 11) is smooth between its
  switching surfaces ``sigma_s(q) = 0``: with the steps ``Upsilon`` of eq. (14)
  frozen at the end state's values the field is a smooth function, and its
  roots that keep the same steps are equilibria in the interior of that
  region. Smooth laws have no surfaces and this is the whole story.
* **Switching surfaces.** When the end state sits on surfaces (an implicit
  scheme lands there), or no root of a frozen piece is consistent with its
  own steps, :func:`refine` solves for a Filippov (sliding-mode)
  equilibrium: ``sigma_s(q) = 0`` for the surfaces in ``S`` and
  ``0 = u_w(q)`` for some weights ``w_s in [0, 1]`` (the convex
  combination of the two one-sided fields, eq. 11 with ``Upsilon``
  replaced by ``w_s``; ``formationlab.Law.control_with``).

Translation and rotation leave ``u`` unchanged (up to turning it), so the
roots form three-dimensional orbits. The solver works modulo those: three
gauge equations pin the centroid to the start's and the mean angular
displacement about it to zero. In space (positions ``(n, 3)``) the orbits have six
dimensions and the gauge six equations: the centroid, and the mean angular displacement
``sum_i p0_i x p_i`` about it, a vector. The chirality-restricted law's surfaces
``beta v + theta = 0`` (docs/three-d.md) are refined on as the plane's.

**Relative equilibria** (``moving=True``): shapes that the field moves as a
rigid body, ``u_i(q) = v + omega k x (q_i - q_bar)`` (a drift ``v`` of the
centroid and a rotation ``omega`` about it; the centre of the rotation is
``q_bar + (k x v) / omega``). The three numbers ``(v, omega)`` are unknowns
beside the shape (and the Filippov weights): ``2n + 3 (+ |S|)`` unknowns for
``2n`` field equations, ``3`` gauge equations (``+ |S|`` surfaces), the same
square system as for a static equilibrium, which is its case ``v = 0,
omega = 0``. Every surface ``sigma_s`` is a function of the shape only, so a
rigid motion keeps a state on the surfaces it lies on: the Filippov
combination is taken as for static equilibria. In space the rigid motion is a screw,
``u_i = v + w x (q_i - q_bar)`` (Chasles): six unknowns ``(v, w)`` beside the shape's
``3n``, for ``3n`` field equations and the six of the gauge, again a square system. Its
axis is ``w / |w|``, its rate ``omega = |w|``, its advance along the axis ``v . w / |w|``:
the helical motion that mismatched distances drive a formation in space into (Sun, Mou,
Anderson and Morse, IEEE Transactions on Automatic Control 62(8), 2017).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import combinations
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..controllers import Law
from ..formation.spec import Formation
from .relative import MAX_NEAR, all_subsets, attracts, rigid_field, rigid_guess

__all__ = ["Refined", "refine", "rigid_field"]


@dataclass(frozen=True, kw_only=True, eq=False)
class Refined:
    """An end state refined to an equilibrium.

    Attributes
    ----------
    q : ndarray, shape (n, d)
        The equilibrium (same centroid as the start).
    weights : ndarray, shape (s,)
        Step of each switching surface: 1 active, 0 inactive, in between on a
        surface (Filippov weight). Empty for a smooth law.
    surfaces : tuple of int
        0-based indices of the surfaces the equilibrium lies on (Filippov).
    residual : float
        Largest ``|u_i|`` of the field used (``u_w``), at ``q``.
    success : bool
        Whether the residual is below the tolerance and the steps are
        consistent with the signs of ``sigma(q)``.
    message : str
        What happened, in words.
    velocity : ndarray, shape (d,)
        Relative equilibria: velocity ``v`` of the centroid (zero for a static one).
    omega : float
        Relative equilibria: angular velocity about the centroid, rad/s (in space its
        size, ``>= 0``, about :attr:`axis`).
    axis : ndarray, shape (3,), or None
        In space, the unit direction of the rotation (zero when it does not turn); None in
        the plane, where the axis is ``k`` and ``omega`` is signed.
    """

    q: NDArray[np.float64]
    weights: NDArray[np.float64]
    surfaces: tuple[int, ...]
    residual: float
    success: bool
    message: str
    velocity: NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))
    omega: float = 0.0
    axis: NDArray[np.float64] | None = None

    @property
    def filippov(self) -> bool:
        """Whether the equilibrium lies on a switching surface."""
        return bool(self.surfaces)


def _scale(q: NDArray[np.float64]) -> float:
    return max(float(np.sqrt(np.mean(np.sum((q - q.mean(axis=0)) ** 2, axis=-1)))), 1e-3)


def _gauge(
    q: NDArray, c0: NDArray, p0: NDArray, scale: float, invariance: str = "rotation"
) -> NDArray:
    """Centroid of ``q`` minus ``c0`` (2) and the mean angular displacement from ``p0``
    (``invariance = "rotation"``) or the mean radial one (``"scale"``) (1).

    ``q`` has shape ``(..., n, 2)``; returns ``(..., 3)``. In space, ``(..., n, 3)``:
    the centroid (3) and the mean angular displacement ``sum_i p0_i x p_i / (n scale)``
    (3), or the radial one (1).
    """
    c = q.mean(axis=-2)
    p = q - c[..., None, :]
    if invariance == "scale":  # p0 . (p - p0): the size pinned to the start's
        third = np.sum(p0 * (p - p0), axis=(-2, -1)) / (q.shape[-2] * scale)
    elif q.shape[-1] == 3:
        turn = np.sum(np.cross(p0, p), axis=-2) / (q.shape[-2] * scale)
        return np.concatenate([c - c0, turn], axis=-1)
    else:
        third = np.sum(p0[:, 0] * p[..., 1] - p0[:, 1] * p[..., 0], axis=-1) / (q.shape[-2] * scale)
    return np.concatenate([c - c0, third[..., None]], axis=-1)


def _field(law: Law, formation: Formation, weights: NDArray) -> Callable[[NDArray], NDArray]:
    """``q (..., n, d) -> u (..., n, d)`` with the steps frozen at ``weights``."""
    if law.smooth or weights.size == 0:
        return lambda q: law.control(formation, q)
    return lambda q: law.control_with(
        formation, q, np.broadcast_to(weights, (*q.shape[:-2], weights.size))
    )


def _solve(fun: Callable[[NDArray], NDArray], x0: NDArray, **kwargs: object) -> NDArray:
    """``least_squares`` on a batch-aware ``fun`` (``(..., N) -> (..., M)``).

    Its Jacobian is taken by central differences in one batched call (all
    ``2N`` perturbed points at once), much cheaper than column by column.
    """

    def jac(x: NDArray) -> NDArray:
        h = 1e-7 * max(1.0, float(np.max(np.abs(x))))
        e = np.eye(x.size) * h
        vals = fun(np.concatenate([x + e, x - e]))
        return ((vals[: x.size] - vals[x.size :]) / (2 * h)).T

    sol = least_squares(
        fun, x0, jac=jac, xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=100, **kwargs
    )
    return sol.x


def refine(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    *,
    tol: float = 1e-9,
    surface_tol: float = 1e-7,
    max_surfaces: int = 2,
    band: float | None = None,
    moving: bool = False,
) -> Refined:
    """Refine ``q0`` (shape ``(n, d)``) to an equilibrium of ``law`` on ``formation``.

    Parameters
    ----------
    tol : float
        Largest ``|u_i|`` accepted at the root, relative to the scale of the
        field at ``q0`` (at least 1).
    surface_tol : float
        ``|sigma_s|`` below which a state counts as on surface ``s``, relative
        to the size of the configuration squared (``sigma`` is an area plus
        ``theta``).
    max_surfaces : int
        Most surfaces a Filippov equilibrium is searched on at once.
    band : float
        Surfaces with ``|sigma_s(q0)|`` below ``band`` times the size of the
        configuration squared are those ``q0`` sits on: a Filippov equilibrium
        on exactly that set is tried before anything else; then the frozen
        smooth piece; then the nearest surfaces one, two, ... at a time.
        Default 1e-2; 5e-2 with ``moving``: the end state of a formation that
        drifts while explicit Euler chatters on several surfaces at once lies
        farther from them (``docs/drifting.md``).
    moving : bool
        Solve for a relative equilibrium: the shape and its rigid motion ``(v, omega)``
        together (module docstring); the residual is then ``max_i |u_i - v - omega k x
        (q_i - q_bar)|`` (in space ``max_i |u_i - v - w x (q_i - q_bar)|``).

    Returns
    -------
    Refined
        ``success`` says whether an equilibrium was found; ``message`` why not.
    """
    q0 = np.asarray(q0, dtype=float)
    band = (5e-2 if moving else 1e-2) if band is None else band
    scale = _scale(q0)
    sigma0 = np.asarray(law.switching(formation, q0), dtype=float)
    w0 = (sigma0 >= 0).astype(float)
    u_scale = max(1.0, float(np.max(np.abs(law.control(formation, q0)))))
    atol = tol * u_scale
    stol = surface_tol * scale**2 + surface_tol

    m0 = None
    if moving:  # the rigid part of the field halfway across the surfaces q0 is near
        w_half = np.where(np.abs(sigma0) <= band * scale**2, 0.5, w0)
        m0 = rigid_guess(_field(law, formation, w_half)(q0), q0)

    def try_filippov(subset: tuple[int, ...]) -> Refined:
        q, w, m = _solve_filippov(formation, law, q0, w0, subset, scale, m0)
        res_f = _residual(formation, law, q, w, m)
        sig = np.asarray(law.switching(formation, q), dtype=float)
        on = np.zeros(sig.size, bool)
        on[list(subset)] = True
        ok = (
            res_f <= atol
            and bool(np.all(np.abs(sig[on]) <= stol))
            and bool(np.all((sig[~on] >= 0) == (w[~on] > 0.5)))
            and bool(np.all(np.abs(sig[~on]) > stol))
            and bool(np.all((w[on] > 0) & (w[on] < 1)))
        )
        return Refined(
            q=q,
            weights=w,
            surfaces=subset,
            residual=res_f,
            success=ok,
            message="Filippov equilibrium on a switching surface" if ok else "",
            **_motion(m, q0.shape[-1]),
        )

    smooth_law = law.smooth or sigma0.size == 0
    subsets = [] if smooth_law else _subsets(sigma0, max_surfaces, band * scale**2)
    # a state that sits on surfaces (an implicit scheme's end, or a continuation
    # step) is first refined on them: the frozen field of one side could lead far away
    if moving and subsets and 0 < len(subsets[0]) <= MAX_NEAR:
        # near surfaces of a moving formation: several relative equilibria slide on
        # subsets of them; the one the run was at attracts on each of its surfaces,
        # and of those it is the nearest to q0
        found = [r for r in map(try_filippov, all_subsets(subsets[0])) if r.success]
        held = [r for r in found if attracts(formation, law, r.q, r.weights, r.surfaces)] or found
        if held:
            return min(held, key=lambda r: float(np.sum((r.q - q0) ** 2)))
    if subsets and np.all(np.abs(sigma0[list(subsets[0])]) <= band * scale**2):
        first = try_filippov(subsets[0])
        if first.success:
            return first
        subsets = subsets[1:]
    smooth, m = _solve_piece(formation, law, q0, w0, scale, m0)
    res = _residual(formation, law, smooth, w0, m)
    sig = np.asarray(law.switching(formation, smooth), dtype=float)
    consistent = bool(np.all((sig >= 0) == (w0 > 0.5))) and bool(np.all(np.abs(sig) > stol))
    if res <= atol and consistent:
        return Refined(
            q=smooth,
            weights=w0,
            surfaces=(),
            residual=res,
            success=True,
            message="equilibrium in the interior of a smooth region",
            **_motion(m, q0.shape[-1]),
        )
    why = (
        f"the root finder stopped at largest |u_i| = {res:.3g}"
        if res > atol
        else "the root of the frozen field lies across a switching surface"
    )
    best = Refined(
        q=smooth,
        weights=w0,
        surfaces=(),
        residual=res,
        success=False,
        message=why,
        **_motion(m, q0.shape[-1]),
    )
    for subset in subsets:
        cand = try_filippov(subset)
        if cand.success:
            return cand
        if cand.residual < best.residual:
            best = Refined(
                q=cand.q,
                weights=cand.weights,
                surfaces=subset,
                residual=cand.residual,
                success=False,
                message=why + "; no Filippov equilibrium on the nearest surfaces either",
                velocity=cand.velocity,
                omega=cand.omega,
                axis=cand.axis,
            )
    return best


def _motion(m: NDArray | None, dim: int = 2) -> dict[str, Any]:
    """:class:`Refined`'s motion fields from the solved rigid motion ``m`` (None: at rest)."""
    if dim == 2:
        return {} if m is None else {"velocity": np.array(m[:2], dtype=float), "omega": float(m[2])}
    if m is None:
        return {"velocity": np.zeros(3), "axis": np.zeros(3)}
    w = np.array(m[3:], dtype=float)
    omega = float(np.linalg.norm(w))
    axis = w / omega if omega > 0 else np.zeros(3)
    return {"velocity": np.array(m[:3], dtype=float), "omega": omega, "axis": axis}


def _residual(
    formation: Formation, law: Law, q: NDArray, w: NDArray, m: NDArray | None = None
) -> float:
    u = _field(law, formation, w)(q)
    if m is not None:
        u = u - rigid_field(q, m)
    return float(np.max(np.linalg.norm(u, axis=-1)))


def _solve_piece(
    formation: Formation, law: Law, q0: NDArray, w: NDArray, scale: float, m0: NDArray | None
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Root of the field with frozen steps ``w``, modulo translation and rotation.

    With ``m0``, of the field minus a rigid motion solved for from ``m0``.
    """
    n, d = q0.shape
    size = q0.size
    c0 = q0.mean(axis=0)
    p0 = q0 - c0
    field = _field(law, formation, w)

    def fun(x: NDArray) -> NDArray:
        q = x[..., :size].reshape(*x.shape[:-1], n, d)
        u = field(q)
        if m0 is not None:
            u = u - rigid_field(q, x[..., size:])
        return np.concatenate(
            [u.reshape(*x.shape[:-1], size), _gauge(q, c0, p0, scale, law.invariance)], axis=-1
        )

    x0 = q0.ravel() if m0 is None else np.concatenate([q0.ravel(), m0])
    x = _solve(fun, x0, method="lm")
    return x[:size].reshape(n, d), (None if m0 is None else x[size:])


def _solve_filippov(
    formation: Formation,
    law: Law,
    q0: NDArray,
    w0: NDArray,
    subset: tuple[int, ...],
    scale: float,
    m0: NDArray | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """Solve ``u_w(q) = 0``, ``sigma_S(q) = 0`` for ``q`` and ``w_S in [0, 1]``.

    With ``m0``: ``u_w(q) = v + omega k x (q - q_bar)``, with ``(v, omega)`` unknowns too.
    """
    n, d = q0.shape
    size = q0.size
    c0 = q0.mean(axis=0)
    p0 = q0 - c0
    idx = list(subset)
    k = size + len(idx)

    def unpack(x: NDArray) -> tuple[NDArray, NDArray]:
        w = np.broadcast_to(w0, (*x.shape[:-1], w0.size)).copy()
        w[..., idx] = x[..., size:k]
        return x[..., :size].reshape(*x.shape[:-1], n, d), w

    def fun(x: NDArray) -> NDArray:
        q, w = unpack(x)
        u = law.control_with(formation, q, w)
        if m0 is not None:
            u = u - rigid_field(q, x[..., k:])
        sig = np.asarray(law.switching(formation, q))[..., idx] / scale**2
        parts = [u.reshape(*x.shape[:-1], size), sig, _gauge(q, c0, p0, scale, law.invariance)]
        return np.concatenate(parts, axis=-1)

    extra = np.zeros(0) if m0 is None else m0
    free = np.full(extra.size, np.inf)
    x0 = np.concatenate([q0.ravel(), np.full(len(idx), 0.5), extra])
    lo = np.concatenate([np.full(size, -np.inf), np.zeros(len(idx)), -free])
    hi = np.concatenate([np.full(size, np.inf), np.ones(len(idx)), free])
    x = _solve(fun, x0, bounds=(lo, hi), method="trf")
    q, w = unpack(x)
    return q, w, (None if m0 is None else x[k:])


def _subsets(sigma0: NDArray, max_surfaces: int, band: float) -> list[tuple[int, ...]]:
    """Sets of surfaces to try: those ``q0`` sits on (``|sigma| <= band``), then the nearest."""
    order = np.argsort(np.abs(sigma0))
    near = tuple(sorted(int(s) for s in np.flatnonzero(np.abs(sigma0) <= band)))
    out = [near] if near else []
    for size in range(1, min(max_surfaces, sigma0.size) + 1):
        for subset in combinations(order[: max_surfaces + 1].tolist(), size):
            key = tuple(sorted(subset))
            if key not in out:
                out.append(key)
    return out
