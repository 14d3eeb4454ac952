"""Monte-Carlo studies: many random starts, several laws, a parameter sweep.

A :class:`StudySetup` holds what a study runs; :meth:`StudySetup.from_scenario`
is the one place where a scenario's study gets its defaults (``dt``,
``duration``, the centre of gaussian starts, each law's parameters).
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
size or the order in which chunks finish. With ``[study.settle]`` enabled, the
kernel's ``not-converged`` trials of switching laws are settled with implicit
Euler inside their chunk, trial by trial
(:func:`~formationlab.studies.chunks.settle_trials`), which keeps that property.

Resume: every finished chunk is handed to ``store.save`` as soon as it arrives
(the command line's store writes it atomically under ``DIR/chunks/``); with
``resume=True`` chunks that ``store.load`` returns are not run again.

The pieces live in :mod:`~formationlab.studies.groups`,
:mod:`~formationlab.studies.chunks` and :mod:`~formationlab.studies.executors`;
this module ties them together and touches no files: the store does.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..controllers import LAWS, Law
from ..engine.loop import step_chunk
from ..errors import ParameterError
from ..formation.spec import Formation
from ..models import RobotModel, SingleIntegrator
from ..safety import describe_obstacle
from ..sensing import Faults, Sensing, delay_steps
from ..validation import positive, steps_within, whole
from ..validation import seed as check_seed
from .batch import batch_backend, run_batch
from .chunks import ChunkTask, plan_chunks, run_chunk
from .config import GaussianInitial, StudyConfig, parse_study
from .executors import run_in_process, run_on_dask
from .groups import REPULSION_KEYS, ROBOT_KEYS, Group, study_groups
from .sampling import model_initial_states, trial_initial_states
from .summary import study_outcomes, summarize_groups

if TYPE_CHECKING:
    from ..scenario.parse import Scenario

#: Euler step of a study whose scenario's integrator has none (``filippov``), seconds.
DEFAULT_DT = 1e-3

__all__ = [
    "REPULSION_KEYS",
    "ROBOT_KEYS",
    "ChunkStore",
    "ChunkTask",
    "Group",
    "StudyResult",
    "StudySetup",
    "plan_chunks",
    "run_chunk",
    "run_study",
    "study_groups",
    "study_identity",
]


class ChunkStore(Protocol):
    """Where finished chunks are kept (:class:`formationlab.io.trials.ChunkFolder`)."""

    def load(self, chunk_id: str) -> pd.DataFrame | None: ...

    def save(self, chunk_id: str, frame: pd.DataFrame) -> None: ...


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
    model: RobotModel | None = None,
    safety: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Everything the trials depend on, JSON-ready, with its SHA-256 ``fingerprint``.

    Two runs with the same identity produce the same chunks; ``--resume`` refuses
    to mix chunks of different identities.
    """
    h = hashlib.sha256()
    for g in groups:
        f = g.formation
        alpha = f.alpha if f.alpha is not None or not f.has_orientation else f.restricted_alpha
        edges = f.edges.astype(np.int64)  # the bytes of int64, as the fingerprint was defined
        for arr in (f.diameters, edges, f.distances, alpha, f.template):
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
        "settle": config.settle.model_dump(mode="json"),
        "dt": float(dt),
        "duration": float(duration),
        "groups": [g.describe() for g in groups],
        "formations": h.hexdigest(),
    }
    if model is not None and model != SingleIntegrator():
        # (single-integrator studies keep the identity they had)
        ident["model"] = {"name": model.name, **dataclasses.asdict(model)}
    if safety is not None:  # obstacles and filter (absent without them: fingerprints kept)
        ident["safety"] = safety
    text = json.dumps(ident, sort_keys=True, default=float)
    ident["fingerprint"] = hashlib.sha256(text.encode()).hexdigest()[:16]
    return ident


@dataclass(frozen=True, kw_only=True, eq=False)
class StudySetup:
    """What a study runs: formation, laws, ``[study]`` configuration, step and duration.

    Parameters
    ----------
    formation : Formation
        The formation (the sweep may change its diameters).
    law : Law
        The scenario's law.
    config : StudyConfig
        The ``[study]`` table.
    dt, duration : float
        Euler step and simulated time per trial, seconds (> 0).
    center : array_like, shape (n, 2), optional
        Centre of gaussian starts; default the formation's template (required for
        gaussian starts when the formation has none).
    laws : mapping, optional
        The base law of each name of ``config.laws`` (default: it takes the parameters
        it shares with ``law``).
    model : RobotModel
        The robots (``[robots] model``); unicycles start with random headings,
        double integrators at rest (:func:`~formationlab.studies.sampling.model_initial_states`).
    obstacles : tuple of Circle or Polygon
        Static obstacles of every trial (starts touching one are drawn again).
    safety : SafetyFilter, optional
        Safety filter of every trial. With obstacles or a filter the trials run on the
        compiled loop, :mod:`formationlab.engine`
        (:func:`~formationlab.studies.batch.batch_backend`).
    """

    formation: Formation
    law: Law
    config: StudyConfig
    dt: float
    duration: float
    center: NDArray[np.float64] | None = None
    laws: Mapping[str, Law] | None = None
    model: RobotModel = field(default_factory=SingleIntegrator)
    obstacles: tuple[Any, ...] = ()
    safety: Any = None
    sensing: Sensing | None = None
    faults: Faults | None = None

    def __post_init__(self) -> None:
        if self.config.settle.enabled and not isinstance(self.model, SingleIntegrator):
            raise ParameterError(
                "settling (study.settle) covers single integrators only; disable it for "
                f"the robot model {self.model.name!r}",
                key="settle",
            )
        object.__setattr__(self, "dt", positive(self.dt, "dt"))
        object.__setattr__(self, "duration", positive(self.duration, "duration"))
        steps_within(self.duration, self.dt, "dt")
        center = self.center
        if isinstance(self.config.initial, GaussianInitial):
            if center is None:
                center = self.formation.template
            if center is None:
                raise ParameterError(
                    "a gaussian initial distribution needs a centre shape: give center= "
                    "or a formation with a template"
                )
            center = np.asarray(center, dtype=float)
        object.__setattr__(self, "center", center)

    @classmethod
    def from_scenario(cls, sc: Scenario, config: StudyConfig | None = None) -> StudySetup:
        """The study of a scenario; ``config`` default: its ``[study]`` table.

        Defaults (``docs/studies.md``): ``dt`` is ``study.dt``, else the scenario's
        integrator's ``dt``, else 1e-3 s; ``duration`` is ``study.duration``, else the
        scenario's; gaussian starts are centred on the template, else on
        ``robots.positions``; every law of ``study.laws`` takes the ``[controller]``
        keys it has (:meth:`~formationlab.scenario.Scenario.law_named`).

        Raises
        ------
        ScenarioError
            A bad ``[study]`` table, law parameter or sweep key, with its line.
        """
        if config is None:
            config = parse_study(sc.study, source=sc.source, text=sc.text)
        dt = config.dt if config.dt is not None else getattr(sc.integrator, "dt", DEFAULT_DT)
        duration = config.duration if config.duration is not None else sc.duration
        center = None  # of gaussian starts: the template, else the scenario's positions
        if isinstance(config.initial, GaussianInitial):
            center = sc.formation.template if sc.formation.template is not None else sc.q0
        if sc.marching is not None:
            raise sc.error(
                "marching",
                "a study classifies formations that come to rest: remove [marching] "
                "(or run the scenario with `formationlab run`)",
            )
        names = [n for n in config.laws or (sc.law.name,) if n in LAWS]
        laws = {LAWS.canonical(n): sc.law_named(n) for n in names}
        try:
            setup = cls(
                formation=sc.formation,
                law=sc.law,
                config=config,
                dt=dt,
                duration=duration,
                center=center,
                laws=laws,
                model=sc.model,
                obstacles=sc.obstacles,
                safety=sc.safety,
                sensing=sc.sensing,
                faults=sc.faults,
            )
        except ParameterError as exc:
            if exc.key != "dt":
                raise
            given = "study.dt" if config.dt is not None else "study.duration"
            raise sc.locate(ParameterError(str(exc), key=given)) from None
        try:
            setup.groups  # noqa: B018 - checks laws and sweep keys now, with the file's lines
        except ParameterError as exc:
            raise sc.locate(exc) from None
        return setup

    @cached_property
    def groups(self) -> list[Group]:
        """The groups (:func:`study_groups`)."""
        groups = study_groups(
            self.formation, self.law, self.config, laws=self.laws, sensing=self.sensing,
            faults=self.faults,
        )  # fmt: skip
        for g in groups:  # a swept delay must be whole steps of the study's dt
            if g.sensing is not None and g.sensing.delay > 0:
                try:
                    delay_steps(g.sensing.delay, self.dt)
                except ParameterError as exc:
                    key = "study.sweep.delay" if "delay" in g.parameters else "sensing.delay"
                    raise ParameterError(f"{exc} (study dt = {self.dt:g} s)", key=key) from None
        return groups

    @property
    def backend(self) -> tuple[str, str]:
        """The backend the trials run on and why it is not ``config.backend`` ("" if it is)."""
        sensed = any(g.sensed for g in self.groups)
        return batch_backend(
            self.config.backend, self.obstacles, self.safety, sensed, self.model,
            self.formation.dim, laws=[g.law for g in self.groups],
        )  # fmt: skip

    def safety_description(self) -> dict[str, Any] | None:
        """JSON-ready obstacles and filter (None without either)."""
        filtered = self.safety is not None and self.safety.enabled
        if not self.obstacles and not filtered:
            return None
        f = self.safety
        return {
            "obstacles": [describe_obstacle(ob) for ob in self.obstacles],
            "filter": None
            if not filtered
            else {
                "filter": f.filter,
                "distance": f.distance,
                "gamma": f.gamma,
                "max_speed": f.max_speed,
                "obstacle_distance": f.d_obstacle,
            },
        }

    def identity(self, seed: int) -> dict[str, Any]:
        """:func:`study_identity` of this study with ``seed``."""
        return study_identity(
            self.groups,
            self.config,
            seed=seed,
            dt=self.dt,
            duration=self.duration,
            center=self.center,
            model=self.model,
            safety=self.safety_description(),
        )


def run_study(
    setup: StudySetup,
    *,
    seed: int,
    scheduler: str | None = None,
    workers: int | None = None,
    store: ChunkStore | None = None,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
    notify: Callable[[str], None] | None = None,
) -> StudyResult:
    """Run a Monte-Carlo study.

    Parameters
    ----------
    setup : StudySetup
        What to run (:meth:`StudySetup.from_scenario` for a scenario file's study).
    seed : int
        Seed of the study (>= 0); trial ``t``'s start depends on ``(seed, t)`` only
        (:mod:`formationlab.studies.sampling`).
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
    notify : callable, optional
        Called with a message before a long silent step (compiling the kernels).

    Returns
    -------
    StudyResult
    """
    check_seed(seed, "--seed")
    if workers is not None:
        whole(workers, "--workers")
    if resume and store is None:
        raise ParameterError("resume needs a store of finished chunks")
    config, dt, duration = setup.config, setup.dt, setup.duration
    groups = setup.groups
    tasks = plan_chunks(
        groups, config, seed=int(seed), dt=dt, duration=duration, center=setup.center,
        model=setup.model,


        obstacles=setup.obstacles, safety=setup.safety,
    )  # fmt: skip
    total = sum(t.size for t in tasks)
    # compiled (or loaded from numba's cache) here, timed apart from the trials; dask
    # workers compile for themselves
    compile_time = _warm_kernels(tasks, notify) if scheduler is None else 0.0
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
        stream = run_on_dask(todo, scheduler, workers)
    else:
        stream = run_in_process(todo, workers or 1)
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
    settled = int(trials["settled"].sum()) if "settled" in trials else 0
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
        **_backend_used(setup),
        "settle": config.settle.model_dump(mode="json"),
        "laws": list(dict.fromkeys(g.law.name for g in groups)),
        "model": {"name": setup.model.name, **dataclasses.asdict(setup.model)},
        "sweep": {k: list(v) for k, v in config.sweep.items()},
        "outcomes": study_outcomes(trials),
        "groups": summarize_groups(trials, [g.describe() for g in groups]),
        "trial_steps": steps,
        "settled_trials": settled,
        "wall_time_s": wall,
        "compile_time_s": compile_time,
        "trial_steps_per_s": steps / wall if wall > 0 and resumed == 0 else None,
        "scheduler": scheduler,
        "workers": workers,
    }
    return StudyResult(trials=trials, summary=summary, groups=groups)


def _warm_kernels(tasks: list[ChunkTask], notify: Callable[[str], None] | None) -> float:
    """Compile (or load from numba's cache) each version of the loop the tasks use (with or
    without sensing, safety, per robot model, in the plane or in space), on a batch of two
    steps, so that the study's throughput does not count it; returns the time taken."""
    first: dict[tuple[Any, ...], ChunkTask] = {}  # one batch per version of the loop
    for t in tasks:
        if t.backend == "numba":
            safe = bool(t.obstacles) or (t.safety is not None and t.safety.enabled)
            dim = t.group.formation.dim  # (the loop compiles once for each dimension)
            first.setdefault((t.group.sensed, safe, type(t.model), dim), t)
    if not first:
        return 0.0
    if notify is not None and not _kernel_cached(step_chunk):
        notify("compiling kernels (once; later studies load them from the cache) ...")
    start = time.perf_counter()
    for t in first.values():
        f, g = t.group.formation, t.group
        trials = np.arange(min(t.size, 2))
        q0 = trial_initial_states(
            f, t.initial, t.seed, trials, center=t.center, obstacles=t.obstacles
        )
        x0 = model_initial_states(f, t.model, q0, t.seed, trials)
        run_batch(
            f, g.law, x0, dt=t.dt, duration=2 * t.dt, tolerances=t.tolerances,
            model=t.model, obstacles=t.obstacles, safety=t.safety,
            sensing=g.sensing if g.sensed else None, faults=g.faults if g.sensed else None,
            seeds=[(t.seed, int(i)) for i in trials] if g.sensed else None,
        )  # fmt: skip
    return time.perf_counter() - start


def _kernel_cached(dispatcher: Any) -> bool:
    """Whether numba's on-disk cache holds compiled versions of ``dispatcher`` (its index
    file exists; a new signature may still compile)."""
    try:
        from pathlib import Path

        return (
            bool(dispatcher.signatures) or Path(dispatcher._cache._cache_file._index_path).exists()
        )
    except AttributeError:  # another numba's internals: assume compiling
        return False


def _backend_used(setup: StudySetup) -> dict[str, Any]:
    """``backend_used``, ``backend_note`` and ``safety`` of a study with obstacles or a filter;
    ``backend_used`` and ``backend_note`` of one whose backend is not the one asked for (a
    formation in space under a law or model the compiled loop does not step there runs on the
    numpy path)."""
    used, note = setup.backend
    safety = setup.safety_description()
    if safety is None:
        return {"backend_used": used, "backend_note": note} if note else {}
    return {"backend_used": used, "backend_note": note, "safety": safety}
