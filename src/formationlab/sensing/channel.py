"""The measurement channel of a batch of trials: frames, mismatch, noise, delay, drops, range.

A :class:`Channel` belongs to one run of ``B`` trials (the stepping driver makes one;
so do the PettingZoo environment and the asynchronous runner). Everything random is
drawn from each trial's own seed, in an order that does not depend on the other
trials, so a trial's run is the same alone, in any batch, on any worker:

* at creation, each robot's frame (a uniform rotation, for robots without a heading: an
  angle in the plane, a rotation of SO(3) in space,
  :func:`~formationlab.sensing.local.uniform_rotations`) and each robot's error in each
  of its desired distances (``mismatch``);
* per step ``k``, the noise of the measurements taken at ``k`` and the losses of the
  measurements delivered at ``k`` (drawn in blocks of :data:`BLOCK` steps).

At step ``k`` robot ``i`` measures ``z_ij(k) = R_i^T (p_j(k) - p_i(k)) + noise`` (``R_i =
R(a_i(k))`` in the plane; noise on each of the ``d`` coordinates) of every robot within
``range`` (centre to centre); the measurement it uses is the one
taken at ``k - m`` (``m = delay / dt``), unless that one is lost (probability
``drop``), in which case it keeps the last one it received. A robot out of range when
the measurement was taken is not seen: its terms are left out, nothing is held.

With no noise, delay or drops the channel is a function of the state (:meth:`field`),
evaluated at every stage of a scheme; otherwise measurements change once per step
(:meth:`observe`) and a robot holds its command over the step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..controllers.terms import PAIR_LIMIT, KernelTerms
from ..errors import ParameterError
from ..formation.spec import Formation
from ..models import RobotModel
from .config import Sensing, delay_ring
from .local import from_frames, local_controls, measured, uniform_rotations

__all__ = ["BLOCK", "SENSING_LIMIT", "Channel", "Seed"]

#: steps of noise and losses drawn at once per trial
BLOCK = 256
#: most robots a sensed run takes: the measurements of a trial are an n x n array
SENSING_LIMIT = 256
#: what a trial's randomness is drawn from: an int, or a tuple of ints (study seed, trial)
Seed = int | tuple[int, ...]


class _Draws(NamedTuple):
    """What a channel draws for each of its trials at creation (``None``: not drawn)."""

    noise: list[np.random.Generator]
    drop: list[np.random.Generator]
    angles: NDArray[np.float64] | None  #: (B, n) fixed frames or frame errors, in the plane
    rotations: NDArray[np.float64] | None  #: (B, n, 3, 3) fixed frames in space
    own_distance: NDArray[np.float64] | None  #: (B, E, 2) with mismatch


def _entropy(seed: Seed) -> list[int]:
    return [int(s) for s in (seed if isinstance(seed, tuple) else (seed,))]


class Channel:
    """What the robots of ``B`` trials measure, step by step (module docstring).

    Parameters
    ----------
    sensing : Sensing
        The sensing model.
    formation, law, model
        The closed loop's formation, law (its :meth:`~Law.compiled_terms` give the
        per-robot controls) and robot model (its heading, if any, is the local frame).
    seeds : sequence of int or tuple of int
        One per trial.
    dt : float
        The step (the delay is a whole number of steps).
    """

    def __init__(
        self,
        sensing: Sensing,
        formation: Formation,
        law: Law,
        model: RobotModel,
        seeds: Sequence[Seed],
        dt: float,
    ) -> None:
        n = formation.n
        if n > SENSING_LIMIT:
            raise ParameterError(
                f"[sensing] models formations of at most {SENSING_LIMIT} robots (each "
                f"trial keeps an n x n array of measurements); this one has {n}: remove "
                "[sensing] for larger swarms",
                key="sensing",
            )
        assert n <= PAIR_LIMIT
        self.sensing, self.formation, self.model, self.n = sensing, formation, model, n
        self.terms: KernelTerms = law.sensed_terms(formation)
        self.dim = formation.dim
        self.B = len(seeds)
        self.m = delay_ring(sensing.delay, dt, n, self.B) if sensing.delay > 0 else 0
        self.k = -1  # the last step observed
        draws = self._draws(seeds)
        self._noise, self._drop = draws.noise, draws.drop
        self.fixed_angles: NDArray[np.float64] | None = draws.angles  # in the plane
        self.fixed_rotations: NDArray[np.float64] | None = draws.rotations  # (B, n, 3, 3)
        self.own_distance: NDArray[np.float64] | None = draws.own_distance  # (B, E, 2)
        shape = (self.B, n, n)
        # the delay ring and the held measurements (made at the first observed step: a
        # compiled path keeps its own and asks the channel only for seeds and draws)
        self._ring_z = self._ring_in = self._held = np.zeros(0)
        self._has = np.zeros(shape, dtype=bool)
        self._blocks: dict[str, NDArray[np.float64]] = {}
        self._eye = np.eye(n, dtype=bool)
        self._block_of: dict[str, int] = {}

    def _draws(self, seeds: Sequence[Seed]) -> _Draws:
        """Each trial's frames, mismatch and generators, drawn from its own seed."""
        n, sensing = self.n, self.sensing
        roots = [np.random.SeedSequence(_entropy(s)) for s in seeds]
        kids = [r.spawn(4) for r in roots]  # frames, mismatch, noise, drops
        angles = rotations = own = None
        if sensing.frames == "local" and not self.model.has_heading and self.dim == 3:
            rotations = np.stack(
                [uniform_rotations(np.random.Generator(np.random.PCG64(c[0])), n) for c in kids]
            ).reshape(len(kids), n, 3, 3)
        elif sensing.frames == "local" and not self.model.has_heading:
            angles = np.stack(
                [np.random.Generator(np.random.PCG64(c[0])).uniform(0, 2 * np.pi, n) for c in kids]
            )
        elif sensing.frame_error > 0:  # the common frame, turned by each robot's own error
            angles = np.stack(
                [np.random.Generator(np.random.PCG64(c[0])).normal(0.0, sensing.frame_error, n)
                 for c in kids]
            )  # fmt: skip
        if sensing.mismatch > 0:
            d, a = self.terms.edge_distance, self.terms.edge_contact
            e = np.stack(
                [np.random.Generator(np.random.PCG64(c[1])).standard_normal((d.size, 2))
                 for c in kids]
            ) * sensing.mismatch  # fmt: skip
            cap = (0.5 * (d - a))[None, :, None]
            own = d[None, :, None] + np.clip(e, -cap, cap)
        return _Draws(
            [np.random.Generator(np.random.PCG64(c[2])) for c in kids],
            [np.random.Generator(np.random.PCG64(c[3])) for c in kids],
            angles, rotations, own,
        )  # fmt: skip

    def renew(
        self, trials: NDArray[np.intp], seeds: Sequence[Seed], *, draws_only: bool = False
    ) -> None:
        """Give ``trials`` new seeds: their frames, mismatch and generators become those a
        channel made with ``seeds`` draws (formations of a vectorised environment that start
        a new episode, :mod:`formationlab.envs.vector`).

        Only for a channel that is a function of the state (no noise, delay or drops:
        :meth:`field`), whose trials carry no measurements from step to step, or
        (``draws_only``) one whose caller keeps its trials' measurements itself (a compiled
        sensing stage) and asks the channel only for the draws (:meth:`block`).
        """
        if self.sensing.sampled and not draws_only:
            raise ParameterError(
                "a channel with noise, delay or drops carries its trials' measurements from "
                "step to step: make a new Channel for the new seeds",
                key="sensing",
            )
        trials = np.asarray(trials, dtype=np.intp).reshape(-1)
        if trials.size != len(seeds):
            raise ValueError(f"{len(seeds)} seeds for {trials.size} trials")
        new = self._draws(seeds)
        for ours, theirs in (
            (self.fixed_angles, new.angles),
            (self.fixed_rotations, new.rotations),
            (self.own_distance, new.own_distance),
        ):
            if ours is not None and theirs is not None:
                ours[trials] = theirs
        for row, t in enumerate(trials):
            self._noise[t], self._drop[t] = new.noise[row], new.drop[row]

    # ------------------------------------------------------------------ frames and views

    def frames(self, x: NDArray[np.float64], live: NDArray[np.intp]) -> NDArray[np.float64] | None:
        """Each robot's frame at states ``x`` of trials ``live``: angles ``(L, n)`` in the plane
        (:meth:`angles`), rotation matrices ``(L, n, 3, 3)`` in space; None: the common frame."""
        if self.fixed_rotations is not None:
            return self.fixed_rotations[live]
        return self.angles(x, live)

    def angles(self, x: NDArray[np.float64], live: NDArray[np.intp]) -> NDArray[np.float64] | None:
        """Each robot's frame ``(L, n)`` in the plane at states ``x`` of trials ``live`` (None:
        the common frame, or a formation in space)."""
        if self.fixed_angles is not None:  # fixed random frames, or the frame errors
            return self.fixed_angles[live]
        if self.sensing.frames != "local":
            return None
        return self.model.heading(x)

    def in_range(self, x: NDArray[np.float64]) -> NDArray[np.bool_] | None:
        """Who sees whom by range, ``(L, n, n)`` (centre to centre); None without a range."""
        if np.isinf(self.sensing.range):
            return None
        q = self.model.positions(x)
        r = q[..., None, :, :] - q[..., :, None, :]
        return np.sum(r * r, axis=-1) <= self.sensing.range**2

    def field(self, x: NDArray[np.float64], live: NDArray[np.intp]):
        """``(z, seen)`` of states ``x`` now (a channel without noise, delay or drops)."""
        return measured(self.model.points(x), self.frames(x, live)), self.in_range(x)

    def block(self, which: str, trials: NDArray[np.intp]) -> NDArray[np.float64]:
        """The next :data:`BLOCK` steps of noise or losses of each of ``trials``.

        ``which = "noise"``: standard normals ``(L, BLOCK, n, n, d)``; ``"drop"``: uniforms
        in ``[0, 1)`` ``(L, BLOCK, n, n)``; each trial's from its own generator, so a
        trial's draws depend only on its seed and on how many blocks it has drawn.
        """
        n = self.n
        out = np.empty((len(trials), BLOCK, n, n, *((self.dim,) if which == "noise" else ())))
        for row, b in enumerate(trials):
            if which == "noise":
                out[row] = self._noise[b].standard_normal(out.shape[1:])
            else:
                out[row] = self._drop[b].random(out.shape[1:])
        return out

    def _draw(self, which: str, live: NDArray[np.intp], k: int, shape: tuple[int, ...]) -> NDArray:
        block, row = divmod(k, BLOCK)
        buf = self._blocks.get(which)
        if buf is None:
            buf = self._blocks[which] = np.zeros((self.B, BLOCK, *shape))
        if self._block_of.get(which, -1) != block:  # a new block for the live trials
            buf[live] = self.block(which, live)
            self._block_of[which] = block
        return buf[live, row]

    def observe(
        self, x: NDArray[np.float64], live: NDArray[np.intp], k: int
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """The measurements ``(z, seen)`` the robots of trials ``live`` use at step ``k``.

        Steps are observed in order, once each (``k`` = the previous ``k`` + 1).
        """
        if k != self.k + 1:
            raise RuntimeError(f"the channel observes steps in order: step {k} after {self.k}")
        self.k = k
        n, s, dim = self.n, self.sensing, self.dim
        if k == 0:
            shape = (self.B, n, n)
            self._ring_z = np.zeros((self.m + 1, *shape, dim))
            self._ring_in = np.zeros((self.m + 1, *shape), dtype=bool)
            self._held = np.zeros((*shape, dim))
        z = measured(self.model.points(x), self.frames(x, live))
        if s.noise > 0:
            z = z + s.noise * np.where(
                self._eye[..., None], 0.0, self._draw("noise", live, k, (n, n, dim))
            )
        rng = self.in_range(x)
        inside = np.ones((live.size, n, n), dtype=bool) if rng is None else rng
        slot = k % (self.m + 1)
        self._ring_z[slot, live], self._ring_in[slot, live] = z, inside
        if k < self.m:  # nothing has arrived yet
            arrived = np.zeros_like(inside)
            z_in = z
        else:
            back = (k - self.m) % (self.m + 1)
            z_in, arrived = self._ring_z[back, live], self._ring_in[back, live]
        if s.drop > 0:
            lost = (self._draw("drop", live, k, (n, n)) < s.drop) & ~self._eye
            fresh = arrived & ~lost
            keep = arrived & lost & self._has[live]
        else:
            fresh, keep = arrived, np.zeros_like(arrived)
        held = np.where(fresh[..., None], z_in, self._held[live])
        has = fresh | keep
        self._held[live], self._has[live] = held, has
        return held, has

    def informed(self, x: NDArray[np.float64], live: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Whether every robot of each trial sees all its neighbours now, ``(L,)``.

        A trial whose robots still wait for a measurement (before the first one arrives
        after a delay, or while it is lost before a first one was received, or out of
        range) is not at rest, however still its robots stand: the driver's stop rule
        asks this too.
        """
        ei, ej = self.terms.edge_i, self.terms.edge_j
        has: NDArray[np.bool_] | None = self._has[live] if self.sensing.sampled else None
        if has is None:
            has = self.in_range(x)
            if has is None:
                return np.ones(live.size, dtype=bool)
        return np.all(has[:, ei, ej] & has[:, ej, ei], axis=-1)

    # ------------------------------------------------------------------ commands

    def local(
        self, z: NDArray, seen: NDArray | None, live: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """Every robot's command in its own frame from its measurements; ``(L, n, d)``."""
        own = None if self.own_distance is None else self.own_distance[live]
        return local_controls(self.terms, z, seen=seen, own_distance=own)

    def world(self, u_local: NDArray, x: NDArray, live: NDArray[np.intp]) -> NDArray[np.float64]:
        """Commands ``(L, n, d)`` in the common frame: ``R_i u_i``."""
        return from_frames(u_local, self.frames(x, live))
