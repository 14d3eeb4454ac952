"""``B`` formations of a scenario as one vectorised environment (Gymnasium's ``VectorEnv``).

:class:`FormationVectorEnv` steps ``B`` copies of a scenario's formation at once, each
robot an agent acting on its own observation, for learning with many formations in one
process (``pip install formationlab[agents]``). An agent's observation, action and reward
are the PettingZoo environment's (:mod:`.pettingzoo`, :mod:`.observations`,
:mod:`.rewards`), batched:

``observations`` ``(B, n, obs)`` float32
    every robot's flat observation (its measured neighbours in its own frame, which it
    sees, which are its neighbours, its own heading or velocity);
``actions`` ``(B, n, 2)``
    every robot's command in its own frame (``(v, omega)`` for unicycles);
``rewards`` ``(B, n)``
    every robot's own reward (:class:`~.rewards.Rewards`: weights of the distance errors,
    the wrong orientations, the control effort and a rejected step), not one number per
    formation as single-agent Gymnasium has it; ``rewards.sum(-1)`` is the formation's;
``terminations``, ``truncations`` ``(B,)``
    per formation: it reached the desired formation
    (:func:`formationlab.outcomes.analysis.classify`) or a step was rejected by the contact
    rule (the state stays the last accepted one); truncated after ``duration / dt`` steps.

Each formation's step is the engine's: its robots' model turns the commands into rates with
the model's limits and the Euler step is judged by the contact rule, in compiled code
(:mod:`formationlab.engine.commanded`, the batch loop's stages); faults stop robots. The
observations, the reward's errors and ends are computed for every robot of every formation
in compiled loops (:mod:`.stage`), the measurements by the sensing stage's formulas
(:mod:`formationlab.sensing.stage`: frames, frame errors, range, noise, delay, drops); one
measurement channel (:class:`formationlab.sensing.Channel`) over all formations holds their
seeds and draws, renewed row by row when a formation starts an episode. With noise, delay
or drops each formation carries its delay ring and held measurements, and its noise and
losses are drawn from its own generators, a block of :data:`~formationlab.sensing.BLOCK`
steps at a time as its steps reach it (its draws follow its own steps).

Episodes and seeds: ``reset(seed=s)`` gives formation ``b`` the seed ``s + b`` (a list of
``B`` seeds gives each its own); formation ``b``'s episode ``e`` (0, 1, ...) is trial
``e`` of a study with seed ``s + b``: its start is drawn from the scenario's ``[study]``
distribution (``study.initial``: a box, by default, or Gaussian starts around the template)
as ``formationlab study`` draws trial ``e``
(:func:`formationlab.studies.sampling.trial_initial_states` and
:func:`~formationlab.studies.sampling.model_initial_states`), and its channel is seeded with
``(s + b, e)`` as the study seeds that trial's. Formation ``b`` of ``B`` is therefore the
same, bit for bit, as the only formation of an environment of ``B = 1`` reset with seed
``s + b``. Finished formations start their next episode in the same step
(``metadata["autoreset_mode"]`` is Gymnasium's ``SAME_STEP``): the observation returned is
the new episode's first, ``infos["final_obs"]`` holds the last one where
``infos["_final_obs"]`` is True, ``infos["outcome"]`` how the episode ended.

What it refuses, by name: marching, obstacles and safety filters (their commands need the
law's field or a QP per formation: use the PettingZoo environment), an integrator other
than explicit Euler, formations in space, robot models and laws the compiled loop does not
step.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from ..engine.commanded import commanded_rates, commanded_step
from ..errors import ParameterError
from ..io.scenario import resolve_scenario
from ..models import Unicycle
from ..models.stage import headings, points
from ..models.terms import model_terms
from ..models.transforms import NearIdentity
from ..outcomes.analysis import Tolerances, bearings_met
from ..outcomes.batch import classify_batch
from ..scenario import Scenario
from ..sensing import BLOCK, Channel, Faults, Seed, Sensing
from ..sensing.stage import sensing_arrays, sensing_terms
from ..studies.config import GaussianInitial, parse_study
from ..validation import seed as check_seed
from ..validation import whole
from .observations import (
    action_bound,
    common_commands,
    observation_space,
    other_robots,
    own_key,
    own_part,
)
from .rewards import Rewards, orientation_errors, robot_errors
from .stage import errors, observe
from .starts import EpisodeStarts

__all__ = ["VECTOR_ENV_ID", "FormationVectorEnv"]

#: the environment's id in Gymnasium's registry (``gymnasium.make_vec``)
VECTOR_ENV_ID = "formationlab/FormationVector-v0"


class FormationVectorEnv(VectorEnv):
    """``B`` formations of a scenario, every robot an agent (module docstring).

    Parameters
    ----------
    scenario : Scenario, str or pathlib.Path
        A scenario, its file or its TOML text (:func:`~formationlab.io.scenario.resolve_scenario`).
    num_envs : int
        ``B``, the formations stepped together.
    sensing, faults : Sensing, Faults, optional
        Override the scenario's ``[sensing]`` and ``[faults]``.
    rewards : Rewards, optional
        The reward's weights (default: the PettingZoo environment's reward).
    max_command : float, optional
        The action bound of a model without a limit (:func:`.observations.action_bound`).
    tolerances : Tolerances, optional
        When the formation counts as reached.
    copy : bool
        Whether ``reset`` and ``step`` return a copy of the observations (default, as
        Gymnasium's vector environments) or the environment's own buffer, which the next
        step overwrites in place.

    Attributes
    ----------
    single_observation_space, single_action_space : gymnasium.spaces.Box
        One formation's: ``(n, obs)`` and ``(n, 2)``; ``observation_space`` and
        ``action_space`` have ``B`` of them.
    dict_space : gymnasium.spaces.Dict
        One robot's observation as its parts (the flat vector is its ``flatten``);
        ``parts[key]`` is the slice of the flat vector that holds part ``key``.
    seeds : ndarray of int, shape (B,)
        Each formation's seed; ``episodes`` ``(B,)`` the number of its current episode.
    starts : EpisodeStarts
        Where episodes start (:mod:`.starts`: the study's trials, a seed block kept per
        formation; ``B x 64`` states).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "autoreset_mode": AutoresetMode.SAME_STEP,
        "render_modes": [],
    }
    #: as Gymnasium's own vector environments say it (TorchRL's wrapper reads the attribute)
    autoreset_mode: ClassVar[AutoresetMode] = AutoresetMode.SAME_STEP

    def __init__(
        self,
        scenario: Scenario | str | os.PathLike[str],
        *,
        num_envs: int = 1,
        sensing: Sensing | None = None,
        faults: Faults | None = None,
        rewards: Rewards | None = None,
        max_command: float | None = None,
        tolerances: Tolerances | None = None,
        copy: bool = True,
    ) -> None:
        sc = resolve_scenario(scenario)
        self.num_envs = B = whole(num_envs, "num_envs")
        for key, there, why in (
            ("marching", sc.marching, "its reference term"),
            ("obstacles", sc.obstacles, "the obstacles' repulsion"),
            ("safety", sc.safety is not None and sc.safety.enabled, "a safety filter"),
        ):
            if there:
                raise ParameterError(
                    f"the vectorised environment steps the robots' models under the agents' "
                    f"commands; it does not add {why} to them: remove [{key}] or use the "
                    "PettingZoo environment (formationlab.envs.parallel_env)",
                    key=key,
                )
        dt = getattr(sc.integrator, "dt", None)
        if dt is None or sc.integrator.name != "euler":
            raise ParameterError(
                "the vectorised environment steps explicit Euler at the scenario's [simulation] "
                f'dt; the integrator is {sc.integrator.name!r}: use integrator = "euler"',
                key="simulation.integrator",
            )
        sc.in_plane("the vectorised environment")
        sensing = sc.sensing if sensing is None else sensing
        faults = sc.faults if faults is None else faults
        if not isinstance(sensing, Sensing | None) or not isinstance(faults, Faults | None):
            raise ParameterError("sensing must be a Sensing and faults Faults (or None)")
        self.scenario, self.formation, self.model = sc, sc.formation, sc.model
        self.sensing = sensing or Sensing()
        self.rewards = Rewards() if rewards is None else rewards
        if not isinstance(self.rewards, Rewards):
            raise ParameterError(f"rewards must be a Rewards, got {type(rewards).__name__}")
        self.tolerances = tolerances or Tolerances()
        self.dt = float(dt)
        self.n_steps = max(1, round(float(sc.duration) / self.dt))
        model = sc.model
        # unicycles are driven by (v, omega) through the near-identity transform (exactly
        # invertible), whose model stage steps them with the model's own limits
        driven = model
        if isinstance(model, Unicycle) and model.mapping != NearIdentity.name:
            driven = dataclasses.replace(model, mapping=NearIdentity.name)
        try:
            self._model_terms = model_terms(driven)
        except ParameterError as exc:
            raise ParameterError(str(exc), key="robots.model") from None
        self._terms = sc.law.compiled_terms(self.formation)  # its pairs: the contact rule
        self.terms = sc.law.sensed_terms(self.formation)  # the law's local form (policies)
        self._stop_at = np.full(self.formation.n, np.inf)
        for s in (faults or Faults()).stop:
            self._stop_at[s.robot - 1] = s.at
        study = parse_study(sc.study, source=sc.source, text=sc.text)
        self.initial = study.initial
        self._center = None
        if isinstance(self.initial, GaussianInitial):
            t = self.formation.template
            self._center = t if t is not None else sc.q0
        n = self.formation.n
        self.others = other_robots(n)
        rows = np.arange(n)[:, None]
        self.neighbours = self.formation.adjacency[rows, self.others].astype(np.int8)
        self.dict_space = observation_space(self.formation, model, np.float32)
        size = spaces.flatdim(self.dict_space)
        self.parts: dict[str, slice] = {}  # where each part is in the flat vector
        for key, part in self.dict_space.spaces.items():
            at = sum(s.stop - s.start for s in self.parts.values())
            self.parts[key] = slice(at, at + spaces.flatdim(part))
        bound = np.broadcast_to(action_bound(model, max_command).astype(np.float32), (n, 2))
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (n, size), np.float32)
        self.single_action_space = spaces.Box(-bound, bound, dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, B)
        self.action_space = batch_space(self.single_action_space, B)
        self.copy = bool(copy)
        self.seeds = np.zeros(B, dtype=np.int64)
        self.episodes = np.zeros(B, dtype=np.int64)
        self._k = np.zeros(B, dtype=np.int64)
        k = model.state_size()
        self._xt = np.zeros((n, k, B))  # the states in the loop's layout, formations innermost
        self._xn = np.zeros((n, k, B))  # the other buffer: the next states, then the last
        self._f = np.zeros((n, k, B))
        self._code = np.zeros(B, dtype=np.int8)
        self.starts = EpisodeStarts(self.formation, model, self.initial, self._center, B)
        self._obs = np.zeros((B, n, size), dtype=np.float32)
        self._own = np.zeros((B, n, 2) if own_key(model) else (1, 1, 2))
        key = own_key(model)
        self._at = np.array(
            [self.parts[p].start for p in ("neighbour", "relative", "seen")]
            + [self.parts[key].start if key else -1],
            dtype=np.int64,
        )
        self._err = np.zeros((B, n))
        self._worst = np.zeros(B)
        halves = self.formation.restricted_halves
        self._wrong = np.zeros((B, n))
        self._halves = np.ascontiguousarray(halves, dtype=np.int64).reshape(-1, 3)
        self._want = -np.sign(self.formation.half_alpha()) if len(halves) else np.zeros(0)
        edges = self.formation.edges
        self._edges = (edges[:, 0].astype(np.int64), edges[:, 1].astype(np.int64))
        self._hand = isinstance(model, Unicycle) and model.mapping == NearIdentity.name
        self._headed = model.has_heading and self.sensing.frames == "local"
        self._channel: Channel | None = None  # the formations' seeds and draws
        self._sn: Any = None  # the sensing stage's terms of the formations
        self._ss: Any = None  # and what they carry from step to step (noise, delay, drops)
        self._all = np.arange(B)

    # ------------------------------------------------------------------ episodes

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start an episode in every formation (module docstring for the seeds); ``options``
        are not used. Returns the observations ``(B, n, obs)`` and ``infos``."""
        B = self.num_envs
        if seed is None:
            seed = int(np.random.SeedSequence().entropy % 2**62)  # type: ignore[operator]
        if isinstance(seed, int | np.integer):
            seeds = [check_seed(int(seed)) + b for b in range(B)]
        else:
            seeds = [check_seed(int(s)) for s in seed]
            if len(seeds) != B:
                raise ParameterError(f"reset takes {B} seeds (one per formation), got {len(seeds)}")
        self.seeds[:] = seeds
        self.episodes[:] = 0
        self.starts.forget()
        self._channel = self._sn = self._ss = None
        self._begin(self._all)
        return self._out(), self._infos(np.zeros(B, bool), self._score().copy())

    def _out(self) -> NDArray[np.float32]:
        return self._obs.copy() if self.copy else self._obs

    @property
    def _x(self) -> NDArray[np.float64]:
        """The states ``(B, n, k)``: a view of the loop's layout."""
        return self._xt.transpose(2, 0, 1)

    def _begin(self, which: NDArray[np.intp]) -> None:
        """Formations ``which`` start their current episode: start, channel, observation."""
        self._xt[:, :, which] = self.starts.states(self.seeds, self.episodes, which).transpose(
            1, 2, 0
        )
        self._k[which] = 0
        seeds: list[Seed] = [(int(self.seeds[b]), int(self.episodes[b])) for b in which]
        ch = self._channel
        if ch is None:
            f, law, model = self.formation, self.scenario.law, self.model
            ch = self._channel = Channel(self.sensing, f, law, model, seeds, self.dt)
            headed = model.has_heading and ch.fixed_angles is None
            if self.sensing.sampled:  # the measurements each formation carries: compiled
                self._sn, self._ss = sensing_arrays(ch, self._all, self._stop_at, headed)
            else:
                self._sn, self._ss = sensing_terms(ch, self._all, self._stop_at, headed), None
        elif self._drawn(ch):  # frames, mismatch or noise: drawn from the new seeds
            ch.renew(which, seeds, draws_only=True)
            headed = self.model.has_heading and ch.fixed_angles is None
            new = sensing_terms(ch, which, self._stop_at, headed)
            for key in ("cos_in", "sin_in", "cos_out", "sin_out", "own_distance"):
                if getattr(self._sn, key).shape[0] == self.num_envs:
                    getattr(self._sn, key)[which] = getattr(new, key)
            if self._ss is not None:  # nothing measured, nothing held yet
                for held in self._ss[:4]:
                    held[which] = 0
        self._observe(which)

    def _drawn(self, channel: Channel) -> bool:
        """Whether the channel draws anything per formation that its measurements use
        (frames, frame errors, mismatch, noise, drops)."""
        return (
            self.sensing.sampled
            or channel.fixed_angles is not None
            or channel.own_distance is not None
        )

    def _points(self) -> tuple[NDArray[np.float64], ...]:
        """The law's points ``(n, 2, B)`` and the headings' ``cos`` and ``sin`` ``(n, B)``
        (``(1, 1)`` for a model without headings) of every formation, by the loop's model
        stage (:func:`formationlab.models.stage.points`)."""
        xt = self._xt
        n, B = xt.shape[0], xt.shape[2]
        if not self.model.has_heading:
            return np.ascontiguousarray(xt[:, :2, :]), np.zeros((1, 1)), np.zeros((1, 1))
        hc, hs = np.empty((n, B)), np.empty((n, B))
        headings(xt, hc, hs, np.empty((n, B)), np.empty((n, B)), B)
        if not self._hand:
            return np.ascontiguousarray(xt[:, :2, :]), hc, hs
        p = np.empty((n, 2, B))
        points(xt, hc, hs, p, B, self._model_terms)
        return p, hc, hs

    def _observe(self, which: NDArray[np.intp], at: tuple | None = None) -> None:
        """The observations of formations ``which`` at their current states, every robot's in
        one compiled loop (:func:`.stage.observe`; ``at``: the law's points and headings of
        :meth:`_points`, if known). With noise or drops, the formations whose step begins a
        block of :data:`~formationlab.sensing.BLOCK` steps draw the block's (each from its
        own generator, as its own channel would)."""
        ch, sn = self._channel, self._sn
        assert ch is not None
        if self.sensing.sampled:
            due = which[self._k[which] % BLOCK == 0]
            if due.size and self.sensing.noise > 0:
                sn.noise_block[due] = ch.block("noise", due)
            if due.size and self.sensing.drop > 0:
                sn.drop_block[due] = ch.block("drop", due)
        p, hc, hs = self._points() if at is None else at
        if own_key(self.model) is not None:
            x = self._x[which]
            self._own[which] = own_part(self.model, x, ch.angles(x, which))
        observe(p, self._xt, hc, hs, which, self._k, sn, self._ss, self.others,
                self.neighbours, self._at, self._own, self._obs)  # fmt: skip

    def _score(self, at: tuple | None = None) -> NDArray[np.float64]:
        """Each robot's local formation error ``(B, n)`` now; ``_worst`` and ``_wrong`` too
        (``at``: as in :meth:`_observe`)."""
        f = self.formation
        if f.bearings is not None:  # judged by its bearings (numpy)
            p = self.model.points(self._x)
            self._err = robot_errors(f, p)
            if self.rewards.orientation:
                self._wrong = orientation_errors(f, p)
            return self._err
        p = (self._points() if at is None else at)[0]
        halves = self._halves if self.rewards.orientation else self._halves[:0]
        errors(p, *self._edges, f.distances, halves, self._want, self._err, self._worst,
               self._wrong)  # fmt: skip
        return self._err

    @property
    def own_distance(self) -> NDArray[np.float64] | None:
        """Each formation's robots' own desired distances ``(B, E, 2)`` (None: the
        formation's), with ``[sensing] mismatch``."""
        return None if self._channel is None else self._channel.own_distance

    # ------------------------------------------------------------------ steps

    def step(
        self, actions: Any
    ) -> tuple[NDArray[np.float32], NDArray, NDArray[np.bool_], NDArray[np.bool_], dict]:
        """Step every formation with its robots' actions ``(B, n, 2)`` (module docstring)."""
        if self._channel is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(actions, dtype=float)
        B, n = self.num_envs, self.formation.n
        if a.shape != (B, n, 2):
            raise ParameterError(
                f"step takes the actions of every robot of every formation, shape ({B}, {n}, 2) "
                f"(each robot's command in its own frame), got shape {a.shape}",
                key="actions",
            )
        xt, xn, f, code, ch = self._xt, self._xn, self._f, self._code, self._channel
        x0 = self._x
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            u = common_commands(self.model, a, x0, lambda v: ch.world(v, x0, self._all))
            commanded_rates(xt, np.ascontiguousarray(u.transpose(1, 2, 0)), f, self._model_terms)
            stopped = self._k[None, :] * self.dt >= self._stop_at[:, None]  # (n, B)
            if stopped.any():  # robots stopped by a fault (System._faulty)
                f.transpose(0, 2, 1)[stopped] = 0.0
            commanded_step(xt, f, xn, self.dt, self._terms, code)
        rejected = code != 0
        done = rejected.copy()
        moved = np.flatnonzero(~rejected)
        self._k += ~rejected
        cut = ~done & (self._k >= self.n_steps)
        if rejected.any():  # the state stays the last accepted one
            xn[:, :, rejected] = xt[:, :, rejected]
        self._xt, self._xn = xn, xt  # (the states before the step stay in _xn until the next)
        at = self._points()
        self._observe(moved, at)
        err = self._score(at).copy()
        outcome = np.full(B, "", dtype=object)
        outcome[rejected] = "collision"
        candidates = moved[self._met(moved)]
        if candidates.size:  # (rare: the shape is met; classify decides)
            desired = self._classify(candidates) == "desired"
            done[candidates[desired]] = True
            outcome[candidates[desired]] = "desired"
        cut &= ~done
        if cut.any():
            outcome[cut] = self._classify(np.flatnonzero(cut))
        wrong = self._wrong if self.rewards.orientation else None
        rewards = self.rewards.of(self.formation, None, u, rejected, err, wrong)
        infos = self._infos(rejected, err)
        ended = np.flatnonzero(done | cut)
        infos["outcome"], infos["_outcome"] = outcome, done | cut
        if ended.size:  # the next episodes start now (SAME_STEP)
            infos["final_obs"] = self._obs.copy()
            infos["_final_obs"] = done | cut
            self.episodes[ended] += 1
            self._begin(ended)
        return self._out(), rewards, done, cut, infos

    def _classify(self, which: NDArray[np.intp]) -> NDArray[np.str_]:
        """The outcomes of formations ``which`` after an accepted step
        (:func:`formationlab.outcomes.batch.classify_batch`, the rates of the step)."""
        x0, x1 = self._xn.transpose(2, 0, 1)[which], self._x[which]
        w = self.model.point_rates(x0, (x1 - x0) / self.dt)
        return classify_batch(self.formation, self.model.points(x1), w, self.tolerances)

    def _met(self, which: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Whether the shape is met in formations ``which`` (``classify``'s first test)."""
        if self.formation.bearings is not None:
            p = self.model.points(self._x[which])
            return bearings_met(self.formation, p, self.tolerances)
        return self._worst[which] <= self.tolerances.distance

    def _infos(self, rejected: NDArray[np.bool_], err: NDArray[np.float64]) -> dict[str, Any]:
        return {"t": self._k * self.dt, "seed": self.seeds.copy(), "episode": self.episodes.copy(),
                "error": err, "rejected": rejected}  # fmt: skip

    def state(self) -> NDArray[np.float64]:
        """The formations' states ``(B, n, k)`` (the model's columns: positions first)."""
        return self._x.copy()


if VECTOR_ENV_ID not in gymnasium.registry:  # gymnasium.make_vec(VECTOR_ENV_ID, num_envs=B, ...)
    gymnasium.register(id=VECTOR_ENV_ID, vector_entry_point=f"{__name__}:FormationVectorEnv")
