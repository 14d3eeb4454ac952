"""Monte-Carlo studies: many random starts, several laws, a parameter sweep.

:func:`run_study` runs ``trials`` random initial states (see
:mod:`formationlab.studies.sampling`) for every *group*, a group being one law
at one point of the sweep (:func:`study_groups`). The trials of a group are
cut into chunks of ``chunk_size``; each chunk is one call of the batched kernel
:func:`formationlab.studies.batch.run_batch` and one unit of work. By default
chunks run one after the other in this process, the numba kernel spreading
each over every core; ``workers > 1`` runs them in a pool of single-threaded
worker processes instead, and ``scheduler`` on a dask.distributed cluster
(``"local"``: a LocalCluster of ``workers`` single-threaded processes on this
machine; otherwise the scheduler's address).

Determinism: trial ``t``'s initial state depends on ``(seed, t)`` only
(:mod:`formationlab.studies.sampling`) and every trial is simulated on its own,
so the table of trials is the same whatever the number of workers, the chunk
size or the order in which chunks finish.

Resume: every finished chunk is handed to ``store.save`` as soon as it arrives
(the command line's store writes it atomically under ``DIR/chunks/``); with
``resume=True`` chunks that ``store.load`` returns are not run again.

This module touches no files: the store does.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import time
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context
from typing import Any, Protocol

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..analysis import OUTCOMES, Tolerances
from ..controllers import LAWS, Law
from ..errors import ParameterError, UserInputError
from ..spec import Formation
from .config import BoxInitial, GaussianInitial, StudyConfig
from .sampling import trial_initial_states
from .summary import summarize_groups

__all__ = [
    "REPULSION_KEYS",
    "ROBOT_KEYS",
    "ChunkStore",
    "ChunkTask",
    "Group",
    "StudyResult",
    "plan_chunks",
    "run_chunk",
    "run_study",
    "study_groups",
    "study_identity",
]

#: Sweep keys that set a field of the law's :class:`~formationlab.controllers.Repulsion`.
REPULSION_KEYS = ("eta", "influence")
#: Sweep keys that set a property of the robots.
ROBOT_KEYS = ("diameter",)


# ----------------------------------------------------------------------------- groups


@dataclass(frozen=True, kw_only=True, eq=False)
class Group:
    """One law at one point of the sweep.

    Attributes
    ----------
    index : int
        0-based position in the study (the ``group`` column of the trials).
    law : Law
        The law with the point's parameters.
    formation : Formation
        The formation with the point's robot parameters (``diameter``).
    parameters : dict
        The swept parameters that apply to this law, ``{key: value}``.
    """

    index: int
    law: Law
    formation: Formation
    parameters: dict[str, float]

    def describe(self) -> dict[str, Any]:
        """JSON-ready: ``law``, ``parameters`` and the law's full ``law_parameters``."""
        return {
            "group": self.index,
            "law": self.law.name,
            "parameters": dict(self.parameters),
            "law_parameters": dataclasses.asdict(self.law),
            "diameters": self.formation.diameters.tolist(),
        }


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls) if f.init}


def _base_law(name: str, law: Law) -> Law:
    """Law ``name`` with the parameters it shares (by name) with the scenario's ``law``."""
    if name == law.name:
        return law
    cls = LAWS[name]
    shared = _fields(cls) & _fields(type(law))
    return cls(**{k: getattr(law, k) for k in shared})


def _applies(key: str, cls: type) -> bool:
    names = _fields(cls)
    return key in ROBOT_KEYS or key in names or (key in REPULSION_KEYS and "repulsion" in names)


def _apply(law: Law, formation: Formation, point: dict[str, float]) -> tuple[Law, Formation]:
    names = _fields(type(law))
    params: dict[str, Any] = {k: v for k, v in point.items() if k in names}
    rep = {k: v for k, v in point.items() if k in REPULSION_KEYS and k not in names}
    if rep:
        params["repulsion"] = dataclasses.replace(law.repulsion, **rep)  # type: ignore[attr-defined]
    if "diameter" in point:
        formation = formation.with_diameters(point["diameter"])
    return law.with_params(**params) if params else law, formation


def study_groups(formation: Formation, law: Law, config: StudyConfig) -> list[Group]:
    """The groups of a study: every law of ``config.laws`` at every point of its sweep.

    A law runs the product of the sweep lists of the keys that apply to it
    (its dataclass fields, ``eta``/``influence`` of its repulsion, ``diameter``).

    Raises
    ------
    ParameterError
        An unknown law, a sweep key that applies to none of the laws, or a sweep
        value a law or the formation rejects.
    """
    names = config.laws or (law.name,)
    for name in names:
        if name not in LAWS:
            raise ParameterError(
                f"study.laws: unknown law {name!r}; known laws: {', '.join(sorted(LAWS))}"
            )
    keys = list(config.sweep)
    for key in keys:
        if not any(_applies(key, LAWS[name]) for name in names):
            takes = sorted(set().union(*(_fields(LAWS[n]) for n in names)) - {"repulsion"})
            raise ParameterError(
                f"study.sweep.{key}: no law of the study ({', '.join(names)}) has a parameter "
                f"{key!r}; sweepable: {', '.join([*takes, *REPULSION_KEYS, *ROBOT_KEYS])}"
            )
    groups: list[Group] = []
    for name in names:
        base = _base_law(name, law)
        mine = [k for k in keys if _applies(k, type(base))]
        for values in itertools.product(*(config.sweep[k] for k in mine)):
            point = {k: float(v) for k, v in zip(mine, values, strict=True)}
            try:
                g_law, g_formation = _apply(base, formation, point)
            except UserInputError as exc:
                where = ", ".join(f"{k} = {v:g}" for k, v in point.items())
                raise ParameterError(f"study.sweep ({name}, {where}): {exc}") from None
            groups.append(
                Group(index=len(groups), law=g_law, formation=g_formation, parameters=point)
            )
    return groups


# ----------------------------------------------------------------------------- chunks


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
    backend: str
    sweep_keys: tuple[str, ...] = ()

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
) -> list[ChunkTask]:
    """Cut every group's ``config.trials`` trials into chunks of ``config.chunk_size``."""
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
                    backend=config.backend,
                    sweep_keys=tuple(config.sweep),
                )
            )
    return tasks


def run_chunk(task: ChunkTask) -> pd.DataFrame:
    """Run one chunk; one row per trial (columns: see :mod:`formationlab.io.trials`)."""
    from .batch import run_batch

    g = task.group
    f = g.formation
    trials = np.arange(task.start, task.stop, dtype=np.int64)
    q0 = trial_initial_states(f, task.initial, task.seed, trials, center=task.center)
    res = run_batch(
        f,
        g.law,
        q0,
        dt=task.dt,
        duration=task.duration,
        tolerances=task.tolerances,
        backend=task.backend,
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
        outcome=np.asarray(res.outcome, dtype=object),
        max_distance_error=np.asarray(res.max_distance_error, dtype=float),
        converged_time=np.asarray(res.converged_time, dtype=float),
        min_clearance=np.asarray(res.min_clearance, dtype=float),
        steps=np.asarray(res.steps, dtype=np.int64),
    )
    for i in range(f.n):
        cols[f"x{i + 1}_init"] = q0[:, i, 0]
        cols[f"y{i + 1}_init"] = q0[:, i, 1]
    qf = np.asarray(res.q_final, dtype=float)
    for i in range(f.n):
        cols[f"x{i + 1}"] = qf[:, i, 0]
        cols[f"y{i + 1}"] = qf[:, i, 1]
    return pd.DataFrame(cols)


# ----------------------------------------------------------------------------- execution


class ChunkStore(Protocol):
    """Where finished chunks are kept (:class:`formationlab.io.trials.ChunkFolder`)."""

    def load(self, chunk_id: str) -> pd.DataFrame | None: ...

    def save(self, chunk_id: str, frame: pd.DataFrame) -> None: ...


def _worker_init() -> None:  # pragma: no cover - runs in the pool's processes
    # One process per core: keep each kernel on one thread (read when numba loads).
    os.environ["NUMBA_NUM_THREADS"] = "1"


def _in_process(tasks: list[ChunkTask], workers: int) -> Iterator[tuple[ChunkTask, pd.DataFrame]]:
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            yield t, run_chunk(t)
        return
    ctx = get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=_worker_init
    ) as pool:
        futures = {pool.submit(run_chunk, t): t for t in tasks}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _on_dask(
    tasks: list[ChunkTask], scheduler: str, workers: int | None
) -> Iterator[tuple[ChunkTask, pd.DataFrame]]:
    try:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed
    except ImportError:  # pragma: no cover - depends on the installation
        raise ParameterError(
            "--scheduler needs dask.distributed: pip install 'formationlab[distributed]'"
        ) from None
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env={"NUMBA_NUM_THREADS": "1"},
        )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ParameterError(
                f"cannot reach the dask scheduler at {scheduler!r} ({exc}); check the address "
                '(e.g. "tcp://host:8786") or use --scheduler local'
            ) from None
    run = uuid.uuid4().hex[:8]
    try:
        futures = {}
        for t in tasks:
            fut = client.submit(run_chunk, t, key=f"formationlab-{run}-{t.id}", pure=False)
            futures[fut.key] = (fut, t)
        for fut in dask_completed([f for f, _ in futures.values()]):
            yield futures[fut.key][1], fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ----------------------------------------------------------------------------- the study


@dataclass(frozen=True, kw_only=True, eq=False)
class StudyResult:
    """What :func:`run_study` returns.

    Attributes
    ----------
    trials : DataFrame
        One row per trial, sorted by group and trial.
    summary : dict
        JSON-ready: ``groups`` (:func:`~formationlab.studies.summary.summarize_groups`),
        ``trial_steps``, ``wall_time_s`` and the study's settings.
    groups : list of Group
    """

    trials: pd.DataFrame
    summary: dict[str, Any]
    groups: list[Group] = field(default_factory=list)


def study_identity(
    groups: list[Group],
    config: StudyConfig,
    *,
    seed: int,
    dt: float,
    duration: float,
    center: ArrayLike | None = None,
) -> dict[str, Any]:
    """Everything the trials depend on, JSON-ready, with its SHA-256 ``fingerprint``.

    Two runs with the same identity produce the same chunks; ``--resume`` refuses
    to mix chunks of different identities.
    """
    h = hashlib.sha256()
    for g in groups:
        f = g.formation
        for arr in (f.diameters, f.edges, f.distances, f.alpha, f.template):
            h.update(b"-" if arr is None else np.ascontiguousarray(arr).tobytes())
    if center is not None:
        h.update(np.ascontiguousarray(center, dtype=float).tobytes())
    ident = {
        "seed": int(seed),
        "trials": config.trials,
        "chunk_size": config.chunk_size,
        "initial": config.initial.model_dump(mode="json"),
        "tolerances": config.tolerances.model_dump(mode="json"),
        "backend": config.backend,
        "dt": float(dt),
        "duration": float(duration),
        "groups": [g.describe() for g in groups],
        "formations": h.hexdigest(),
    }
    text = json.dumps(ident, sort_keys=True, default=float)
    ident["fingerprint"] = hashlib.sha256(text.encode()).hexdigest()[:16]
    return ident


def run_study(
    formation: Formation,
    law: Law,
    config: StudyConfig,
    *,
    seed: int,
    dt: float,
    duration: float,
    center: ArrayLike | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    store: ChunkStore | None = None,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> StudyResult:
    """Run a Monte-Carlo study.

    Parameters
    ----------
    formation : Formation
        The formation (the sweep may change its diameters).
    law : Law
        The scenario's law; other laws of ``config.laws`` take its parameters by name.
    config : StudyConfig
        The ``[study]`` table.
    seed : int
        Seed of the study (>= 0); trial ``t`` uses ``SeedSequence(seed, spawn_key=(t,))``.
    dt, duration : float
        Euler step and simulated time per trial (config values take precedence).
    center : array_like, shape (n, 2), optional
        Centre of a gaussian initial distribution (the template, else the scenario's
        positions).
    scheduler : str, optional
        ``"local"`` (a dask LocalCluster of ``workers`` processes, default one per core)
        or the address of a dask scheduler. Without it, chunks run in this process
        (the numba kernel uses every core) or, with ``workers > 1``, in a pool of
        ``workers`` single-threaded processes.
    workers : int, optional
        Number of worker processes.
    store : ChunkStore, optional
        Receives every finished chunk; with ``resume`` it also provides finished ones.
    resume : bool
        Skip the chunks ``store`` already holds.
    progress : callable, optional
        Called as ``progress(done_trials, total_trials)`` after each chunk.

    Returns
    -------
    StudyResult
    """
    if not isinstance(seed, int | np.integer) or seed < 0 or seed >= 2**63:
        raise ParameterError(f"--seed must be a whole number in [0, 2**63), got {seed!r}")
    if workers is not None and workers < 1:
        raise ParameterError(f"--workers must be >= 1, got {workers}")
    if resume and store is None:
        raise ParameterError("resume needs a store of finished chunks")
    dt = float(config.dt or dt)
    duration = float(config.duration or duration)
    if not (dt > 0 and duration > 0 and math.isfinite(dt) and math.isfinite(duration)):
        raise ParameterError(f"dt and duration must be > 0, got dt={dt}, duration={duration}")
    if isinstance(config.initial, GaussianInitial):
        if center is None:
            center = formation.template
        if center is None:
            raise ParameterError("a gaussian initial distribution needs a centre shape")
    groups = study_groups(formation, law, config)
    tasks = plan_chunks(groups, config, seed=int(seed), dt=dt, duration=duration, center=center)
    total = sum(t.size for t in tasks)
    start = time.perf_counter()
    frames: dict[str, pd.DataFrame] = {}
    done = 0
    if resume:
        assert store is not None
        for t in tasks:
            old = store.load(t.id)
            if old is not None:
                frames[t.id] = old
                done += t.size
    resumed = len(frames)
    if progress is not None:
        progress(done, total)
    todo = [t for t in tasks if t.id not in frames]
    if scheduler is not None:
        stream = _on_dask(todo, scheduler, workers)
    else:
        stream = _in_process(todo, workers or 1)
    for task, frame in stream:
        if store is not None:
            store.save(task.id, frame)
        frames[task.id] = frame
        done += task.size
        if progress is not None:
            progress(done, total)
    wall = time.perf_counter() - start
    trials = pd.concat([frames[t.id] for t in tasks], ignore_index=True)
    trials = trials.sort_values(["group", "trial"], kind="stable", ignore_index=True)
    steps = int(trials["steps"].sum())
    summary = {
        "seed": int(seed),
        "trials_per_group": config.trials,
        "chunk_size": config.chunk_size,
        "chunks": {"total": len(tasks), "resumed": resumed},
        "dt": dt,
        "duration": duration,
        "initial": config.initial.model_dump(mode="json"),
        "tolerances": config.tolerances.model_dump(mode="json"),
        "backend": config.backend,
        "laws": list(config.laws or (law.name,)),
        "sweep": {k: list(v) for k, v in config.sweep.items()},
        "outcomes": list(OUTCOMES),
        "groups": summarize_groups(trials, [g.describe() for g in groups]),
        "trial_steps": steps,
        "wall_time_s": wall,
        "trial_steps_per_s": steps / wall if wall > 0 and resumed == 0 else None,
        "scheduler": scheduler,
        "workers": workers,
    }
    return StudyResult(trials=trials, summary=summary, groups=groups)
