"""A formation on the move: a reference velocity for every robot, a leader, or motion parameters.

Three ways to make a formation march, each a frozen dataclass whose
``command(formation, p, u, t)`` adds to (or replaces) the law's control ``u``
``(..., n, d)`` at the law's points ``p`` and time ``t``:

* :class:`Marching` without a leader: every robot is given the reference
  velocity ``v_ref(t)``, ``u_i + v_ref(t)``. A law whose controls sum to zero
  (every pairwise law: the distance law, eq. 8) keeps the centroid moving at
  exactly ``v_ref``, and the shape converges as without marching (the relative
  motion does not see ``v_ref``).
* :class:`Marching` with a ``leader``: only that robot knows ``v_ref`` and
  moves with it alone; the others follow through the law. Several leaders
  (``leader = (1, 4)``) all move with ``v_ref``: the translational maneuver of a
  bearing formation, whose two or more leaders fix its position and scale (Zhao and
  Zelazo, IEEE Transactions on Control of Network Systems 4(3), 2017; docs/bearing.md).
  In steady state every robot moves at ``v_ref``, the followers' laws pulling with
  ``u_i = v_ref``: the shape is off by an amount of order ``|v_ref| / k_c``. Several
  leaders may also be given a velocity each (``velocity`` of shape ``(l, 2)``, one row
  per leader in the order of ``leader``): leaders that move apart or together change the
  scale of a bearing formation, the scaling maneuver of the same paper, and the
  followers track the formation the leaders define
  (:func:`formationlab.controllers.bearing.leader_target`).
* :class:`MotionParameters` (Garcia de Marina, Jayawardhana and Cao,
  "Distributed rotational and translational maneuvering of rigid formations
  and their applications", IEEE Transactions on Robotics 32(3), 2016): one
  pair ``(mu_k, mu_tilde_k)`` per edge ``k = (i, j)``, ``z_k = p_i - p_j``;
  robot ``i`` adds ``mu_k z_k`` and robot ``j`` adds ``mu_tilde_k z_k``. At the
  desired shape the added velocities are a rigid motion: translation ``v`` and
  rotation ``omega`` about the centroid, both in the frame of the shape the
  parameters were designed on (:meth:`MotionParameters.design`), so they turn
  with the formation.

In space (a formation of ``dim = 3``) a reference velocity and leaders are the same
formulas with ``v_ref = [vx, vy, vz]`` (:meth:`Marching.check` holds it to the
formation's dimension); motion parameters are designed in the plane only (the scenario
refuses them in space). A time-dependent ``v_ref`` reaches the closed loop through
``System.rhs(x, t)`` (docs/architecture.md). Metrics: :func:`centroid_velocity` and
:func:`heading_spread`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._jit import formula
from ..errors import FormationError, ParameterError
from ..formation.geometry import perp
from ..formation.spec import Formation

__all__ = [
    "March",
    "Marching",
    "MotionParameters",
    "centroid_velocity",
    "heading_spread",
    "marched",
    "shape_realization",
]

Velocity = Callable[[float], ArrayLike]


def _vector(value: Any, what: str, rows: int = 0) -> NDArray[np.float64]:
    """``value`` as a finite ``[vx, vy]`` (or ``[vx, vy, vz]`` in space), or (``rows`` > 1)
    as ``rows`` of them."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = np.full(0, np.nan)
    shapes = [(d,) for d in (2, 3)] + ([(rows, d) for d in (2, 3)] if rows > 1 else [])
    if v.shape not in shapes or not np.all(np.isfinite(v)):
        each = f", or one per leader ({rows} rows)" if rows > 1 else ""
        raise ParameterError(
            f"{what} must be a finite [vx, vy] (in space [vx, vy, vz]) in m/s{each}, got {value!r}",
            key="velocity",
        )
    v.setflags(write=False)
    return v


@dataclass(frozen=True, kw_only=True)
class Marching:
    """A reference velocity for every robot, or for a leader only (module docstring).

    Parameters
    ----------
    velocity : array_like of shape (d,) or (l, d), or callable
        ``v_ref`` in m/s, constant, or a function of the time ``t`` (seconds)
        returning ``[vx, vy]`` (``[vx, vy, vz]`` for a formation in space: ``d`` is the
        formation's dimension, checked by :meth:`check`); with ``l >= 2`` leaders, one row
        per leader may be given instead (in the order of ``leader``): each leader moves
        with its own.
    leader : int or sequence of int, optional
        The 1-based robot (or robots) that alone are given ``v_ref`` (and ignore the
        law); None: every robot is given it, on top of its law.
    """

    velocity: ArrayLike | Velocity
    leader: int | tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.leader is not None and not isinstance(self.leader, int | np.integer):
            object.__setattr__(self, "leader", tuple(self.leader))  # several leaders
        for r in self.leaders:
            if isinstance(r, bool) or not isinstance(r, int | np.integer) or r < 1:
                raise ParameterError(
                    f"leader must be a robot number (1-based) or a list of them, got "
                    f"{self.leader!r}", key="leader",
                )  # fmt: skip
        if len(set(self.leaders)) != len(self.leaders) or (
            self.leader is not None and not self.leaders
        ):
            raise ParameterError(
                f"leader lists each robot once, and at least one, got {list(self.leaders)}",
                key="leader",
            )
        rows = len(self.leaders)
        if not callable(self.velocity):
            object.__setattr__(self, "velocity", _vector(self.velocity, "velocity", rows))
        else:
            _vector(self.velocity(0.0), "velocity(0)", rows)

    @property
    def leaders(self) -> tuple[int, ...]:
        """The leaders' 1-based numbers (empty: every robot is given ``v_ref``)."""
        if self.leader is None:
            return ()
        return (self.leader,) if isinstance(self.leader, int | np.integer) else self.leader

    @property
    def time_dependent(self) -> bool:
        """Whether ``v_ref`` is a function of time."""
        return callable(self.velocity)

    @property
    def per_leader(self) -> bool:
        """Whether each leader is given a velocity of its own (``velocity`` ``(l, d)``)."""
        return np.ndim(self.reference(0.0)) == 2

    def reference(self, t: float) -> NDArray[np.float64]:
        """``v_ref(t)``, shape ``(d,)``, or ``(l, d)``: each leader's."""
        if callable(self.velocity):
            return np.asarray(self.velocity(float(t)), dtype=float)
        return np.asarray(self.velocity)

    def check(self, formation: Formation) -> None:
        """The leaders are robots of the formation, and ``v_ref`` has its dimension."""
        d = np.shape(self.reference(0.0))[-1]
        if d != formation.dim:
            given = "[vx, vy, vz]" if d == 3 else "[vx, vy]"
            wanted = "[vx, vy, vz] (space)" if formation.dim == 3 else "[vx, vy] (the plane)"
            raise ParameterError(
                f"velocity {given} has {d} components and the formation is {formation.dim}-D: "
                f"give {wanted}",
                key="velocity",
            )
        for r in self.leaders:
            if r > formation.n:
                raise ParameterError(
                    f"leader {r} is not a robot: there are {formation.n} robots (1 to "
                    f"{formation.n})",
                    key="leader",
                )

    def command(
        self,
        formation: Formation,
        p: NDArray[np.float64],
        u: NDArray[np.float64],
        t: float,
        gain: float = 1.0,
    ) -> NDArray[np.float64]:
        """The controls ``(..., n, d)`` with ``gain v_ref(t)`` added (or the leaders' replaced,
        each by its own row when :attr:`per_leader`).

        ``gain`` is the robot model's ``velocity_gain`` (the command that holds a
        robot at a velocity: ``k_d`` for double integrators, 1 otherwise).
        """
        if self.leader is None:
            return marched(u, gain, self.reference(t))
        out = np.array(u, dtype=float, copy=True)
        out[..., np.array(self.leaders) - 1, :] = gain * self.reference(t)
        return out


@formula
def marched(u, gain, v):
    """A command with its marching term: ``u + gain v``, ``v`` the reference velocity or a
    robot's sum of motion-parameter terms ``sum_k a_ik z_k`` (``gain``: the model's
    ``velocity_gain``). The numpy commands above and the compiled stage
    (:mod:`.stage`) call it."""
    return u + gain * v


def shape_realization(formation: Formation) -> NDArray[np.float64]:
    """A shape ``(n, 2)`` with the formation's distances: its template, else from the distances.

    Without a template every pair's distance is needed (a complete graph): the
    classical multidimensional scaling of the distance matrix.
    """
    if formation.template is not None:
        return np.asarray(formation.template, dtype=float)
    d = np.array(formation.distance_matrix, dtype=float)
    np.fill_diagonal(d, 0.0)
    if not np.all(np.isfinite(d)):
        raise FormationError(
            "motion parameters need the desired shape: give the formation a template "
            "(formation.template), or the distance of every pair"
        )
    n = formation.n
    centre = np.eye(n) - 1.0 / n
    gram = -0.5 * centre @ (d * d) @ centre
    w, vecs = np.linalg.eigh(gram)
    top = np.argsort(w)[::-1][:2]
    if np.any(w[top] < 0) or (n > 2 and w[np.argsort(w)[::-1][2]] > 1e-9 * max(w[top[0]], 1)):
        raise FormationError("the desired distances are not those of a planar shape")
    return vecs[:, top] * np.sqrt(np.maximum(w[top], 0.0))


@dataclass(frozen=True, kw_only=True)
class MotionParameters:
    """Garcia de Marina et al.'s motion parameters (module docstring).

    Parameters
    ----------
    mu, mu_tilde : array_like, shape (m,)
        Per edge of ``formation.edges`` (in that order): the gain of ``z_k`` for
        its first robot ``i`` and for its second robot ``j``.
    """

    mu: NDArray[np.float64]
    mu_tilde: NDArray[np.float64]

    #: the parameters are constant
    time_dependent = False

    def __post_init__(self) -> None:
        for name in ("mu", "mu_tilde"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.ndim != 1 or not np.all(np.isfinite(v)):
                raise ParameterError(f"{name} must be finite numbers, one per edge", key=name)
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    @classmethod
    def design(
        cls,
        formation: Formation,
        velocity: ArrayLike,
        angular_velocity: float = 0.0,
        shape: ArrayLike | None = None,
    ) -> MotionParameters:
        """The parameters that move ``shape`` with ``velocity`` and ``angular_velocity``.

        Solves, for each robot ``i``, ``sum_k a_ik z*_k = v + omega J (p*_i - c*)``
        at the shape ``p*``
        (:func:`shape_realization` by default), least-norm per robot.

        Raises
        ------
        FormationError
            A robot whose edges cannot produce its velocity (fewer than two edges in
            different directions when it must move across them).
        """
        v = _vector(velocity, "velocity")
        w = float(angular_velocity)
        if not np.isfinite(w):
            raise ParameterError(f"angular_velocity must be finite, got {angular_velocity!r}")
        p = shape_realization(formation) if shape is None else np.asarray(shape, dtype=float)
        target = v + w * perp(p - p.mean(axis=0))  # rigid motion at the shape
        edges = formation.edges
        z = p[edges[:, 0]] - p[edges[:, 1]]
        mu, mu_t = np.zeros(len(edges)), np.zeros(len(edges))
        for i in range(formation.n):
            first, second = np.flatnonzero(edges[:, 0] == i), np.flatnonzero(edges[:, 1] == i)
            cols = np.concatenate([z[first], z[second]]).T  # (2, deg)
            sol = np.linalg.lstsq(cols, target[i], rcond=None)[0]
            miss = float(np.linalg.norm(cols @ sol - target[i]))
            if miss > 1e-9 * max(1.0, float(np.linalg.norm(target[i]))):
                raise FormationError(
                    f"robot {i + 1} cannot be given its velocity by motion parameters: its "
                    "edges do not span the plane; add an edge to a robot in another direction"
                )
            mu[first], mu_t[second] = sol[: first.size], sol[first.size :]
        return cls(mu=mu, mu_tilde=mu_t)

    def check(self, formation: Formation) -> None:
        """One parameter pair per edge."""
        if self.mu.shape != (len(formation.edges),) or self.mu_tilde.shape != self.mu.shape:
            raise ParameterError(
                f"motion parameters need one (mu, mu_tilde) per edge: {len(formation.edges)} "
                f"edges, got {self.mu.shape[0]} and {self.mu_tilde.shape[0]}"
            )

    def command(
        self,
        formation: Formation,
        p: NDArray[np.float64],
        u: NDArray[np.float64],
        t: float,
        gain: float = 1.0,
    ) -> NDArray[np.float64]:
        """``u_i + gain sum_k a_ik z_k``, ``(..., n, 2)``; ``a_ik`` is ``mu_k`` or ``mu_tilde_k``.

        ``gain``: the robot model's ``velocity_gain`` (as for :meth:`Marching.command`).
        """
        edges = formation.edges
        z = p[..., edges[:, 0], :] - p[..., edges[:, 1], :]
        return marched(u, gain, self.incidence(formation) @ z)

    def incidence(self, formation: Formation) -> NDArray[np.float64]:
        """The matrix ``(n, m)`` of the ``a_ik``."""
        edges, m = formation.edges, len(formation.edges)
        a = np.zeros((formation.n, m))
        a[edges[:, 0], np.arange(m)] = self.mu
        a[edges[:, 1], np.arange(m)] = self.mu_tilde
        return a


#: Either way of marching.
March = Marching | MotionParameters


def centroid_velocity(t: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Centroid velocity by central differences of saved positions ``(T, n, 2)``; ``(T, 2)``."""
    c = np.mean(q, axis=-2)
    return np.gradient(c, t, axis=0)


def heading_spread(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Largest angle between a heading and the headings' circular mean; ``(..., n) -> (...)``."""
    mean = np.angle(np.mean(np.exp(1j * theta), axis=-1))
    return np.max(np.abs(np.angle(np.exp(1j * (theta - mean[..., None])))), axis=-1)
