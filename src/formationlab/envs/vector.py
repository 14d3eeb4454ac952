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
measurements come from the sensing's channel (:class:`formationlab.sensing.Channel`): one
channel over all formations when it is a function of the state (the paper's sensing,
local frames, frame errors, range, mismatch), renewed row by row when a formation starts an
episode; one channel per formation, observed one by one, with noise, delay or drops (a
formation's draws then follow its own steps).

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
from ..models.terms import model_terms
from ..models.transforms import NearIdentity
from ..outcomes.analysis import Tolerances, bearings_met, classify
from ..scenario import Scenario
from ..sensing import Channel, Faults, Seed, Sensing
from ..studies.config import GaussianInitial, parse_study
from ..studies.sampling import model_initial_states, trial_initial_states
from ..validation import seed as check_seed
from ..validation import whole
from .observations import (
    action_bound,
    common_commands,
    flat_observations,
    observation_parts,
    observation_space,
    other_robots,
)
from .rewards import Rewards, edge_errors, robot_errors

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
        self.seeds = np.zeros(B, dtype=np.int64)
        self.episodes = np.zeros(B, dtype=np.int64)
        self._k = np.zeros(B, dtype=np.int64)
        self._x = np.zeros((B, n, model.state_size()))
        self._obs = np.zeros((B, n, size), dtype=np.float32)
        self._channel: Channel | None = None  # one for all formations (a field of the state)
        self._channels: list[Channel] = []  # or one per formation (noise, delay, drops)
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
        self._channel, self._channels = None, []
        self._begin(self._all)
        return self._obs.copy(), self._infos(np.zeros(B, bool))

    def _begin(self, which: NDArray[np.intp]) -> None:
        """Formations ``which`` start their current episode: start, channel, observation."""
        f, model = self.formation, self.model
        for b in which:  # trial e of a study with seed s (each formation its own)
            s, e = int(self.seeds[b]), int(self.episodes[b])
            q0 = trial_initial_states(f, self.initial, s, [e], center=self._center)
            self._x[b] = model_initial_states(f, model, q0, s, [e])[0]
        self._k[which] = 0
        seeds: list[Seed] = [(int(self.seeds[b]), int(self.episodes[b])) for b in which]
        law, dt = self.scenario.law, self.dt
        if self.sensing.sampled:  # one channel per formation: its draws follow its steps
            if not self._channels:
                self._channels = [None] * self.num_envs  # type: ignore[list-item]
            for b, s in zip(which, seeds, strict=True):
                self._channels[b] = Channel(self.sensing, f, law, model, [s], dt)
        elif self._channel is None:
            self._channel = Channel(self.sensing, f, law, model, seeds, dt)
        else:
            self._channel.renew(which, seeds)
        self._observe(which)

    def _observe(self, which: NDArray[np.intp]) -> None:
        """The observations of formations ``which`` at their current states."""
        x = self._x[which]
        if self._channel is not None:
            z, seen = self._channel.field(x, which)
            if seen is None:
                seen = np.ones(z.shape[:-1], dtype=bool)
            angles = self._channel.angles(x, which)
        else:
            one = np.zeros(1, dtype=np.intp)
            got = [
                self._channels[b].observe(x[r : r + 1], one, int(self._k[b]))
                for r, b in enumerate(which)
            ]
            z = np.concatenate([g[0] for g in got])
            seen = np.concatenate([g[1] for g in got])
            frames = [self._channels[b].angles(x[r : r + 1], one) for r, b in enumerate(which)]
            angles = None if frames[0] is None else np.concatenate(frames)  # type: ignore[arg-type]
        parts = observation_parts(self.model, x, z, seen, angles, self.others)
        self._obs[which] = flat_observations(self.dict_space, parts, self.neighbours, np.float32)

    @property
    def own_distance(self) -> NDArray[np.float64] | None:
        """Each formation's robots' own desired distances ``(B, E, 2)`` (None: the
        formation's), with ``[sensing] mismatch``."""
        if self._channel is not None:
            return self._channel.own_distance
        if self._channels and self._channels[0].own_distance is not None:
            return np.concatenate([c.own_distance for c in self._channels])  # type: ignore[misc]
        return None

    def _world(self, a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._channel is not None:
            return self._channel.world(a, x, self._all)
        one = np.zeros(1, dtype=np.intp)
        return np.concatenate(
            [c.world(a[b : b + 1], x[b : b + 1], one) for b, c in enumerate(self._channels)]
        )

    # ------------------------------------------------------------------ steps

    def step(
        self, actions: Any
    ) -> tuple[NDArray[np.float32], NDArray, NDArray[np.bool_], NDArray[np.bool_], dict]:
        """Step every formation with its robots' actions ``(B, n, 2)`` (module docstring)."""
        if self._channel is None and not self._channels:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(actions, dtype=float)
        B, n = self.num_envs, self.formation.n
        if a.shape != (B, n, 2):
            raise ParameterError(
                f"step takes the actions of every robot of every formation, shape ({B}, {n}, 2) "
                f"(each robot's command in its own frame), got shape {a.shape}",
                key="actions",
            )
        x0 = self._x
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            u = common_commands(self.model, a, x0, lambda v: self._world(v, x0))
            xt = np.ascontiguousarray(x0.transpose(1, 2, 0))  # the loop's (n, k, B)
            f = np.empty_like(xt)
            commanded_rates(xt, np.ascontiguousarray(u.transpose(1, 2, 0)), f, self._model_terms)
            stopped = self._k[None, :] * self.dt >= self._stop_at[:, None]  # (n, B)
            if stopped.any():  # robots stopped by a fault (System._faulty)
                f.transpose(0, 2, 1)[stopped] = 0.0
            xn = np.empty_like(xt)
            code = np.zeros(B, dtype=np.int8)
            commanded_step(xt, f, xn, self.dt, self._terms, code)
        rejected = code != 0
        x1 = xn.transpose(2, 0, 1)
        self._x = x = np.where(rejected[:, None, None], x0, x1)
        self._k += ~rejected
        moved = np.flatnonzero(~rejected)
        self._observe(moved)
        p = self.model.points(x)
        e = edge_errors(self.formation, p)
        err = robot_errors(self.formation, p, e)
        done = rejected.copy()
        candidates = moved[self._met(p[moved], e[moved])]
        outcome = np.full(B, "", dtype=object)
        outcome[rejected] = "collision"
        for b in candidates:  # (rare: the shape is met; classify decides)
            w = self.model.point_rates(x0[b], (x1[b] - x0[b]) / self.dt)
            got = classify(self.formation, p[b], w, self.tolerances)
            if got == "desired":
                done[b], outcome[b] = True, got
        cut = ~done & (self._k >= self.n_steps)
        for b in np.flatnonzero(cut):
            w = self.model.point_rates(x0[b], (x1[b] - x0[b]) / self.dt)
            outcome[b] = classify(self.formation, p[b], w, self.tolerances)
        rewards = self.rewards.of(self.formation, p, u, rejected, err)
        infos = self._infos(rejected, err)
        ended = np.flatnonzero(done | cut)
        infos["outcome"], infos["_outcome"] = outcome, done | cut
        if ended.size:  # the next episodes start now (SAME_STEP)
            infos["final_obs"] = self._obs.copy()
            infos["_final_obs"] = done | cut
            self.episodes[ended] += 1
            self._begin(ended)
        return self._obs.copy(), rewards, done, cut, infos

    def _met(self, p: NDArray[np.float64], e: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether the shape is met at points ``p`` ``(L, n, 2)`` with edge errors ``e``
        ``(L, E)`` (``classify``'s first test)."""
        if self.formation.bearings is not None:
            return bearings_met(self.formation, p, self.tolerances)
        return np.max(e, axis=-1) <= self.tolerances.distance

    def _infos(
        self, rejected: NDArray[np.bool_], err: NDArray[np.float64] | None = None
    ) -> dict[str, Any]:
        if err is None:
            err = robot_errors(self.formation, self.model.points(self._x))
        return {"t": self._k * self.dt, "seed": self.seeds.copy(), "episode": self.episodes.copy(),
                "error": err, "rejected": rejected}  # fmt: skip

    def state(self) -> NDArray[np.float64]:
        """The formations' states ``(B, n, k)`` (the model's columns: positions first)."""
        return self._x.copy()


if VECTOR_ENV_ID not in gymnasium.registry:  # gymnasium.make_vec(VECTOR_ENV_ID, num_envs=B, ...)
    gymnasium.register(id=VECTOR_ENV_ID, vector_entry_point=f"{__name__}:FormationVectorEnv")
