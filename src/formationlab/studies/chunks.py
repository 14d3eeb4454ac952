"""Chunks: a fixed number of consecutive trials of one group, the unit of work.

A :class:`ChunkTask` is picklable (it is sent to worker processes and dask
workers); :func:`run_chunk` draws the chunk's initial states
(:mod:`formationlab.studies.sampling`), runs the batched kernel
:func:`formationlab.studies.batch.run_batch` on them, settles the trials the
kernel leaves ``not-converged`` under a switching law if ``[study.settle]`` asks
for it (:func:`settle_trials`), and returns one row per trial (the columns of
``trials.parquet``, see :mod:`formationlab.io.trials`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..controllers import Law
from ..equilibria.search import settle as settle_batch
from ..formation.spec import Formation
from ..integrators import ImplicitEuler
from ..models import RobotModel, SingleIntegrator
from ..outcomes.analysis import Tolerances
from ..outcomes.batch import BatchResult
from ..outcomes.rigid_motion import RigidMotion
from .batch import batch_backend, run_batch
from .config import BoxInitial, GaussianInitial, SettleModel, StudyConfig
from .groups import Group
from .sampling import model_initial_states, trial_initial_states

__all__ = ["ChunkTask", "motion_columns", "plan_chunks", "run_chunk", "settle_trials"]


@dataclass(frozen=True, kw_only=True, eq=False)
class ChunkTask:
    """Trials ``start <= t < stop`` of one group: one unit of work (picklable)."""

    group: Group
    chunk: int
    start: int
    stop: int
    seed: int
    initial: BoxInitial | GaussianInitial
    center: NDArray[np.float64] | None
    dt: float
    duration: float
    tolerances: Tolerances
    backend: Literal["numba", "numpy"]
    sweep_keys: tuple[str, ...] = ()
    settle: SettleModel = field(default_factory=SettleModel)
    model: RobotModel = field(default_factory=SingleIntegrator)
    obstacles: tuple[Any, ...] = ()
    safety: Any = None

    @property
    def id(self) -> str:
        """``g003-c000012``: group and chunk number, the chunk's file name."""
        return f"g{self.group.index:03d}-c{self.chunk:06d}"

    @property
    def size(self) -> int:
        return self.stop - self.start


def plan_chunks(
    groups: list[Group],
    config: StudyConfig,
    *,
    seed: int,
    dt: float,
    duration: float,
    center: ArrayLike | None = None,
    model: RobotModel | None = None,
    obstacles: tuple[Any, ...] = (),
    safety: Any = None,
) -> list[ChunkTask]:
    """Cut every group's ``config.trials`` trials into chunks of ``config.chunk_size``.

    ``obstacles`` and ``safety`` (a :class:`~formationlab.safety.SafetyFilter`) go to
    every chunk.
    """
    model = model or SingleIntegrator()
    c = None if center is None else np.asarray(center, dtype=float)
    tasks = []
    n, size = config.trials, config.chunk_size
    for g in groups:
        for k in range(math.ceil(n / size)):
            tasks.append(
                ChunkTask(
                    group=g,
                    chunk=k,
                    start=k * size,
                    stop=min((k + 1) * size, n),
                    seed=seed,
                    initial=config.initial,
                    center=c,
                    dt=dt,
                    duration=duration,
                    tolerances=config.tol,
                    backend=batch_backend(
                        config.backend,
                        obstacles,
                        safety,
                        g.sensed,
                        model,
                        g.formation.dim,
                        laws=(g.law,),
                    )[0],
                    sweep_keys=tuple(config.sweep),
                    settle=config.settle,
                    model=model,
                    obstacles=obstacles,
                    safety=safety,
                )
            )
    return tasks


def run_chunk(task: ChunkTask) -> pd.DataFrame:
    """Run one chunk; one row per trial (columns: see :mod:`formationlab.io.trials`)."""
    g = task.group
    f = g.formation
    trials = np.arange(task.start, task.stop, dtype=np.int64)
    q0 = trial_initial_states(
        f, task.initial, task.seed, trials, center=task.center, obstacles=task.obstacles
    )
    x0 = model_initial_states(f, task.model, q0, task.seed, trials)
    res = run_batch(
        f,
        g.law,
        x0,
        dt=task.dt,
        duration=task.duration,
        tolerances=task.tolerances,
        backend=task.backend,
        model=task.model,
        obstacles=task.obstacles,
        safety=task.safety,
        sensing=g.sensing,
        faults=g.faults,
        seeds=[(task.seed, int(t)) for t in trials] if g.sensed else None,
    )
    outcome = np.asarray(res.outcome, dtype=object)
    # settling steps the law alone: not the closed loop with obstacles or a filter
    plain = not task.obstacles and (task.safety is None or not task.safety.enabled)
    plain = plain and not g.sensed  # nor a sensed one
    settle = task.settle if plain else SettleModel(enabled=False)
    settled, settled_outcome = settle_trials(
        f, g.law, res.q_final, outcome, settle=settle, tolerances=task.tolerances
    )
    cols: dict[str, Any] = {
        "group": np.full(trials.size, g.index, dtype=np.int64),
        "trial": trials,
        "seed": np.full(trials.size, task.seed, dtype=np.int64),
        "law": np.full(trials.size, g.law.name, dtype=object),
    }
    for key in task.sweep_keys:
        cols[key] = np.full(trials.size, g.parameters.get(key, np.nan), dtype=float)
    cols.update(
        outcome=outcome,
        settled=settled,
        settled_outcome=settled_outcome,
        max_distance_error=np.asarray(res.max_distance_error, dtype=float),
        max_bearing_error=np.asarray(
            np.full(trials.size, np.nan)
            if res.max_bearing_error is None
            else res.max_bearing_error,
            dtype=float,
        ),
        converged_time=np.asarray(res.converged_time, dtype=float),
        net_speed=np.asarray(res.net_speed, dtype=float),
        min_clearance=np.asarray(res.min_clearance, dtype=float),
        **safety_columns(res),
        steps=np.asarray(res.steps, dtype=np.int64),
        **motion_columns(res.motion),
    )
    axes = "xyz"[: f.dim]  # the position columns: x, y (and z in space) per robot
    for i in range(f.n):
        for a, name in enumerate(axes):
            cols[f"{name}{i + 1}_init"] = q0[:, i, a]
    if "theta" in type(task.model).state_names:
        for i in range(f.n):
            cols[f"theta{i + 1}_init"] = x0[:, i, 2]
    qf = np.asarray(res.q_final, dtype=float)
    for i in range(f.n):
        for a, name in enumerate(axes):
            cols[f"{name}{i + 1}"] = qf[:, i, a]
    return pd.DataFrame(cols)


def safety_columns(res: BatchResult) -> dict[str, NDArray[Any]]:
    """The clearance and safety-filter columns of ``trials.parquet`` (:mod:`formationlab.io.
    trials`): ``min_robot_clearance``, ``min_obstacle_clearance`` (NaN without obstacles),
    ``min_pair_distance`` (NaN without a filter) and ``below_safety_distance``."""
    B = len(res.min_clearance)
    obst = res.min_obstacle_clearance
    obst = np.full(B, np.nan) if obst is None else np.asarray(obst, dtype=float)
    return {
        "min_robot_clearance": np.asarray(
            res.min_clearance if res.min_robot_clearance is None else res.min_robot_clearance,
            dtype=float,
        ),
        "min_obstacle_clearance": np.where(np.isposinf(obst), np.nan, obst),
        "min_pair_distance": np.asarray(
            np.full(B, np.nan) if res.min_pair_distance is None else res.min_pair_distance,
            dtype=float,
        ),
        "below_safety_distance": np.asarray(
            np.zeros(B, bool) if res.below_safety_distance is None else res.below_safety_distance,
            dtype=bool,
        ),
    }


def motion_columns(motion: RigidMotion) -> dict[str, NDArray[np.float64]]:
    """The rigid-motion columns of ``trials.parquet`` (:mod:`formationlab.io.trials`); in
    space also ``drift_vz`` and ``drift_cz`` (the centre is the screw axis's point nearest
    the centroid) and the axis, ``drift_ax``, ``drift_ay``, ``drift_az``."""
    axes = list(enumerate("xyz"[: motion.velocity.shape[-1]]))
    return {
        **{f"drift_v{a}": np.asarray(motion.velocity[:, k], dtype=float) for k, a in axes},
        "drift_speed": np.asarray(motion.speed, dtype=float),
        "drift_omega": np.asarray(motion.omega, dtype=float),
        **{f"drift_c{a}": np.asarray(motion.centre[:, k], dtype=float) for k, a in axes},
        **(
            {}
            if motion.axis is None
            else {f"drift_a{a}": np.asarray(motion.axis[:, k], dtype=float) for k, a in axes}
        ),
        "shape_rate": np.asarray(motion.shape_rate, dtype=float),
    }


def settle_trials(
    formation: Formation,
    law: Law,
    q_final: NDArray[np.float64],
    outcome: NDArray[Any],
    *,
    settle: SettleModel,
    tolerances: Tolerances,
) -> tuple[NDArray[np.bool_], NDArray[np.object_]]:
    """Settle the kernel's ``not-converged`` trials of a switching law with implicit Euler.

    Explicit Euler chatters across an attractive switching surface, so a trial
    at rest at a sliding-mode (Filippov) equilibrium never passes the kernel's
    convergence test. Implicit Euler in the switching weights lands on the
    surfaces and slides (:mod:`formationlab.integrators.implicit`): each such
    trial is continued from its final state with ``ImplicitEuler(dt=settle.dt)``
    until its robots move slower than ``tolerances.speed`` (displacement per
    step over ``dt``) or for ``settle.duration`` seconds, and classified again
    (:func:`formationlab.equilibria.settle`). The chunk's trials are stepped as
    one batch; every trial stops on its own, and the batched implicit-Euler step
    equals stepping each member alone (``tests/test_integrators.py``), so a
    label does not depend on the other trials of its chunk.

    Parameters
    ----------
    formation : Formation
    law : Law
        A smooth law (``law.smooth``) has no switching surface: its trials are
        never settled.
    q_final : ndarray, shape (B, n, 2)
        The kernel's final positions.
    outcome : ndarray of str, shape (B,)
        The kernel's outcomes.
    settle : SettleModel
        ``[study.settle]``; nothing is settled unless ``settle.enabled``.
    tolerances : Tolerances
        Of the classification; ``speed`` also ends the settling.

    Returns
    -------
    settled : ndarray of bool, shape (B,)
        The trials that were settled.
    settled_outcome : ndarray of str (object), shape (B,)
        Their outcome after settling; ``outcome`` for the others.
    """
    outcome = np.asarray(outcome, dtype=object)
    settled = outcome == "not-converged"
    if not settle.enabled or law.smooth:
        settled[:] = False
    new = outcome.copy()
    which = np.flatnonzero(settled)
    if which.size:
        res = settle_batch(
            formation,
            law,
            q_final[which],
            duration=settle.duration,
            integrator=ImplicitEuler(dt=settle.dt),
            speed=tolerances.speed,
            tolerances=tolerances,
        )
        new[which] = [str(x) for x in res.outcome]
    return settled, new
