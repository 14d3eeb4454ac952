"""The files of a study: ``trials.parquet``, ``summary.json`` and the chunks kept for resuming.

``trials.parquet`` has one row per trial and these columns (robots 1-based; docs/outputs.md
defines them for a reader, and a test holds that page to the columns written):

============================  ======================================================
``group``                     0-based group (law x sweep point), as in ``summary.json``
``trial``                     0-based trial number within the group
``seed``                      the study's seed; with ``trial`` it reproduces the start
                              (:func:`formationlab.studies.sampling.trial_initial_states`)
``law``                       the law's name
one per swept parameter       its value; NaN for a law the parameter does not apply to
``outcome``                   one of :data:`formationlab.OUTCOMES` (the batched kernel's)
``settled``                   whether the trial was settled with implicit Euler
                              (``[study.settle]``: not-converged under a switching law)
``settled_outcome``           its outcome after settling; ``outcome`` if not settled
``max_distance_error``        largest ``|r_ij - d_ij|`` over the edges at the end
``max_bearing_error``         largest ``||g_ij - g*_ij||`` at the end (bearing formations;
                              NaN for the others)
``converged_time``            time of the first passed convergence test (instantaneous or
                              net speed <= the tolerance); NaN if never
``net_speed``                 net speed over the last check interval (displacement / time)
``min_clearance``             least clearance of robots and obstacles together over every
                              accepted step (the lesser of the next two)
``min_robot_clearance``       least ``r_ij - a_ij`` over the pairs of robots and time
``min_obstacle_clearance``    least robot-obstacle clearance over time; NaN without obstacles
``min_pair_distance``         least distance of two robots the safety filter keeps ``D_s``
                              apart, over time; NaN without a filter
``below_safety_distance``     whether that distance came below ``D_s`` (the filter's promise
                              broken; ``SafetyFilter.below``)
``steps``                     Euler steps taken (a trial stops once converged)
``drift_vx, drift_vy``        velocity of the centroid at the end, m/s, of the rigid motion
                              (and ``drift_vz`` for a formation in space)
                              fitted over the last ``drift_window`` seconds
                              (:mod:`formationlab.outcomes.rigid_motion`): the drift of a
                              ``drifting`` or ``rotating`` trial; NaN when the trial
                              stopped before that window (or the run is shorter)
``drift_speed``               the fastest robot's speed in that rigid motion, m/s (not the
                              centroid's: that is the norm of ``drift_vx, drift_vy``)
``drift_omega``               its angular velocity, rad/s (counter-clockwise positive; in
                              space its size, the axis carrying the direction)
``drift_cx, drift_cy``        its centre of rotation (NaN when ``drift_omega`` is 0); in
                              space, with ``drift_cz``, the point of its screw axis nearest
                              the centroid
``drift_ax, ...``             in space, the unit direction of that axis (``drift_ay``,
                              ``drift_az``; the velocity along it is the screw's advance)
``shape_rate``                how fast the shape changed over the window (the rigid fit's
                              largest residual over the window), m/s
``x1_init, y1_init, ...``     initial positions (``z1_init``, ... in space)
``theta1_init, ...``          initial headings (unicycles)
``x1, y1, x2, y2, ...``       final positions (``z1``, ... in space)
============================  ======================================================

Chunks live in ``DIR/chunks/<fingerprint>/`` (the fingerprint of the study's
identity, :func:`formationlab.studies.runner.study_identity`) beside a
``manifest.json`` holding that identity, so chunks of another study are never
mixed in.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import ParameterError
from .files import KeptFolder, atomic_path

__all__ = ["ChunkFolder", "read_trials", "trials_schema", "write_trials"]

_INTS = ("group", "trial", "seed", "steps")
_STRINGS = ("law", "outcome", "settled_outcome")
_BOOLS = ("settled", "below_safety_distance")


def trials_schema(columns: list[str]) -> pa.Schema:
    """The Arrow schema of a trials table with these columns (ints, strings, bools, floats)."""
    fields = []
    for c in columns:
        if c in _INTS:
            fields.append(pa.field(c, pa.int64()))
        elif c in _BOOLS:
            fields.append(pa.field(c, pa.bool_()))
        elif c in _STRINGS:
            fields.append(pa.field(c, pa.string()))
        else:
            fields.append(pa.field(c, pa.float64()))
    return pa.schema(fields)


def _write(frame: pd.DataFrame, target: Path) -> Path:
    table = pa.Table.from_pandas(
        frame, schema=trials_schema(list(frame.columns)), preserve_index=False
    )
    with atomic_path(target) as tmp:
        pq.write_table(table, tmp, compression="zstd")
    return target


def write_trials(frame: pd.DataFrame, target: str | os.PathLike[str]) -> Path:
    """Write a trials table to parquet atomically (schema of :func:`trials_schema`)."""
    return _write(frame, Path(target))


def read_trials(path: str | os.PathLike[str]) -> pd.DataFrame:
    """Read a trials table written by :func:`write_trials`.

    Raises
    ------
    ParameterError
        The file cannot be read or is not a parquet table (damaged, truncated, another
        kind of file); the message names it.
    """
    try:
        return pq.read_table(path).to_pandas()
    except FileNotFoundError:
        raise
    except (OSError, pa.ArrowException) as exc:
        reason = getattr(exc, "strerror", None) or str(exc).split("\n")[0]
        raise ParameterError(f"cannot read {path} as a trials table (parquet): {reason}") from None


class ChunkFolder(KeptFolder):
    """Finished chunks of one study under ``DIR/chunks/<fingerprint>/`` (a ``ChunkStore``).

    Parameters
    ----------
    out : path-like
        The study's output folder.
    identity : dict
        :func:`formationlab.studies.runner.study_identity` of the study.
    """

    def __init__(self, out: str | os.PathLike[str], identity: dict[str, Any]) -> None:
        super().__init__(out, "chunks", identity, str(identity["fingerprint"]))

    def path(self, chunk_id: str) -> Path:
        return self.folder / f"{chunk_id}.parquet"

    def check_resumable(self) -> int:
        """Check that this study can be resumed here; return how many chunks are kept.

        Raises
        ------
        ParameterError
            When the folder holds no chunks of this study, naming what differs from
            the study whose chunks it does hold.
        """
        manifest = self.folder / "manifest.json"
        if manifest.exists():
            return self.finished()
        others = sorted(self.root.glob("*/manifest.json"), key=lambda p: p.stat().st_mtime)
        if not others:
            raise ParameterError(
                f"nothing to resume in {self.root.parent}: it holds no chunks of a study; "
                "run without --resume"
            )
        try:
            old = json.loads(others[-1].read_text(encoding="utf-8"))
        except (OSError, ValueError):
            old = {}  # a damaged manifest: say only that the chunks are another study's
        diff = [
            k for k in self.identity if k != "fingerprint" and old.get(k) != self.identity.get(k)
        ]
        raise ParameterError(
            f"{self.root.parent} holds chunks of another study (differs in: "
            f"{', '.join(diff) or 'the formation'}); resume with the same scenario, --seed, "
            "--trials and chunk size, or start afresh in an empty folder"
        )

    def finished(self) -> int:
        """How many finished chunks the folder holds."""
        return len(list(self.folder.glob("g*-c*.parquet")))

    def load(self, chunk_id: str) -> pd.DataFrame | None:
        """The chunk's trials, or None if it has not finished.

        Raises
        ------
        ParameterError
            The chunk's file is damaged (it was not written by this package's atomic
            writer, or the disk corrupted it): delete it and resume to run it again.
        """
        p = self.path(chunk_id)
        if not p.exists():
            return None
        try:
            return read_trials(p)
        except ParameterError as exc:
            raise ParameterError(f"{exc}; delete it and resume again to rerun that chunk") from None

    def save(self, chunk_id: str, frame: pd.DataFrame) -> None:
        """Keep a finished chunk (atomic: an interruption leaves no half-written chunk)."""
        _write(frame, self.path(chunk_id))
