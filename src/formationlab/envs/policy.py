"""The scenario's law as the policy of every agent, from each agent's own observation.

:func:`law_policy` returns the decentralized form of the paper's law for an environment of
:func:`~formationlab.envs.parallel_env`: robot ``i``'s action is the law's control
``u_i`` computed by :func:`formationlab.sensing.local_controls` from robot ``i``'s own
observation alone, flat or ``Dict`` (its measured relative positions in its own frame,
which it sees, and its own desired distances), turned into the robot's action: the
command itself for single and double integrators, ``(v_i, omega_i)`` through the model's
transform (:mod:`formationlab.models.transforms`) at the robot's observed heading for
unicycles.
With the paper's sensing (no faults, common frame) the environment driven by it is
:func:`formationlab.simulate` with explicit Euler at the same ``dt`` (tested to ``1e-12``);
with noise, delay, drops, range or mismatch it is ``simulate(sensing=...)`` with the
same seed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..controllers.terms import KernelTerms
from ..models import RobotModel, Unicycle
from ..sensing import local_controls
from .stage import law_commands

if TYPE_CHECKING:
    from .pettingzoo import FormationEnv
    from .vector import FormationVectorEnv

__all__ = ["law_actions", "law_policy", "vector_law_policy"]

Policy = Callable[[Mapping[str, Mapping[str, NDArray]]], dict[str, NDArray[np.float64]]]


def law_policy(env: FormationEnv) -> Policy:
    """``policy(observations) -> actions``: the law of ``env``'s scenario in every agent.

    The actions of all agents are computed in one call (one array operation), each row
    from that agent's observation only (module docstring). The desired distances are the
    episode's own (``env.own_distance``, with ``[sensing] mismatch``).
    """
    n, others = env.formation.n, env.others
    transform = env.model.transform if isinstance(env.model, Unicycle) else None

    def policy(observations: Mapping[str, Mapping[str, Any]]) -> dict[str, NDArray[np.float64]]:
        z = np.zeros((n, n, env.formation.dim))
        seen = np.zeros((n, n), dtype=bool)
        ids = [env.agent_index[a] for a in observations]
        parts = {a: env.as_dict(o) for a, o in observations.items()}  # "flat" or "dict"
        for a, i in zip(observations, ids, strict=True):
            z[i, others[i]] = parts[a]["relative"]
            seen[i, others[i]] = np.asarray(parts[a]["seen"], dtype=bool)
        h = None
        if transform is not None:
            h = np.array([parts[a]["heading"] for a in observations], dtype=float)[None]
        act = law_actions(env.terms, env.model, z[None], seen[None], env.own_distance, h, ids)[0]
        return {a: act[r].copy() for r, a in enumerate(observations)}

    return policy


def law_actions(
    terms: KernelTerms,
    model: RobotModel,
    z: NDArray[np.float64],
    seen: NDArray[np.bool_],
    own: NDArray[np.float64] | None,
    heading: NDArray[np.float64] | None,
    ids: Sequence[int] | NDArray[np.intp] | None = None,
) -> NDArray[np.float64]:
    """The law's actions ``(B, m, 2)`` of robots ``ids`` (default all) of ``B`` formations.

    ``z`` ``(B, n, n, 2)`` and ``seen`` ``(B, n, n)``: what each robot measures in its own
    frame; ``own``: the robots' own desired distances ``(B, E, 2)`` or ``(E, 2)`` (None:
    the formation's); ``heading`` ``(B, m, 2)``: the unicycles' observed ``(cos, sin)``
    (else None). The command ``u_i`` of :func:`formationlab.sensing.local_controls`, as
    ``(v_i, omega_i)`` through the model's transform for unicycles.
    """
    if own is not None and own.ndim == 2:
        own = own[None]
    u = local_controls(terms, z, seen=seen, own_distance=own)
    if ids is not None:
        u = u[:, np.asarray(ids, dtype=np.intp)]
    return as_actions(model, u, heading)


def as_actions(
    model: RobotModel, u: NDArray[np.float64], heading: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    """The actions ``(B, m, 2)`` of the law's commands ``u`` ``(B, m, 2)`` in the robots'
    frames: ``u`` itself, or ``(v_i, omega_i)`` through the model's transform at the
    observed headings ``(cos, sin)`` ``heading`` ``(B, m, 2)`` for unicycles."""
    if isinstance(model, Unicycle):
        assert heading is not None
        v, omega = model.transform.commands(u, np.arctan2(heading[..., 1], heading[..., 0]))
        return np.stack([v, omega], axis=-1)
    return u


def vector_law_policy(env: FormationVectorEnv) -> Callable[[NDArray], NDArray[np.float64]]:
    """``policy(observations) -> actions``: the law of ``env``'s scenario in every robot of
    every formation of a :class:`~formationlab.envs.vector.FormationVectorEnv`.

    ``observations`` ``(B, n, obs)`` (flat, as the environment gives them) become each
    robot's measurements and its actions ``(B, n, 2)`` are :func:`law_actions` of them,
    computed by one compiled loop over all robots (:func:`.stage.law_commands`: the same
    terms in the same order, so the same numbers), each from that robot's observation only.
    """
    at = env.parts  # where each part of the observation is in the flat vector
    relative, seen = at["relative"].start, at["seen"].start
    others = env.others.astype(np.int64)
    E = env.terms.edge_i.size
    formation_own = np.broadcast_to(env.terms.edge_distance[None, :, None], (1, E, 2)).copy()

    def policy(observations: NDArray) -> NDArray[np.float64]:
        o = np.ascontiguousarray(observations, dtype=np.float64)
        u = np.empty((*o.shape[:2], 2))
        own = env.own_distance
        law_commands(o, others, relative, seen, formation_own if own is None else own,
                     env.terms, u)  # fmt: skip
        heading = o[..., at["heading"]].astype(float) if "heading" in at else None
        return as_actions(env.model, u, heading)

    return policy
