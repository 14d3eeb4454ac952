"""What a robot of an environment observes and may do: spaces and observations, batched.

The one definition of an agent's observation and action (module docstring of
:mod:`.pettingzoo`), shared by the PettingZoo environment (one formation) and the
vectorised one (:mod:`.vector`, ``B`` formations): :func:`observation_space` and
:func:`action_bound` make the spaces, :func:`observation_parts` the parts of every robot's
observation from the channel's measurements, :func:`flat_observations` the flat
``float32`` vectors, in the order ``gymnasium.spaces.flatten`` gives the ``Dict``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from gymnasium import spaces
from numpy.typing import DTypeLike, NDArray

from ..formation.spec import Formation
from ..models import DoubleIntegrator, RobotModel, Unicycle
from ..models.transforms import NearIdentity, heading_vectors
from ..sensing import to_frames
from ..validation import positive

__all__ = [
    "MAX_COMMAND",
    "action_bound",
    "common_commands",
    "flat_observations",
    "observation_parts",
    "observation_space",
    "other_robots",
    "own_key",
    "own_part",
]

#: the action bound (m/s, or m/s^2 for double integrators) of a model without a limit
MAX_COMMAND = 5.0


def other_robots(n: int) -> NDArray[np.intp]:
    """``others[i]``: the robots other than ``i``, in robot-number order; ``(n, n - 1)``."""
    return np.array([[j for j in range(n) if j != i] for i in range(n)], dtype=np.intp)


def observation_space(formation: Formation, model: RobotModel, dtype: DTypeLike) -> spaces.Dict:
    """The ``Dict`` of one robot's observation (its keys sorted, as ``Dict`` keeps them);
    vectors of ``formation.dim`` coordinates (3 in space)."""
    n, dim = formation.n, formation.dim
    parts: dict[str, spaces.Space] = {
        "relative": spaces.Box(-np.inf, np.inf, shape=(n - 1, dim), dtype=dtype),
        "seen": spaces.MultiBinary(n - 1),
        "neighbour": spaces.MultiBinary(n - 1),
    }
    if isinstance(model, Unicycle):
        parts["heading"] = spaces.Box(-1.0, 1.0, shape=(2,), dtype=dtype)
    if isinstance(model, DoubleIntegrator):
        parts["velocity"] = spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=dtype)
    return spaces.Dict(parts)


def action_bound(model: RobotModel, max_command: float | None, dim: int = 2) -> NDArray[np.float64]:
    """The bound ``(dim,)`` of a robot's action box ``[-b, b]`` (module docstring of
    :mod:`.pettingzoo`): the model's limits, else ``max_command`` (:data:`MAX_COMMAND`);
    ``(v, omega)`` of a unicycle (in the plane only)."""
    b = MAX_COMMAND if max_command is None else positive(max_command, "max_command")
    if isinstance(model, Unicycle):
        v = model.max_speed if model.max_speed is not None else b
        if model.max_turn_rate is not None:
            w = model.max_turn_rate
        elif model.mapping == NearIdentity.name:
            w = b / model.offset  # omega = u . h_perp / l
        else:
            w = 2.0 * model.turn_gain  # omega_max atan2(.) / (pi / 2)
        return np.array([v, w], dtype=float)
    limit = getattr(model, "max_speed", None)
    if limit is not None and not isinstance(model, DoubleIntegrator):
        b = limit
    return np.full(dim, b, dtype=float)


def observation_parts(
    model: RobotModel,
    x: NDArray[np.float64],
    z: NDArray[np.float64],
    seen: NDArray[np.bool_],
    frame: NDArray[np.float64] | None,
    others: NDArray[np.intp],
) -> dict[str, NDArray]:
    """Every robot's observation but ``neighbour``, of ``B`` formations.

    Parameters
    ----------
    model : RobotModel
    x : ndarray, shape (B, n, k)
        The states.
    z, seen : ndarray, shapes (B, n, n, d) and (B, n, n)
        The channel's measurements (:meth:`formationlab.sensing.Channel.observe`).
    frame : ndarray, shape (B, n) or (B, n, 3, 3), or None
        Each robot's frame (:meth:`~formationlab.sensing.Channel.frames`): its angle in the
        plane, its rotation matrix in space; None: the common frame.
    others : ndarray, shape (n, n - 1)
        :func:`other_robots`.

    Returns
    -------
    dict
        ``relative`` ``(B, n, n - 1, d)`` (0 where not seen), ``seen`` ``(B, n, n - 1)``
        bool, and ``heading`` (unicycles, ``(B, n, 2)``) or ``velocity`` (double
        integrators, ``(B, n, d)``) in the robot's own frame.
    """
    rows = np.arange(others.shape[0])[:, None]
    sees = seen[:, rows, others]
    out: dict[str, NDArray] = {
        "relative": np.where(sees[..., None], z[:, rows, others], 0.0),
        "seen": sees,
    }
    own = own_part(model, x, frame)
    if own is not None:
        out[own_key(model)] = own  # type: ignore[index]
    return out


def own_key(model: RobotModel) -> str | None:
    """The key of a robot's observation of itself: ``heading`` (unicycles), ``velocity``
    (double integrators), else None."""
    if isinstance(model, Unicycle):
        return "heading"
    if isinstance(model, DoubleIntegrator):
        return "velocity"
    return None


def own_part(
    model: RobotModel, x: NDArray[np.float64], frame: NDArray[np.float64] | None
) -> NDArray[np.float64] | None:
    """Each robot's observation of itself ``(B, n, d)`` in its own frame (``frame`` as in
    :func:`observation_parts`: angles ``(B, n)`` in the plane, rotations ``(B, n, 3, 3)`` in
    space, or None), at states ``x`` ``(B, n, k)``: its heading ``(cos, sin)`` (unicycles, in
    the plane) or its velocity (:func:`own_key`); None for other models."""
    if isinstance(model, Unicycle):  # (in the plane)
        angle = np.zeros(x.shape[:2]) if frame is None else frame
        return heading_vectors(x[..., 2] - angle)
    if isinstance(model, DoubleIntegrator):
        d = (x.shape[-1]) // 2
        return to_frames(x[..., d : 2 * d], frame)
    return None


def flat_observations(
    space: spaces.Dict, parts: dict[str, NDArray], neighbours: NDArray, dtype: DTypeLike
) -> NDArray:
    """Every robot's flat observation ``(B, n, size)``: the parts of
    :func:`observation_parts` and ``neighbours`` ``(n, n - 1)`` in ``space``'s key order,
    each flattened, as ``gymnasium.spaces.flatten(space, ...)`` makes one robot's."""
    B, n = parts["seen"].shape[:2]
    whole = {**parts, "neighbour": np.broadcast_to(neighbours, (B, n, n - 1))}
    return np.concatenate(
        [np.asarray(whole[key], dtype=dtype).reshape(B, n, -1) for key in space.spaces], axis=-1
    )


def common_commands(
    model: RobotModel,
    a: NDArray[np.float64],
    x: NDArray[np.float64],
    world: Callable[[NDArray[np.float64]], NDArray[np.float64]],
) -> NDArray[np.float64]:
    """The commands ``(..., n, d)`` the closed loop takes (common frame, at the law's points)
    of the robots' actions ``a`` ``(..., n, d)`` at states ``x`` ``(..., n, k)``.

    A unicycle's ``(v, omega)`` becomes ``v h + l omega h_perp`` (the near-identity
    transform's inverse, exact); any other robot's action, a vector in its own frame, is
    turned into the common frame by ``world`` (:meth:`formationlab.sensing.Channel.world`).
    """
    if isinstance(model, Unicycle):  # (v, omega) -> v h + l omega h_perp
        h = heading_vectors(x[..., 2])
        turn = model.offset * a[..., 1]
        return a[..., :1] * h + turn[..., None] * np.stack([-h[..., 1], h[..., 0]], axis=-1)
    return world(a)
