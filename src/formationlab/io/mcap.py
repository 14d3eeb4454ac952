"""A run as an MCAP recording of ROS 2 messages, for Foxglove, ``ros2 bag`` and rosbags.

:func:`write_mcap` writes, per saved state of a run (a
:class:`~formationlab.SimulationResult`, or the dataset of its ``trajectory.nc``), the
topics below in frame ``world``, stamped (log, publish and header time) with the
simulation time from 0 (nanoseconds). It uses the ``mcap`` and ``mcap-ros2-support``
packages (the ``robots`` extra): MCAP's ``ros2`` profile, ``ros2msg`` schemas
(:mod:`formationlab.io.ros2_messages`) and CDR messages, chunks compressed with zstd
(references: the MCAP format specification and its ``ros2`` profile, mcap.dev/spec; the
message types of ROS 2's ``common_interfaces``).

========================== ================================== =================================
topic                      type                               what
========================== ================================== =================================
``/formation/poses``       ``geometry_msgs/msg/PoseArray``    every robot's pose, robot 1 first
``/robot_<k>/pose``        ``geometry_msgs/msg/PoseStamped``  robot k's pose (1-based; up to
                                                              :data:`ROBOT_TOPICS_MAX` robots)
``/formation/graph``       ``visualization_msgs/msg/          the edges (``LINE_LIST``), the
                           MarkerArray``                      active restrictions' triangles
                                                              (``TRIANGLE_LIST``) and their
                                                              switching lines (``LINE_LIST``)
``/formation/lyapunov``    ``std_msgs/msg/Float64``           the law's Lyapunov function V
``/formation/distance_``   ``std_msgs/msg/Float64MultiArray`` ``r_ij - d_ij`` per edge; the
``errors``                                                    layout's one dimension is
                                                              labelled with the edges,
                                                              ``"1-2,1-3,2-3"``
========================== ================================== =================================

A pose's position is the robot's centre (z = 0 in the plane); its orientation the
heading as a rotation about z for robots that have one (unicycles), else the identity.
The markers: namespace ``edges`` (id 0), ``restrictions`` (id 1, the triangles whose
restriction is on, ``sigma >= 0``) and ``switching lines`` (id 2, line ``s`` of eq. (26)
for each vertex of those triangles, :func:`formationlab.controllers.angle_restricted.
switching_lines`, as the live viewer draws them), the last two at the law's points and
for the angle-restricted law in the plane only; a marker with nothing to draw is sent
with action ``DELETE``. The file's metadata record ``formationlab`` holds the scenario's
name, the package's version, the frame and the edges.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..controllers.angle_restricted import switching_lines
from ..errors import UserInputError, require_extra
from ..outcomes.analysis import edge_labels
from ..resources import package_version
from ..validation import whole
from .files import atomic_path
from .ros2_messages import definition

__all__ = ["FRAME", "ROBOT_TOPICS_MAX", "TOPICS", "Recording", "check_extra", "write_mcap"]

#: the frame every message is in
FRAME = "world"
#: robots up to which each also has its own topic ``/robot_<k>/pose``
ROBOT_TOPICS_MAX = 64
#: topic -> message type of the formation's topics
TOPICS = {
    "/formation/poses": "geometry_msgs/msg/PoseArray",
    "/formation/graph": "visualization_msgs/msg/MarkerArray",
    "/formation/lyapunov": "std_msgs/msg/Float64",
    "/formation/distance_errors": "std_msgs/msg/Float64MultiArray",
}
#: each robot's topic (``k`` 1-based) and its type
ROBOT_TOPIC = ("/robot_{k}/pose", "geometry_msgs/msg/PoseStamped")

_LINE_LIST, _TRIANGLE_LIST, _ADD, _DELETE = 5, 11, 0, 2
_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


@dataclasses.dataclass(frozen=True, kw_only=True, eq=False)
class Recording:
    """What a recording holds, from a result or a saved trajectory.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Saved times, seconds.
    q : ndarray, shape (T, n, d)
        Robot centres (d = 2 or 3).
    points : ndarray, shape (T, n, d)
        Where the law acts (``q`` unless near-identity unicycles).
    headings : ndarray, shape (T, n), or None
    V : ndarray, shape (T,)
    errors : ndarray, shape (T, m)
        ``r_ij - d_ij`` per edge.
    edges : ndarray of int, shape (m, 2)
        0-based robots of each edge.
    labels : list of str
        ``"i-j"`` of each edge (1-based).
    diameters : ndarray, shape (n,)
    sigma : ndarray, shape (T, s), or None
        Switching functions of the surfaces, with ``triangles`` (s, 3), ``beta`` (s,) and
        the law's ``theta`` when the switching lines are drawn (else all None).
    name : str
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    points: NDArray[np.float64]
    headings: NDArray[np.float64] | None
    V: NDArray[np.float64]
    errors: NDArray[np.float64]
    edges: NDArray[np.int64]
    labels: list[str]
    diameters: NDArray[np.float64]
    sigma: NDArray[np.float64] | None = None
    triangles: NDArray[np.int64] | None = None
    beta: NDArray[np.float64] | None = None
    theta: float | None = None
    name: str = "formationlab"

    @classmethod
    def from_result(cls, result: Any, *, name: str = "formationlab") -> Recording:
        """The recording of a :class:`~formationlab.SimulationResult`."""
        f = result.formation
        return cls(
            t=np.asarray(result.t, float), q=result.q, points=result.points,
            headings=result.headings, V=np.asarray(result.V, float),
            errors=result.distance_errors, edges=f.edges.astype(np.int64),
            labels=edge_labels(f), diameters=f.diameters, name=name,
            **_surfaces(f, result.law, result.sigma),
        )  # fmt: skip

    @classmethod
    def from_dataset(cls, ds: Any) -> Recording:
        """The recording of a ``trajectory.nc`` (:func:`formationlab.io.netcdf.load_trajectory`);
        the switching lines need its ``scenario`` attribute (the formation's surfaces)."""
        from ..scenario.parse import parse_scenario  # pydantic: for saved runs (start-up)

        missing = [v for v in ("q", "V", "distance_error", "edge_robots") if v not in ds]
        if missing:
            raise UserInputError(
                f"the trajectory has no {missing[0]!r}; give the folder of `formationlab run`"
            )
        q = np.asarray(ds["q"].values, float)
        sigma = np.asarray(ds["sigma"].values, float) if "sigma" in ds else None
        parts: dict[str, Any] = {}
        text = ds.attrs.get("scenario")
        if sigma is not None and isinstance(text, str):
            try:
                sc = parse_scenario(text, source="<trajectory.nc>")
            except UserInputError:
                sc = None  # an old or edited file: no switching lines (as the viewer's replay)
            if sc is not None and sc.n == q.shape[1]:
                parts = _surfaces(sc.formation, sc.law, sigma)
        return cls(
            t=np.asarray(ds["time"].values, float), q=q,
            points=np.asarray(ds["point"].values, float) if "point" in ds else q,
            headings=np.asarray(ds["theta"].values, float) if "theta" in ds else None,
            V=np.asarray(ds["V"].values, float),
            errors=np.asarray(ds["distance_error"].values, float),
            edges=np.asarray(ds["edge_robots"].values, np.int64).reshape(-1, 2) - 1,
            labels=[str(s) for s in ds["edge"].values],
            diameters=np.asarray(ds["diameter"].values, float),
            name=str(ds.attrs.get("scenario_name", "formationlab")), **parts,
        )  # fmt: skip

    def thinned(self, every: int) -> Recording:
        """Every ``every``-th saved state (the first and then each ``every`` after it)."""
        if every == 1:
            return self
        rows = slice(None, None, every)
        return dataclasses.replace(
            self, t=self.t[rows], q=self.q[rows], points=self.points[rows],
            headings=None if self.headings is None else self.headings[rows], V=self.V[rows],
            errors=self.errors[rows], sigma=None if self.sigma is None else self.sigma[rows],
        )  # fmt: skip


def _surfaces(formation: Any, law: Any, sigma: Any) -> dict[str, Any]:
    """The switching surfaces to draw: those of the angle-restricted law in the plane."""
    sigma = None if sigma is None else np.asarray(sigma, float)
    theta = getattr(law, "theta", None)
    if sigma is None or not sigma.shape[-1] or formation.dim != 2 or theta is None:
        return {}
    tris, beta, _ = formation.surfaces
    if len(tris) != sigma.shape[-1]:
        return {}
    return {"sigma": sigma, "triangles": tris, "beta": beta, "theta": float(theta)}


def check_extra() -> None:
    """Raise :class:`~formationlab.errors.MissingExtraError` naming ``formationlab[robots]``
    unless ``mcap`` and ``mcap-ros2-support`` import."""
    require_extra("robots", ("mcap", "mcap_ros2.writer"), "MCAP recordings")


def write_mcap(
    source: Any, target: str | os.PathLike[str], *, name: str | None = None, every: int = 1
) -> Path:
    """Write a run as an MCAP file of ROS 2 messages (module docstring), atomically.

    Parameters
    ----------
    source : SimulationResult or xarray.Dataset
        A run, or the dataset of its ``trajectory.nc``
        (:func:`formationlab.io.netcdf.load_trajectory`), or a :class:`Recording`.
    target : path
        The ``.mcap`` file (replaced if it exists).
    name : str, optional
        The scenario's name for the metadata (a dataset's ``scenario_name`` otherwise).
    every : int
        Record every ``every``-th saved state (1: all). Encoding takes about 0.8 ms per
        state of three robots (docs/robots.md): a run saved at every step of 1 ms plays
        in the tools at a rate no display needs.

    Raises
    ------
    MissingExtraError
        Without the ``robots`` extra (``mcap``, ``mcap-ros2-support``).
    """
    every = whole(every, "every", minimum=1)
    check_extra()
    from mcap_ros2.writer import Writer  # the robots extra (checked above)

    if isinstance(source, Recording):
        rec = source
    elif hasattr(source, "formation"):
        rec = Recording.from_result(source, name=name or "formationlab")
    else:
        rec = Recording.from_dataset(source)
    if name is not None:
        rec = dataclasses.replace(rec, name=name)
    rec = rec.thinned(every)
    with atomic_path(target, suffix=".mcap") as tmp, open(tmp, "wb") as fh:
        writer = Writer(fh)
        _write(writer, rec)
        writer.finish()
    return Path(target)


def _write(writer: Any, rec: Recording) -> None:
    """Every message of ``rec`` in time order."""
    n = rec.q.shape[1]
    schemas = {t: writer.register_msgdef(t, definition(t)) for t in TOPICS.values()}
    robots = n <= ROBOT_TOPICS_MAX
    if robots:
        schemas[ROBOT_TOPIC[1]] = writer.register_msgdef(ROBOT_TOPIC[1], definition(ROBOT_TOPIC[1]))
    writer.add_metadata(
        "formationlab",
        {
            "scenario_name": rec.name,
            "formationlab_version": package_version(),
            "frame": FRAME,
            "robots": str(n),
            "edges": json.dumps((rec.edges + 1).tolist()),
        },
    )
    xyz = np.zeros((*rec.q.shape[:2], 3))
    xyz[..., : rec.q.shape[-1]] = rec.q
    turns = _quaternions(rec.headings, rec.q.shape[:2])
    width = 0.25 * float(np.min(rec.diameters)) if n else 0.05
    layout = {"dim": [{"label": ",".join(rec.labels), "size": len(rec.labels),
                       "stride": len(rec.labels)}], "data_offset": 0}  # fmt: skip
    stamps = np.rint(rec.t * 1e9).astype(np.int64)
    for k, ns in enumerate(stamps.tolist()):
        header = {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": FRAME}
        p, o = xyz[k].tolist(), turns[k].tolist()
        poses = [{"position": _point(p[i]), "orientation": _quat(o[i])} for i in range(n)]

        def put(topic: str, kind: str, message: dict[str, Any], k: int = k, ns: int = ns) -> None:
            writer.write_message(topic, schemas[kind], message, log_time=ns, publish_time=ns,
                                 sequence=k)  # fmt: skip

        put("/formation/poses", TOPICS["/formation/poses"], {"header": header, "poses": poses})
        if robots:
            for i in range(n):
                put(ROBOT_TOPIC[0].format(k=i + 1), ROBOT_TOPIC[1],
                    {"header": header, "pose": poses[i]})  # fmt: skip
        put("/formation/graph", TOPICS["/formation/graph"],
            {"markers": _markers(rec, k, xyz[k], header, width)})  # fmt: skip
        put("/formation/lyapunov", TOPICS["/formation/lyapunov"], {"data": float(rec.V[k])})
        put("/formation/distance_errors", TOPICS["/formation/distance_errors"],
            {"layout": layout, "data": rec.errors[k].tolist()})  # fmt: skip


def _point(p: list[float]) -> dict[str, float]:
    return {"x": p[0], "y": p[1], "z": p[2]}


def _quat(o: list[float]) -> dict[str, float]:
    return {"x": o[0], "y": o[1], "z": o[2], "w": o[3]}


def _quaternions(headings: NDArray[np.float64] | None, shape: tuple[int, ...]) -> NDArray:
    """Unit quaternions ``(x, y, z, w)`` of rotations by the headings about z, ``(T, n, 4)``
    (the identity without headings)."""
    out = np.zeros((*shape, 4))
    if headings is None:
        out[..., 3] = 1.0
        return out
    half = 0.5 * np.asarray(headings, float)
    out[..., 2], out[..., 3] = np.sin(half), np.cos(half)
    return out


def _markers(
    rec: Recording, k: int, xyz: NDArray[np.float64], header: dict[str, Any], width: float
) -> list[dict[str, Any]]:
    """The markers of saved state ``k``: edges, active restrictions, switching lines."""
    ends = xyz[rec.edges.reshape(-1)].tolist()
    out = [_marker(header, "edges", 0, _LINE_LIST, ends, width, (0.35, 0.35, 0.35, 1.0))]
    if rec.sigma is None or rec.triangles is None or rec.beta is None or rec.theta is None:
        return out
    on = np.flatnonzero(rec.sigma[k] >= 0)  # (drawn in the plane only: z = 0)
    tris = rec.triangles[on]
    corners = np.concatenate([rec.points[k][tris.reshape(-1)], np.zeros((3 * len(on), 1))], 1)
    segments = switching_lines(rec.points[k], tris, rec.beta[on], rec.theta).reshape(-1, 2, 2)
    segments = segments[np.all(np.isfinite(segments), axis=(1, 2))].reshape(-1, 2)
    lines = np.concatenate([segments, np.zeros((len(segments), 1))], 1)
    out.append(_marker(header, "restrictions", 1, _TRIANGLE_LIST, corners.tolist(), 1.0,
                       (0.88, 0.54, 0.0, 0.25)))  # fmt: skip
    out.append(_marker(header, "switching lines", 2, _LINE_LIST, lines.tolist(), 0.5 * width,
                       (0.88, 0.54, 0.0, 1.0)))  # fmt: skip
    return out


def _marker(
    header: dict[str, Any],
    ns: str,
    ident: int,
    kind: int,
    points: list[list[float]],
    width: float,
    color: tuple[float, float, float, float],
) -> dict[str, Any]:
    """A ``visualization_msgs/msg/Marker`` of ``points`` (``DELETE`` when there are none)."""
    r, g, b, a = color
    return {
        "header": header, "ns": ns, "id": ident, "type": kind,
        "action": _ADD if points else _DELETE, "pose": {"orientation": _IDENTITY},
        "scale": {"x": width, "y": width if kind == _TRIANGLE_LIST else 0.0,
                  "z": width if kind == _TRIANGLE_LIST else 0.0},
        "color": {"r": r, "g": g, "b": b, "a": a},
        "points": [_point(p) for p in points],
    }  # fmt: skip
