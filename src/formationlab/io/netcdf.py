"""Trajectories as netCDF (``trajectory.nc``), through xarray and h5netcdf.

Layout of the file (CF-style names, robots numbered from 1):

========================  ============================  ======================================
variable                  dimensions                    meaning
========================  ============================  ======================================
``q``                     ``(time, robot, axis)``       positions (robot centres)
``u``                     ``(time, robot, axis)``       velocities of the positions (= the
                                                        controls for single integrators, eq. 1)
``x``                     ``(time, robot, state)``      the robot model's full state (models
                                                        with more than positions only)
``theta``                 ``(time, robot)``             headings, radians (unicycles)
``point``                 ``(time, robot, axis)``       where the law acts, when not the
                                                        centres (near-identity hand points)
``V``                     ``(time,)``                   the law's Lyapunov function (eq. 9/15)
``sigma``                 ``(time, surface)``           switching functions (angle-restricted
                                                        laws only); active where ``>= 0``
``distance_error``        ``(time, edge)``              ``r_ij - d_ij``
``diameter``              ``(robot,)``                  ``rho_i``
``edge_robots``           ``(edge, end)``               1-based robot numbers of each edge
``desired_distance``      ``(edge,)``                   ``d_ij``
``filter_status``         ``(time,)``                   safety filter status (0 unchanged, 1
                                                        solved, 2 relaxed, 3 fallback, 4 failed)
``filter_active``         ``(time, robot)``             1 where a robot's constraint is active
``active_pair``           ``(constraint, column)``      active pair constraints: time index
                                                        (0-based), robots i < j (1-based)
``active_obstacle``       ``(obstacle_constraint,       active obstacle constraints: time index,
                          column)``                     robot, obstacle (1-based)
========================  ============================  ======================================

The last four exist only for a run with obstacles or a safety filter; the global
attribute ``obstacles`` then holds the obstacles (JSON of their scenario form) and
``safety`` the filter's parameters.

Storage: every variable is compressed (zlib level :data:`COMPRESSION` with the byte
shuffle filter, lossless), numbers in chunks of whole saved states of about
:data:`CHUNK_BYTES` (``(k, robot, axis)`` for ``q``), so that a reader that wants some
times (an animation's frames) reads and decompresses only those; labels (``edge``,
``surface``) as compressed character arrays (xarray reads them back as strings).

Coordinates: ``time`` in seconds, ``robot`` = 1..n, ``axis`` = ``"x"``, ``"y"``,
``edge`` = labels ``"i-j"``, ``surface`` = labels ``"alpha_ijk"``. Global
attributes: ``scenario`` (the scenario's TOML text), ``formationlab_version``,
``law``, ``integrator`` and ``model`` (JSON of their parameters), ``status``,
``message``; with ``[sensing]`` or ``[faults]`` also ``sensing`` and ``faults`` (JSON of
their tables). ``state`` = the model's ``state_names`` (``"x", "y", "theta"``).
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..outcomes.analysis import distance_errors
from ..resources import package_version
from .files import atomic_write_bytes, to_jsonable

__all__ = [
    "CHUNK_BYTES",
    "COMPRESSION",
    "ENGINE",
    "encoding",
    "load_trajectory",
    "open_trajectory",
    "trajectory_dataset",
    "write_trajectory",
]

#: The netCDF engine used for reading and writing.
ENGINE = "h5netcdf"
#: zlib level of the variables of ``trajectory.nc`` (1 fastest ... 9 smallest)
COMPRESSION = 1
#: target bytes of one chunk (HDF5 reads and decompresses whole chunks)
CHUNK_BYTES = 1 << 20


def trajectory_dataset(result: Any, *, attrs: dict[str, Any] | None = None) -> Any:
    """The :class:`xarray.Dataset` of a :class:`~formationlab.SimulationResult`.

    Parameters
    ----------
    result : SimulationResult
        A simulated run (positions ``(T, n, 2)``, controls, ``V``, ``sigma``).
    attrs : dict, optional
        Extra global attributes (strings or numbers; dicts are stored as JSON).
    """
    import xarray as xr

    coords, data, series, glob = _layout(result, attrs)
    for name, (dims, values, meta) in series.items():
        full = values if isinstance(values, np.ndarray) else values(slice(None))
        data[name] = (dims, full, meta)
    return xr.Dataset(data_vars=data, coords=coords, attrs=glob)


#: a variable over time: its dimensions, its values (or a function of a slice of the
#: saved states giving them), and its attributes
Series = tuple[tuple[str, ...], Any, dict[str, Any]]


def _layout(
    result: Any, attrs: dict[str, Any] | None
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Series], dict[str, Any]]:
    """Coordinates, the variables that do not grow with time, the time series, attributes."""
    f = result.formation
    n = f.n
    robot = np.arange(1, n + 1)
    coords: dict[str, Any] = {
        "time": ("time", np.asarray(result.t, float), {"units": "s", "long_name": "time"}),
        "robot": ("robot", robot, {"long_name": "robot number (1-based)"}),
        "axis": ("axis", np.array(["x", "y", "z"][: f.dim])),
        "edge": ("edge", np.array(result.edge_labels)),
    }
    points = result.points
    series: dict[str, Series] = {
        "q": (("time", "robot", "axis"), result.q, {"long_name": "position q_i"}),
        "u": (("time", "robot", "axis"), result.u, {"long_name": "control u_i = dq_i/dt"}),
        "distance_error": (
            ("time", "edge"),
            lambda rows: distance_errors(f, points[rows]),
            {"long_name": "distance error r_ij - d_ij"},
        ),
    }
    data: dict[str, Any] = {
        "V": (("time",), result.V, {"long_name": "Lyapunov function of the law"}),
        "diameter": (("robot",), f.diameters, {"long_name": "robot diameter rho_i"}),
        "edge_robots": (
            ("edge", "end"),
            f.edges.astype(np.int64) + 1,
            {"long_name": "robots i, j (1-based)"},
        ),
        "desired_distance": (("edge",), f.distances, {"long_name": "desired distance d_ij"}),
    }
    names = list(result.model.names_in(f.dim))
    if len(names) > f.dim:
        coords["state"] = ("state", np.array(names))
        series["x"] = (("time", "robot", "state"), result.x, {"long_name": "full state"})
    if result.headings is not None:
        series["theta"] = (("time", "robot"), result.headings, {"units": "rad"})
    if not np.array_equal(points, result.q):
        series["point"] = (
            ("time", "robot", "axis"), points, {"long_name": "point the law acts on"}
        )  # fmt: skip
    if result.sigma.shape[-1]:
        coords["surface"] = ("surface", np.array(result.restriction_labels))
        series["sigma"] = (
            ("time", "surface"),
            result.sigma,
            {
                "long_name": "switching function sigma = beta v_abcd + theta (active >= 0)"
                if f.dim == 3
                else "switching function sigma = beta c_abc + theta (active >= 0)"
            },
        )
    if result.safety is not None:
        rec = result.safety
        pairs = np.asarray(rec.active_pairs, np.int64).reshape(-1, 3) + np.array([0, 1, 1])
        obs = np.asarray(rec.active_obstacles, np.int64).reshape(-1, 3) + np.array([0, 1, 1])
        data["filter_status"] = (("time",), rec.status, {"long_name": "safety filter status"})
        data["filter_active"] = (
            ("time", "robot"),
            rec.active.astype(np.int8),
            {"long_name": "1 where a constraint of the robot is active"},
        )
        data["active_pair"] = (
            ("constraint", "column"),
            pairs,
            {"long_name": "active pair constraint: time index, robot i, robot j (1-based)"},
        )
        data["active_obstacle"] = (
            ("obstacle_constraint", "column"),
            obs,
            {"long_name": "active obstacle constraint: time index, robot, obstacle (1-based)"},
        )
    return coords, data, series, _attributes(result, attrs)


def _attributes(result: Any, attrs: dict[str, Any] | None) -> dict[str, Any]:
    """The global attributes (module docstring), with ``attrs`` added."""
    glob: dict[str, Any] = {
        "title": "formationlab trajectory",
        "formationlab_version": package_version(),
        "law": json.dumps(to_jsonable(_params(result.law))),
        "integrator": json.dumps(to_jsonable(_params(result.integrator))),
        "model": json.dumps(to_jsonable(_params(result.model))),
        "status": str(result.status),
        "message": result.message,
        "Conventions": "CF-1.8",
    }
    if result.safety is not None:
        summary = result.safety.summary()
        glob["obstacles"] = json.dumps(summary["obstacles"])
        glob["safety"] = json.dumps(to_jsonable(summary["filter"]))
    if getattr(result, "sensing", None) is not None:
        glob["sensing"] = json.dumps(to_jsonable(result.sensing.describe()))
    if getattr(result, "faults", None) is not None:
        glob["faults"] = json.dumps(to_jsonable(result.faults.describe()))
    for key, value in (attrs or {}).items():
        glob[key] = (
            value if isinstance(value, str | int | float) else json.dumps(to_jsonable(value))
        )
    return glob


def _params(obj: Any) -> dict[str, Any]:
    import dataclasses

    return {"name": obj.name, **dataclasses.asdict(obj)}


def write_trajectory(
    result: Any, target: str | os.PathLike[str], *, attrs: dict[str, Any] | None = None
) -> Path:
    """Write ``result`` to the netCDF file ``target`` atomically (see module docstring).

    ``attrs`` are added as global attributes, e.g. ``{"scenario": scenario.text}``.

    The coordinates and the small variables go through xarray; the time series (``q``,
    ``u``, ``distance_error``, ``sigma``, ...) are then added to the same file chunk by
    chunk from the run's own arrays, the distance errors computed a slice of saved states
    at a time: no copy of the trajectory is made.

    The file is composed in memory (its compressed bytes, at most the data's size) and then
    written with plain file output: HDF5 never writes to the disk itself, since an HDF5 file
    whose write failed (a full disk, a file-size limit) cannot be closed safely (HDF5 2.0
    with h5py 3.16 crashes when the file's objects are freed). A full disk is then the one
    error of :func:`~formationlab.io.files.atomic_path`, and no partial file is left.
    """
    import h5netcdf
    import xarray as xr

    coords, data, series, glob = _layout(result, attrs)
    ds: Any = xr.Dataset(data_vars=data, coords=coords, attrs=glob)
    rows = len(result.t)
    image = io.BytesIO()
    ds.to_netcdf(image, engine=ENGINE, invalid_netcdf=False, encoding=encoding(ds))
    with h5netcdf.File(image, "a") as nc:
        for name, (dims, values, meta) in series.items():
            shape = (rows, *(nc.dimensions[d].size for d in dims[1:]))
            dtype = np.dtype(values.dtype if isinstance(values, np.ndarray) else float)
            chunks = _chunks(shape, dtype.itemsize)
            var = nc.create_variable(
                name, dims, dtype, chunks=chunks, compression="gzip",
                compression_opts=COMPRESSION, shuffle=True,
            )  # fmt: skip
            var.attrs.update(meta)
            step = chunks[0] * max(1, CHUNK_BYTES * 16 // (chunks[0] * _bytes(shape, dtype)))
            for a in range(0, rows, step):
                part = slice(a, min(rows, a + step))
                var[part] = values[part] if isinstance(values, np.ndarray) else values(part)
    with image.getbuffer() as data:
        atomic_write_bytes(target, data)
    return Path(target)


def _bytes(shape: tuple[int, ...], dtype: np.dtype[Any]) -> int:
    """Bytes of one saved state of a variable of ``shape`` (time first)."""
    return dtype.itemsize * int(np.prod(shape[1:]))


def _chunks(shape: tuple[int, ...], itemsize: int) -> tuple[int, ...]:
    """Chunks of whole saved states of about :data:`CHUNK_BYTES` (a larger state split along
    its first axis after time)."""
    chunks = list(shape)
    row = itemsize * int(np.prod(shape[1:]))
    if row <= CHUNK_BYTES:
        chunks[0] = min(shape[0], max(1, CHUNK_BYTES // row))
    else:
        chunks[0] = 1
        inner = itemsize * int(np.prod(shape[2:]))
        chunks[1] = min(shape[1], max(1, CHUNK_BYTES // inner))
    return tuple(max(1, c) for c in chunks)


def encoding(ds: Any) -> dict[str, dict[str, Any]]:
    """The storage of each numeric variable of ``ds``: compressed, chunked by saved states.

    A chunk holds whole states ``(k, ...)`` of about :data:`CHUNK_BYTES`, at least one
    (a state larger than that is split along its first axis after time).
    """
    out: dict[str, dict[str, Any]] = {}
    packed = {"zlib": True, "complevel": COMPRESSION, "shuffle": True}
    for name, var in ds.variables.items():
        shape = tuple(int(k) for k in var.shape)
        if not shape or 0 in shape:
            continue
        if var.dtype.kind in "OUS":  # labels: compressed characters, not one heap object each
            out[str(name)] = {"dtype": "S1", **packed}
            continue
        if var.dtype.kind not in "fiub":
            continue
        chunks = _chunks(shape, var.dtype.itemsize)
        out[str(name)] = {**packed, "chunksizes": chunks}
    return out


def open_trajectory(path: str | os.PathLike[str]) -> Any:
    """Open a ``trajectory.nc`` lazily: an ``xarray.Dataset`` whose variables are read when
    indexed (close it when done, e.g. ``with open_trajectory(p) as ds: ds["q"][-1]``)."""
    import xarray as xr

    return xr.open_dataset(path, engine=ENGINE)


def load_trajectory(path: str | os.PathLike[str]) -> Any:
    """Read a ``trajectory.nc`` into memory and close the file; returns an ``xarray.Dataset``."""
    with open_trajectory(path) as ds:
        return ds.load()
