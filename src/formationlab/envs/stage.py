"""The vectorised environment's per-step work on the host, compiled: observations, errors,
the law as policy.

:class:`~formationlab.envs.vector.FormationVectorEnv` steps ``B`` formations with the
engine's compiled step (:mod:`formationlab.engine.commanded`); what it does around that
step, for every robot of every formation, is here, each a loop over ``(B, n)`` with the
formations' states in the loop's layout ``(n, k, B)``:

:func:`observe`
    every robot's flat observation (:mod:`.observations`: its neighbours' relative
    positions as it measures them, which it sees, which are its neighbours, its own part),
    written in place into the ``float32`` buffer ``(B, n, obs)``; each measurement is the
    sensing stage's (:func:`formationlab.sensing.stage.measured_pair` and
    :func:`~formationlab.sensing.stage.within_range`: frames, frame errors, range, noise;
    :func:`~formationlab.sensing.stage.delivery`: delay and drops), so the observation is
    what :meth:`formationlab.sensing.Channel.field` or :meth:`~formationlab.sensing.Channel.
    observe` gives, cast to ``float32``;
:func:`errors`
    the reward's terms (:mod:`.rewards`): each robot's local formation error
    (:func:`~.rewards.robot_errors`, edge by edge in its order, from 0), each formation's
    largest edge error (the first test of :func:`formationlab.outcomes.analysis.classify`)
    and, when asked, each robot's count of restricted triples turned the wrong way
    (:func:`~.rewards.orientation_errors`, ``c_ijk`` by
    :func:`formationlab.controllers.kinds.restriction.triangle_product`);
:func:`law_commands`
    the law's command of every robot from its own flat observation
    (:func:`formationlab.controllers.stage.local_field`, the compiled twin of
    :func:`formationlab.sensing.local_controls` that the loop's sensing stage calls).

Each equals the numpy function it replaces to the last bit (the same operations in the
same order; a cosine of the library where numpy's may differ by an ulp, in the frames of
headings), tested in ``tests/test_vector_env_stage.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..controllers.kinds.restriction import triangle_product
from ..controllers.stage import local_field
from ..sensing.channel import BLOCK
from ..sensing.stage import delivery, measured_pair, own_frame, within_range

__all__ = ["errors", "law_commands", "observe"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def observe(p, x, hc, hs, which, k, sn, ss, others, neighbours, at, own, obs):
    """Write the observations ``obs[b]`` ``(n, obs)`` of the formations ``b`` in ``which``.

    Parameters
    ----------
    p, x : ndarray, shapes (n, 2, B) and (n, k, B)
        The law's points and the states.
    hc, hs : ndarray, shape (n, B), or (1, 1)
        ``cos`` and ``sin`` of the headings (the frames of robots measuring in them).
    which : ndarray of int, shape (L,)
        The formations observed.
    k : ndarray of int, shape (B,)
        Each formation's step (with noise, delay or drops: each observes its steps in
        order, once each).
    sn, ss : SensingTerms, SensingState or None
        The sensing stage's terms of the ``B`` formations
        (:func:`formationlab.sensing.stage.sensing_terms`) and, with noise, delay or drops,
        their state (delay ring, held measurements; the noise and loss blocks of step
        ``k`` filled); None: the measurements are a function of the state.
    others, neighbours : ndarray, shape (n, n - 1)
        :func:`.observations.other_robots` and whether each is a neighbour (int8).
    at : ndarray of int64, shape (4,)
        Where ``neighbour``, ``relative``, ``seen`` and the robot's own part (heading or
        velocity; -1: none) start in the flat vector.
    own : ndarray, shape (B, n, 2), or (1, 1, 2)
        The own part, in the robot's frame (:func:`.observations.own_part`).
    obs : ndarray of float32, shape (B, n, obs)
        Written in place.
    """
    n = p.shape[0]
    for w in range(which.shape[0]):
        b = which[w]
        kb = k[b]
        row = kb % BLOCK
        for i in range(n):
            c, s = own_frame(sn, hc, hs, i, b, b)  # robot i's turn into its own frame
            for m in range(n - 1):
                j = others[i, m]
                wx = wy = 0.0
                if sn.noise > 0:
                    wx = sn.noise_block[b, row, i, j, 0]
                    wy = sn.noise_block[b, row, i, j, 1]
                zx, zy = measured_pair(
                    p[j, 0, b] - p[i, 0, b], p[j, 1, b] - p[i, 1, b], sn.local, c, s, sn.noise,
                    wx, wy,
                )  # fmt: skip
                inside = within_range(
                    x[j, 0, b] - x[i, 0, b], x[j, 1, b] - x[i, 1, b], sn.ranged, sn.range2
                )
                if ss is not None:  # taken now, used when it arrives (after the delay)
                    slots = ss.ring_z.shape[1]
                    slot = kb % slots
                    back = (kb - (slots - 1)) % slots
                    ss.ring_z[b, slot, i, j, 0] = zx
                    ss.ring_z[b, slot, i, j, 1] = zy
                    ss.ring_in[b, slot, i, j] = inside
                    take, has = delivery(
                        kb >= slots - 1 and ss.ring_in[b, back, i, j],
                        sn.drop > 0 and sn.drop_block[b, row, i, j] < sn.drop,
                        ss.has[b, i, j],
                    )
                    if take:
                        ss.held[b, i, j, 0] = ss.ring_z[b, back, i, j, 0]
                        ss.held[b, i, j, 1] = ss.ring_z[b, back, i, j, 1]
                    ss.has[b, i, j] = has
                    zx, zy = ss.held[b, i, j, 0], ss.held[b, i, j, 1]
                    inside = has
                obs[b, i, at[0] + m] = neighbours[i, m]
                obs[b, i, at[1] + 2 * m] = zx if inside else 0.0
                obs[b, i, at[1] + 2 * m + 1] = zy if inside else 0.0
                obs[b, i, at[2] + m] = 1.0 if inside else 0.0
            if at[3] >= 0:
                obs[b, i, at[3]] = own[b, i, 0]
                obs[b, i, at[3] + 1] = own[b, i, 1]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def errors(p, edge_i, edge_j, distance, halves, want, err, worst, wrong):
    """Each robot's local formation error and wrong orientations, each formation's largest
    edge error, at the law's points ``p`` ``(n, 2, B)``.

    ``edge_i``, ``edge_j``, ``distance`` ``(E,)``: the formation's edges and ``d_ij``;
    ``halves`` ``(T, 3)`` its restricted triples ``(i, j, k)`` (``restricted_halves``) and
    ``want`` ``(T,)`` their desired ``sign(c_ijk)``, or empty to leave ``wrong`` alone.
    Writes ``err`` ``(B, n)`` (``sum_{j in N_i} |r_ij - d_ij|``), ``worst`` ``(B,)`` (the
    largest ``|r_ij - d_ij|``, NaN if any is) and ``wrong`` ``(B, n)``.
    """
    n = p.shape[0]
    for b in range(p.shape[2]):
        for i in range(n):
            err[b, i] = 0.0
        top = -math.inf
        for side in range(2):  # each edge counts for both its robots, as robot_errors sums
            for e in range(edge_i.shape[0]):
                i = edge_i[e]
                j = edge_j[e]
                dx = p[j, 0, b] - p[i, 0, b]
                dy = p[j, 1, b] - p[i, 1, b]
                v = abs(math.sqrt(dx * dx + dy * dy) - distance[e])  # |r_ij - d_ij|
                err[b, i if side == 0 else j] += v
                if side == 0 and (v > top or v != v):
                    top = v
        worst[b] = top
        if halves.shape[0]:
            for i in range(n):
                wrong[b, i] = 0.0
            for t in range(halves.shape[0]):
                i = halves[t, 0]
                j = halves[t, 1]
                k = halves[t, 2]
                c = triangle_product(
                    p[i, 0, b], p[i, 1, b], p[j, 0, b], p[j, 1, b], p[k, 0, b], p[k, 1, b]
                )
                if np.sign(c) * want[t] <= 0:  # collinear counts as wrong (turned_wrong)
                    wrong[b, i] += 1.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def law_commands(obs, others, relative, seen_at, own, terms, u):
    """``u`` ``(B, n, 2)``: every robot's command from its own flat observation ``obs``
    ``(B, n, obs)`` in its own frame (:func:`formationlab.controllers.stage.local_field`).

    ``relative`` and ``seen_at``: where those parts start in the flat vector; ``own``
    ``(B, E, 2)`` or ``(1, E, 2)``: the robots' own desired distances.
    """
    B, n = obs.shape[0], obs.shape[1]
    z = np.zeros((n, n, 2))
    seen = np.zeros((n, n), dtype=np.bool_)
    ul = np.empty((n, 2))
    for b in range(B):
        for i in range(n):
            for m in range(n - 1):
                j = others[i, m]
                z[i, j, 0] = obs[b, i, relative + 2 * m]
                z[i, j, 1] = obs[b, i, relative + 2 * m + 1]
                seen[i, j] = obs[b, i, seen_at + m] != 0
        local_field(z, seen, own[b if own.shape[0] > 1 else 0], terms, ul)
        for i in range(n):
            u[b, i, 0] = ul[i, 0]
            u[b, i, 1] = ul[i, 1]
