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

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..models import Unicycle
from ..sensing import local_controls

if TYPE_CHECKING:
    from .pettingzoo import FormationEnv

__all__ = ["law_policy"]

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
        z = np.zeros((n, n, 2))
        seen = np.zeros((n, n), dtype=bool)
        ids = [env.agent_index[a] for a in observations]
        parts = {a: env.as_dict(o) for a, o in observations.items()}  # "flat" or "dict"
        for a, i in zip(observations, ids, strict=True):
            z[i, others[i]] = parts[a]["relative"]
            seen[i, others[i]] = np.asarray(parts[a]["seen"], dtype=bool)
        own = env.own_distance
        u = local_controls(
            env.terms, z[None], seen=seen[None], own_distance=None if own is None else own[None]
        )[0]
        if transform is not None:
            h = np.array([parts[a]["heading"] for a in observations], dtype=float)
            v, omega = transform.commands(u[ids], np.arctan2(h[:, 1], h[:, 0]))
            return {a: np.array([v[r], omega[r]]) for r, a in enumerate(observations)}
        return {a: u[i].copy() for a, i in zip(observations, ids, strict=True)}

    return policy
