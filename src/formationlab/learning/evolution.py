"""Training the learned law with CMA-ES (Hansen's evolution strategy, the ``cma`` package).

Reference: N. Hansen, "The CMA Evolution Strategy: A Tutorial", arXiv:1604.00772, 2016;
software: N. Hansen et al., ``pycma`` (https://github.com/CMA-ES/pycma). CMA-ES searches
the flat vector of the network's parameters (:meth:`Network.flat`) and needs no gradient,
no GPU and no torch: each candidate is scored by a batched rollout (:mod:`.rollout`) of
``batch`` formations from random starts drawn as a study draws them
(:func:`formationlab.studies.sampling.trial_initial_states`), all candidates of a
generation on the same starts (common random numbers), new starts every generation.
The score is the mean :func:`~.reward.episode_reward`; CMA-ES minimises its negative.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..controllers.network import Network, parameter_count
from ..controllers.policy import FEATURES, OUTPUTS, neighbourhoods, policy_control
from ..errors import ParameterError, require_extra
from ..formation.spec import Formation
from ..integrators.base import steps_for
from ..studies.config import BoxInitial, GaussianInitial
from ..studies.sampling import trial_initial_states
from ..validation import check_fields, whole
from ..validation import seed as check_seed
from .reward import episode_reward
from .rollout import rollout

__all__ = ["CURVE_COLUMNS", "Training", "TrainingConfig", "train"]

#: the columns of the training curve, one row per generation
CURVE_COLUMNS = ("generation", "evaluations", "best", "mean", "centre", "sigma")


@dataclass(frozen=True, kw_only=True)
class TrainingConfig:
    """How to train (docs/learning.md).

    Parameters
    ----------
    generations : int
        CMA-ES generations (default 40).
    population : int
        Candidates per generation (default 12).
    batch : int
        Formations each candidate is scored on per generation (default 48).
    hidden : tuple of int
        Widths of the hidden layers (default two of 16 tanh units).
    sigma0 : float
        CMA-ES's initial step size around the all-zero network (default 0.5).
    dt, duration : float
        Euler step and length of a training rollout, seconds (defaults 0.02 and 10).
    seed : int
        Seeds CMA-ES and the starts (generation ``g`` runs trials ``g batch ... (g + 1)
        batch - 1`` of this seed).
    """

    generations: int = 40
    population: int = 12
    batch: int = 48
    hidden: tuple[int, ...] = (16, 16)
    sigma0: float = 0.5
    dt: float = 0.02
    duration: float = 10.0
    seed: int = 0

    def __post_init__(self) -> None:
        check_fields(self, positive=("sigma0", "dt", "duration"))
        for key in ("generations", "batch"):
            whole(getattr(self, key), key)
        if whole(self.population, "population") < 2:
            raise ParameterError(
                f"population must be at least 2, got {self.population}", key="population"
            )
        check_seed(self.seed)
        object.__setattr__(self, "hidden", tuple(whole(h, "hidden") for h in self.hidden))

    @property
    def sizes(self) -> tuple[int, ...]:
        """The network's layer widths, inputs first."""
        return (FEATURES, *self.hidden, OUTPUTS)


class Training(NamedTuple):
    """What :func:`train` returns.

    Attributes
    ----------
    network : Network
        The trained network: the mean of CMA-ES's final distribution.
    curve : dict of ndarray
        Per generation (:data:`CURVE_COLUMNS`): its number (1-based), evaluations so far,
        the best and the mean reward of its candidates, the reward of the distribution's
        mean (``centre``) on the same starts, and CMA-ES's step size.
    """

    network: Network
    curve: dict[str, NDArray[np.float64]]


def train(
    formation: Formation,
    initial: BoxInitial | GaussianInitial,
    config: TrainingConfig,
    *,
    center: NDArray[np.float64] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Training:
    """Train the learned law on ``formation`` from starts drawn from ``initial``.

    Parameters
    ----------
    formation : Formation
        In the plane, with its desired distances and orientation.
    initial : BoxInitial or GaussianInitial
        The study's distribution of starts (``[study] initial``).
    config : TrainingConfig
    center : ndarray, shape (n, 2), optional
        Centre of gaussian starts.
    progress : callable, optional
        Called as ``progress(generation, generations)`` after each generation.
    """
    cma: Any = require_extra("learn", ("cma",), "training a policy (CMA-ES)")

    hoods = neighbourhoods(formation)
    sizes = config.sizes
    steps = steps_for(config.duration, config.dt)
    options: dict[str, Any] = {
        "popsize": config.population,
        "seed": config.seed + 1,  # cma reads 0 as "seed from the clock"
        "verbose": -9,
        "verb_disp": 0,
        "verb_log": 0,
    }
    es = cma.CMAEvolutionStrategy(np.zeros(parameter_count(sizes)), config.sigma0, options)

    def scores(flat: NDArray[np.float64], q0: NDArray[np.float64]) -> NDArray[np.float64]:
        """Mean reward of each of the ``(P, count)`` candidates, all in one rollout."""
        nets = Network.from_flat(sizes, flat)
        q = np.broadcast_to(q0, (flat.shape[0], *q0.shape))
        field = partial(policy_control, nets, hoods)
        ended = rollout(field, formation, q, dt=config.dt, steps=steps)
        return np.asarray(np.mean(episode_reward(formation, ended), axis=-1))

    rows: list[tuple[float, ...]] = []
    for g in range(config.generations):
        trials = np.arange(g * config.batch, (g + 1) * config.batch)
        q0 = trial_initial_states(formation, initial, config.seed, trials, center=center)
        candidates = es.ask()
        rewards = scores(np.asarray(candidates), q0)
        es.tell(candidates, list(-rewards))
        (centre,) = scores(np.asarray(es.mean)[None, :], q0)
        rows.append((g + 1, es.countevals, rewards.max(), rewards.mean(), centre, es.sigma))
        if progress is not None:
            progress(g + 1, config.generations)
    curve = {name: np.array([r[c] for r in rows], dtype=float)
             for c, name in enumerate(CURVE_COLUMNS)}  # fmt: skip
    return Training(network=Network.from_flat(sizes, np.asarray(es.mean)), curve=curve)
