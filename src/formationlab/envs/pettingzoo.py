"""The robots of a scenario as the agents of a PettingZoo parallel environment.

:func:`parallel_env` (``pip install formationlab[agents]``) makes a
:class:`FormationEnv`: one agent per robot, ``"robot_1"`` to ``"robot_n"`` (1-based, as
in the paper), stepped together by explicit Euler at the scenario's ``dt`` through the
closed loop (:meth:`formationlab.System.rhs_commanded`: the robot model, marching,
obstacle repulsion, the safety filter and faults act on the agents' commands as they act
on the law's).

Observation of robot ``i``: with ``observation="flat"`` (the default) one ``Box`` vector,
what ``gymnasium.spaces.flatten`` makes of the ``Dict`` below (its keys in alphabetical
order, each flattened: ``heading`` or ``velocity``, ``neighbour``, ``relative`` row by row,
``seen``), the form SuperSuit's wrappers and learning libraries take; with
``observation="dict"`` the ``Dict`` itself. Its floating-point parts are ``float32``
(``dtype=np.float64`` on request), ``seen`` and ``neighbour`` ``int8`` (within the flat
vector, 0.0 or 1.0). One slot per *other* robot, in robot-number order (robot ``i`` left
out):

``relative`` ``(n - 1, d)``
    robot ``i``'s measurement of ``p_j - p_i`` in its own frame, from the measurement
    channel (:class:`~formationlab.sensing.Channel`: local frames, noise, delay, drops,
    range, as the scenario's or the given :class:`~formationlab.sensing.Sensing` says);
    0 where robot ``j`` is not seen. ``p`` are the law's points (hand points of
    near-identity unicycles, else the centres);
``seen`` ``(n - 1,)`` of 0/1
    whether robot ``i`` holds a measurement of robot ``j`` (range, delay, drops);
``neighbour`` ``(n - 1,)`` of 0/1
    whether ``j`` is a neighbour of ``i`` in the formation's graph (constant);
``heading`` ``(2,)``, unicycles only
    ``(cos, sin)`` of robot ``i``'s heading in its own frame (``(1, 0)`` in local frames);
``velocity`` ``(d,)``, double integrators only
    robot ``i``'s velocity in its own frame.

``d`` is the formation's dimension: 2 in the plane, 3 for a formation in space
(``Formation.dim``, docs/three-d.md), where a robot's own frame is a rotation of SO(3)
(``[sensing] frames = "local"``) and actions have three components.

The robot's own heading and velocity are exact (proprioception); only the relative
positions pass through the channel.

Action of robot ``i``, in its own frame (the frame of its observation): the velocity
command of a single integrator, the acceleration command ``u_i`` of a double integrator
(``q_ddot_i = -k_d q_dot_i + u_i``), ``(v_i, omega_i)`` of a unicycle. The ``Box`` is
``[-b, b]`` per component, ``b`` the model's limit (``max_speed``, ``max_turn_rate``)
or ``max_command`` (default :data:`MAX_COMMAND`); a unicycle's ``omega`` without a limit
gets ``max_command / offset`` (near-identity) or ``2 turn_gain`` (heading transform),
the largest turn rate the transform asks of a command of size ``max_command``. Actions
are not clipped to the box: the robot model's own limits act (direction-preserving
saturation, :mod:`formationlab.models.limits`), as they do on the law.

Reward of robot ``i`` after a step: ``-sum_{j in N_i} |r_ij - d_ij|`` at the law's
points (its local formation error; ``-sum_{j in N_i} ||g_ij - g*_ij||`` for a formation
judged by its bearings, docs/bearing.md), minus ``contact_penalty`` for every robot when the
step is rejected by the package's contact rule (:meth:`formationlab.System.step_verdict`:
contact at the end of the step, robots passing through each other, non-finite states).

Every agent terminates when the desired formation is reached
(:func:`formationlab.outcomes.analysis.classify` gives ``"desired"`` at the given tolerances)
or at a rejected step (the state stays the last accepted one, as in the stepping
driver); every agent is truncated after ``duration / dt`` steps. ``infos`` hold the
time ``t``, the episode's ``seed``, the agent's ``error`` and, at the end, the
``outcome`` (and ``status`` and ``message`` of a rejected step).

Seeding as in Gymnasium: ``reset(seed=s)`` makes episode ``s`` (the measurement
channel seeded with ``s``, as ``simulate(sensing=Sensing(seed=s))`` seeds its own; the
sensing's own ``seed`` is not used); later ``reset()`` calls make episodes ``(s, 1)``,
``(s, 2)``, ... ; a first ``reset()`` without a seed draws ``s`` from the operating
system. The start of an episode is the scenario's initial state with Gaussian noise of
standard deviation ``jitter`` (m) on each coordinate of each position (headings and
velocities as the scenario gives them), drawn from the episode's seed too and drawn again
while robots would touch; by default ``jitter`` is :data:`JITTER_FRACTION` of the
formation's smallest desired distance, so that different seeds start differently;
``jitter=0`` starts every episode at the scenario's initial state.

Registered in PettingZoo's registry (PettingZoo 1.27 and later have ``pettingzoo.make``)
when this module is imported: ``pettingzoo.make("parallel", "formationlab/Formation-v0",
scenario=...)`` calls :func:`parallel_env`, ``pettingzoo.make("aec", ...)`` :func:`env`.
Like PettingZoo's own environments the module also has the factories :func:`parallel_env`
and :func:`env` and ``metadata["name"]``.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from numpy.typing import DTypeLike, NDArray

try:
    import pettingzoo
    from gymnasium import spaces
    from pettingzoo import ParallelEnv
    from pettingzoo.utils.conversions import parallel_to_aec
except ImportError as exc:  # pragma: no cover - the extra is installed where tests run
    raise ImportError(
        "formationlab.envs.parallel_env needs PettingZoo and Gymnasium, the 'agents' "
        "extra: pip install formationlab[agents]"
    ) from exc

from ..controllers.terms import KernelTerms
from ..errors import FormationError, ParameterError
from ..io.scenario import resolve_scenario
from ..models import Unicycle
from ..models.transforms import NearIdentity
from ..outcomes.analysis import Tolerances, classify
from ..scenario import Scenario, closed_loop
from ..sensing import Channel, Faults, Seed, Sensing
from ..simulation.run import initial_state
from ..status import Status
from ..validation import nonnegative
from ..validation import seed as check_seed
from .observations import (
    MAX_COMMAND,
    action_bound,
    common_commands,
    flat_observations,
    observation_parts,
    observation_space,
    other_robots,
)
from .rewards import CONTACT_PENALTY, robot_errors

__all__ = ["ENV_ID", "JITTER_FRACTION", "MAX_COMMAND", "FormationEnv", "env", "parallel_env"]

#: the environment's id in PettingZoo's registry (``pettingzoo.make``)
ENV_ID = "formationlab/Formation-v0"
#: the default ``jitter`` of the start, as a fraction of the smallest desired distance
JITTER_FRACTION = 0.05
#: the observation forms (``observation=``)
OBSERVATIONS = ("flat", "dict")

#: draws of a jittered start before giving up on one clear of contact
_JITTER_TRIES = 100
_LIVE = np.zeros(1, dtype=np.intp)  # the channel's one trial


class FormationEnv(ParallelEnv):
    """The robots of a scenario as agents (module docstring); made by :func:`parallel_env`.

    Attributes
    ----------
    scenario : Scenario
        The scenario (formation, law, robot model, initial state, dt, duration).
    system : System
        The closed loop the agents act in (its contact rule judges every step).
    dt : float
        The step, seconds; ``n_steps`` steps make the episode's ``duration``.
    channel : Channel
        The current episode's measurement channel (made by :meth:`reset`).
    seed : int or tuple of int
        The current episode's seed.
    observation : {"flat", "dict"}
        The observation form; ``dict_space`` is the ``Dict`` of its parts either way.
    dtype : numpy.dtype
        Of the observations' and actions' floating-point spaces.
    jitter : float
        The standard deviation (m) of the start's perturbation (module docstring).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "formationlab_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 30,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: Scenario | str | os.PathLike[str],
        *,
        sensing: Sensing | None = None,
        faults: Faults | None = None,
        render_mode: str | None = None,
        contact_penalty: float = CONTACT_PENALTY,
        max_command: float | None = None,
        jitter: float | None = None,
        tolerances: Tolerances | None = None,
        observation: str = "flat",
        dtype: DTypeLike = np.float32,
    ) -> None:
        scenario = resolve_scenario(scenario)
        if observation not in OBSERVATIONS:
            raise ParameterError(
                f'observation must be "flat" (one Box vector) or "dict", got {observation!r}',
                key="observation",
            )
        try:
            self.dtype = np.dtype(dtype)
        except TypeError:
            self.dtype = np.dtype(object)
        if self.dtype not in (np.float32, np.float64):
            raise ParameterError(
                f"dtype must be numpy.float32 (the default) or numpy.float64, got {dtype!r}",
                key="dtype",
            )
        self.observation = observation
        sensing = getattr(scenario, "sensing", None) if sensing is None else sensing
        faults = getattr(scenario, "faults", None) if faults is None else faults
        if not isinstance(sensing, Sensing | None):
            raise ParameterError(f"sensing must be a Sensing, got {type(sensing).__name__}")
        if not isinstance(faults, Faults | None):
            raise ParameterError(f"faults must be Faults, got {type(faults).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ParameterError(
                f'render_mode must be None or "rgb_array", got {render_mode!r}', key="render_mode"
            )
        if not isinstance(tolerances, Tolerances | None):
            raise ParameterError(
                f"tolerances must be formationlab.outcomes.analysis.Tolerances, got {tolerances!r}"
            )
        dt = getattr(scenario.integrator, "dt", None)
        if dt is None:
            raise ParameterError(
                "the environment steps explicit Euler at the scenario's [simulation] dt; "
                f"the integrator {scenario.integrator.name!r} has no dt: use euler",
                key="simulation.integrator",
            )
        model = scenario.model
        heading_unicycle = isinstance(model, Unicycle) and model.mapping != NearIdentity.name
        if heading_unicycle and (scenario.marching or scenario.obstacles or scenario.safety):
            raise ParameterError(
                "the environment's unicycle actions (v, omega) pass marching, obstacles and "
                "a safety filter through the near-identity hand points: use mapping = "
                '"near-identity" for a scenario with them',
                key="robots.mapping",
            )
        self.scenario, self.render_mode = scenario, render_mode
        self.formation, self.model = scenario.formation, model
        self.sensing = sensing or Sensing()
        self.contact_penalty = nonnegative(contact_penalty, "contact_penalty")
        if jitter is None:
            jitter = JITTER_FRACTION * float(np.min(scenario.formation.distances))
        self.jitter = nonnegative(jitter, "jitter")
        self.tolerances = tolerances or Tolerances()
        self.dt = float(dt)
        self.n_steps = max(1, round(float(scenario.duration) / self.dt))
        if render_mode is not None and scenario.formation.dim == 3:
            raise ParameterError(
                'render_mode = "rgb_array" draws formations in the plane; this one is in '
                "space: leave render_mode None and watch it with `formationlab view`",
                key="render_mode",
            )
        self.system = closed_loop(scenario, sensing=sensing, faults=faults)
        try:  # the law's local form (the channel's and law_policy's)
            self.terms: KernelTerms = scenario.law.sensed_terms(self.formation)
        except ParameterError as exc:  # in space: the laws robots run on their measurements
            which = str(exc).split(";")[0]  # (the laws that do, named by the law's check)
            raise ParameterError(
                f"{which}; the environment's robots observe each other through the "
                f"measurement channel, so in space it takes those laws only, not "
                f"{scenario.law.name!r}: choose one of them in [controller]",
                key="controller.law",
            ) from None
        # unicycles are driven by (v, omega): through the near-identity transform, which
        # is exactly invertible, the model's own limits and kinematics step them
        self._driven = self.system
        if isinstance(model, Unicycle) and model.mapping != NearIdentity.name:
            twin = dataclasses.replace(model, mapping=NearIdentity.name)
            self._driven = dataclasses.replace(self.system, model=twin)
        n = self.formation.n
        self.possible_agents = [f"robot_{i + 1}" for i in range(n)]
        self.agent_index = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self.others = other_robots(n)
        rows = np.arange(n)[:, None]
        self.neighbours = self.formation.adjacency[rows, self.others].astype(np.int8)
        self._edges = self.formation.edges
        dim = self.formation.dim
        bound = action_bound(model, max_command, dim).astype(self.dtype)
        self.dict_space = observation_space(self.formation, model, self.dtype)
        flat = observation == "flat"
        self._obs_spaces = {
            a: spaces.flatten_space(self.dict_space)
            if flat
            else observation_space(self.formation, model, self.dtype)
            for a in self.possible_agents
        }
        self._act_spaces = {
            a: spaces.Box(-bound, bound, shape=bound.shape, dtype=self.dtype)
            for a in self.possible_agents
        }  # bound in self.dtype (a float64 bound in a float32 Box is warned about)
        self.state_space = spaces.Box(-np.inf, np.inf, shape=(n, len(model.names_in(dim))))
        self.seed: Seed | None = None
        self._root: int | None = None
        self._episode = 0
        self._x = np.asarray(scenario.x0, dtype=float)
        self._k = 0
        self._frames: Any = None  # AgentFrames: one figure for every render

    # ------------------------------------------------------------------ spaces

    def observation_space(self, agent: str) -> spaces.Box | spaces.Dict:
        return self._obs_spaces[self._name(agent)]

    def action_space(self, agent: str) -> spaces.Box:
        return self._act_spaces[self._name(agent)]

    def _name(self, agent: Any) -> str:
        if agent not in self.agent_index:
            raise ParameterError(
                f"unknown agent {agent!r}: the agents are robot_1 to robot_{self.formation.n}"
            )
        return agent

    # ------------------------------------------------------------------ episodes

    @property
    def own_distance(self) -> NDArray[np.float64] | None:
        """Each robot's own desired distances ``(E, 2)`` this episode (None: the formation's)."""
        od = self.channel.own_distance
        return None if od is None else od[0]

    @property
    def t(self) -> float:
        """The time of the current state, seconds."""
        return self._k * self.dt

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, NDArray]], dict[str, dict[str, Any]]]:
        """Start an episode (module docstring for the seeds); ``options`` are not used."""
        if seed is not None:
            self._root, self._episode = check_seed(seed), 0
        elif self._root is None:
            self._root, self._episode = int(np.random.SeedSequence().entropy), 0  # type: ignore[arg-type]
        assert self._root is not None
        self.seed = self._root if self._episode == 0 else (self._root, self._episode)
        self._episode += 1
        self.channel = Channel(
            self.sensing, self.formation, self.scenario.law, self.model, [self.seed], self.dt
        )
        self._x, self._k = self._start(self.seed), 0
        self.agents = list(self.possible_agents)
        self._observe()
        err = self._errors(self._x)
        return self._observations(), self._infos(err)

    def _start(self, seed: Seed) -> NDArray[np.float64]:
        x0 = np.asarray(self.scenario.x0, dtype=float)
        if self.jitter == 0:
            return x0.copy()
        entropy = [int(s) for s in (seed if isinstance(seed, tuple) else (seed,))]
        rng = np.random.default_rng(
            np.random.SeedSequence(entropy).spawn(5)[4]
        )  # not the channel's
        for _ in range(_JITTER_TRIES):
            x = x0.copy()
            dim = self.formation.dim
            x[:, :dim] += self.jitter * rng.standard_normal((self.formation.n, dim))
            try:
                return initial_state(self.formation, self.model, x)
            except FormationError:
                continue
        raise ParameterError(
            f"jitter = {self.jitter:g} m: {_JITTER_TRIES} jittered starts all put robots in "
            "contact; use a smaller jitter",
            key="jitter",
        )

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step every robot with its action (module docstring); all agents act together."""
        if not self.agents:
            raise RuntimeError("the episode has ended (or was never started): call reset()")
        a = self._actions(actions)
        x0, k, dt = self._x, self._k, self.dt
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            u = self._command(a, x0)
            x1 = x0 + dt * self._driven.rhs_commanded(x0[None], u[None], k * dt)[0]
        verdict = int(self.system.step_verdict(x0[None], x1[None])[0][0])
        end: dict[str, Any] = {}
        if verdict:
            status = Status.from_code(verdict)
            end = {
                "outcome": "collision", "status": str(status),
                "message": self.system.step_message(x0, x1, status, (k + 1) * dt, dt),
            }  # fmt: skip
            err = self._errors(x0)
            rewards = -err - self.contact_penalty
            done, cut = True, False
        else:
            self._x, self._k = x1, k + 1
            self._observe()
            err = self._errors(x1)
            rewards = -err
            p = self.model.points(x1)
            w = self.model.point_rates(x0, (x1 - x0) / dt)
            outcome = classify(self.formation, p, w, self.tolerances)
            done = outcome == "desired"
            cut = not done and self._k >= self.n_steps
            if done or cut:
                end = {"outcome": outcome}
        obs = self._observations()
        infos = self._infos(err, end)
        agents = self.agents
        if done or cut:
            self.agents = []
        return (
            obs,
            {a: float(rewards[i]) for i, a in enumerate(agents)},
            dict.fromkeys(agents, done),
            dict.fromkeys(agents, cut),
            infos,
        )

    def _actions(self, actions: Mapping[str, Any]) -> NDArray[np.float64]:
        if not isinstance(actions, Mapping):
            raise ParameterError(
                f"step takes a dict of actions by agent name, got {type(actions).__name__}"
            )
        unknown = sorted(set(actions) - set(self.agents), key=str)
        missing = [a for a in self.agents if a not in actions]
        if unknown or missing:
            what = f"unknown agents {unknown}" if unknown else f"no action for {missing}"
            raise ParameterError(f"step needs one action for each of {self.agents}: {what}")
        size = self._act_spaces[self.possible_agents[0]].shape
        out = np.empty((self.formation.n, *size))
        for a in self.agents:
            v = np.asarray(actions[a], dtype=float)
            if v.shape != size:
                raise ParameterError(
                    f"the action of {a} must have shape {size} (its command in its own frame), "
                    f"got shape {v.shape}"
                )
            out[self.agent_index[a]] = v
        return out

    def _command(self, a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The commands ``(n, d)`` the closed loop takes (common frame, at the law's points)."""
        world = lambda v: self.channel.world(v[None], x[None], _LIVE)[0]  # noqa: E731
        return common_commands(self.model, a, x, world)

    def _observe(self) -> None:
        z, seen = self.channel.observe(self._x[None], _LIVE, self._k)
        frames = self.channel.frames(self._x[None], _LIVE)  # angles, or rotations in space
        self._parts = observation_parts(self.model, self._x[None], z, seen, frames, self.others)

    def _observations(self) -> dict[str, Any]:
        parts = self._parts
        out: dict[str, Any] = {}
        if self.observation == "flat":
            flat = flat_observations(self.dict_space, parts, self.neighbours, self.dtype)[0]
            return {a: flat[self.agent_index[a]] for a in self.agents}
        seen = parts["seen"][0].astype(np.int8)
        own = {k: v[0].astype(self.dtype) for k, v in parts.items() if k != "seen"}
        for a in self.agents:
            i = self.agent_index[a]
            out[a] = {"seen": seen[i], "neighbour": self.neighbours[i].copy()}
            out[a].update({key: v[i] for key, v in own.items()})
        return out

    def as_dict(self, observation: Any) -> dict[str, NDArray]:
        """One agent's observation as the ``Dict``'s parts, whichever ``observation`` form."""
        if self.observation == "dict":
            return observation
        return spaces.unflatten(self.dict_space, np.asarray(observation))

    def _errors(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Each robot's local formation error (:func:`.rewards.robot_errors`); ``(n,)``."""
        return robot_errors(self.formation, self.model.points(x))

    def _infos(self, err: NDArray, end: dict[str, Any] | None = None) -> dict[str, dict[str, Any]]:
        return {
            a: {
                "t": self.t,
                "seed": self.seed,
                "error": float(err[self.agent_index[a]]),
                **(end or {}),
            }
            for a in self.agents
        }

    # ------------------------------------------------------------------ the rest of the API

    def state(self) -> NDArray[np.float64]:
        """The closed loop's state ``(n, k)`` (the model's columns: positions first)."""
        return self._x.copy()

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB frame ``(H, W, 3)`` of the robots with ``render_mode="rgb_array"``; else None."""
        if self.render_mode is None:
            return None
        if self._frames is None:
            from ..plotting.agent_frame import AgentFrames  # matplotlib: when rendering (start-up)

            self._frames = AgentFrames(self.formation, model=self.model)
        return self._frames(self._x, self.t)

    def close(self) -> None:
        """Let go of the figure the frames are drawn on (the next render makes another)."""
        self._frames = None


def parallel_env(
    scenario: Scenario | str | os.PathLike[str],
    *,
    sensing: Sensing | None = None,
    faults: Faults | None = None,
    render_mode: str | None = None,
    contact_penalty: float = CONTACT_PENALTY,
    max_command: float | None = None,
    jitter: float | None = None,
    tolerances: Tolerances | None = None,
    observation: str = "flat",
    dtype: DTypeLike = np.float32,
) -> FormationEnv:
    """The robots of ``scenario`` as the agents of a PettingZoo ``ParallelEnv``.

    Parameters
    ----------
    scenario : Scenario, str or pathlib.Path
        A scenario, the path of a scenario file (``str`` or ``Path``) or a scenario's TOML
        text (:func:`formationlab.io.scenario.resolve_scenario`).
    sensing, faults : Sensing, Faults, optional
        Override the scenario's ``[sensing]`` and ``[faults]`` (default: the scenario's;
        without them the paper's exact, common-frame sensing and no faults).
    render_mode : {None, "rgb_array"}
        ``"rgb_array"``: :meth:`FormationEnv.render` returns an RGB frame.
    contact_penalty : float
        Reward lost by every robot at a step the contact rule rejects (>= 0).
    max_command : float, optional
        The action bound of a model without a limit (default :data:`MAX_COMMAND`).
    jitter : float, optional
        Standard deviation (m) of the Gaussian perturbation of the start, per coordinate of
        each position, drawn from the episode's seed (default :data:`JITTER_FRACTION` of
        the smallest desired distance; 0: the scenario's initial state every episode).
    tolerances : Tolerances, optional
        When the formation counts as reached (:mod:`formationlab.outcomes.analysis`).
    observation : {"flat", "dict"}
        One ``Box`` vector per agent (the default), or the ``Dict`` of its parts.
    dtype : numpy.float32 or numpy.float64
        Of the observations' and actions' floating-point spaces (default float32).

    Returns
    -------
    FormationEnv
        Observations, actions, rewards and the end of an episode: module docstring of
        :mod:`formationlab.envs.pettingzoo`.
    """
    return FormationEnv(
        scenario, sensing=sensing, faults=faults, render_mode=render_mode,
        contact_penalty=contact_penalty, max_command=max_command, jitter=jitter,
        tolerances=tolerances, observation=observation, dtype=dtype,
    )  # fmt: skip


def env(scenario: Scenario | str | os.PathLike[str], **kwargs: Any) -> Any:
    """The environment of :func:`parallel_env` as a PettingZoo ``AECEnv`` (agents in turn).

    PettingZoo's ``parallel_to_aec`` of ``parallel_env(scenario, **kwargs)``; the
    conventional ``env()`` factory of a PettingZoo environment module.
    """
    return parallel_to_aec(parallel_env(scenario, **kwargs))


if hasattr(pettingzoo, "register"):  # PettingZoo 1.27 and later: pettingzoo.make
    for _kind, _factory in (("parallel", "parallel_env"), ("aec", "env")):
        if ENV_ID not in getattr(pettingzoo, f"{_kind}_registry"):
            pettingzoo.register(_kind, ENV_ID, entry_point=f"{__name__}:{_factory}")
