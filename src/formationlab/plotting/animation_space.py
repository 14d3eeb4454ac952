"""A frame of a run in space: robots as points on 3-D axes under a slowly turning camera.

What differs from the plane (:mod:`formationlab.plotting.animation`) is the drawing only:
matplotlib's 3-D axes of one scale on all three axes (a cube of data is a cube on the
page), each robot a point (a marker, not a sphere of its diameter) with its 1-based number
up to :data:`~formationlab.plotting.many.LABEL_LIMIT` robots, the graph's edges and the
trails as 3-D line collections, stopped robots grey with a black rim, and a camera whose
azimuth advances :data:`AZIMUTH_STEP` degrees per frame, so that the depth reads from the
motion (a still projection hides it). The frames, trails, clock and saving are the
plane's (:mod:`formationlab.plotting.frames`, :mod:`formationlab.io.animation`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.colors import to_rgba_array
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from .colors import robot_colors
from .fonts import displayable, font_context
from .frames import frame_indices, play, stop_times
from .many import COLLECTION_LIMIT, LABEL_LIMIT, broken_line, segments
from .safety import ACTIVE_COLOR, draw_solids, solid_bounds

__all__ = ["AZIMUTH", "AZIMUTH_STEP", "ELEVATION", "animate_space"]

#: the camera's elevation above the x-y plane, degrees
ELEVATION = 20.0
#: the camera's azimuth at the first frame, degrees (matplotlib's default view)
AZIMUTH = -60.0
#: degrees the camera turns about the z axis from one frame to the next (150 frames: 150°)
AZIMUTH_STEP = 1.0
#: share of the figure's side that the cube's side takes on the page (to size the markers)
_CUBE_SHARE = 0.5
#: the cube's size in its axes (matplotlib's zoom of the box; 1 fills them)
_ZOOM = 0.85
#: smallest marker, points across
_SMALLEST = 3.0
#: colour of the robots beyond COLLECTION_LIMIT (as in the plane)
_SWARM = "C0"
#: a stopped robot's face
_STOPPED = (0.55, 0.55, 0.55, 1.0)


def animate_space(
    t: ArrayLike,
    q: ArrayLike,
    *,
    edges: ArrayLike,
    diameters: ArrayLike,
    max_frames: int = 150,
    fps: int = 15,
    trail: float | None = None,
    title: str = "",
    size: float = 5.0,
    dpi: int = 90,
    stops: Sequence[tuple[int, float]] = (),
    turn: float = AZIMUTH_STEP,
    obstacles: Sequence[Any] = (),
    active: ArrayLike | None = None,
) -> FuncAnimation:
    """An animation of a run in space, on 3-D axes.

    Parameters
    ----------
    t : array_like, shape (T,)
        Saved times, seconds.
    q : array_like, shape (T, n, 3)
        Positions at those times, metres.
    edges : array_like of int, shape (m, 2)
        0-based robot pairs of the graph, drawn as lines between the robots.
    diameters : array_like, shape (n,)
        Robot diameters ``rho_i``: the size of each robot's marker (the cube's side on
        the page for scale), and the margin of the axes.
    max_frames, fps, trail, title, size, dpi, stops
        As :func:`formationlab.plotting.animation.animate_run`.
    turn : float
        Degrees the camera's azimuth advances per frame (0: a still camera).
    obstacles : sequence
        Spheres and boxes (objects of :mod:`formationlab.safety` or their scenario form),
        drawn grey and numbered (:func:`~formationlab.plotting.safety.draw_solids`).
    active : array_like of bool, shape (T, n), optional
        Robots with an active safety constraint at each saved state: a red rim.

    Returns
    -------
    matplotlib.animation.FuncAnimation
        Not attached to pyplot; save it with :func:`formationlab.io.animation.save_animation`.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    diameters = np.asarray(diameters, dtype=float)
    if q.ndim != 3 or q.shape[-1] != 3 or q.shape[0] != t.shape[0]:
        raise ValueError(f"q must have shape (T, n, 3) with T = len(t), got {q.shape}")
    n = q.shape[1]
    many = n > LABEL_LIMIT
    frame_indices(t, max_frames)  # checks max_frames before a figure is made

    title = displayable(title)  # the user's scenario name: any script
    with font_context():
        fig = Figure(figsize=(size, size), dpi=dpi, layout="constrained")
        ax: Any = fig.add_subplot(projection="3d")
    held = np.concatenate([q.reshape(-1, 3), solid_bounds(obstacles)])[None]
    side = _cube(ax, held, float(diameters.max()))
    draw_solids(ax, obstacles)
    ring = np.zeros((len(t), n), bool) if active is None else np.asarray(active, bool)
    points_per_metre = _CUBE_SHARE * size * 72.0 / side
    graph = _Lines3D(ax, len(edges), colors="0.3", linewidth=0.5 if many else 1.0)
    robots = _Robots3D(ax, diameters * points_per_metre, label=not many)
    stop_at = stop_times(n, stops)
    clock = ax.set_title("")

    def draw(k: int, idx: int, sel: NDArray[np.int64]) -> list[Any]:
        now = q[idx]
        graph.set(np.stack([now[edges[:, 0]], now[edges[:, 1]]], axis=1))
        ax.view_init(elev=ELEVATION, azim=AZIMUTH + turn * k)
        drawn = robots.draw(q[sel], t[idx] >= stop_at, ring[idx])
        return [graph.artist, *drawn]

    return play(
        fig, t, draw, q=q, max_frames=max_frames, n=n, trail=trail, clock=clock, title=title,
        fps=fps,
    )  # fmt: skip


def _cube(ax: Any, q: NDArray[np.float64], margin: float) -> float:
    """Set the limits of the 3-D axes ``ax`` to one cube around every position of ``q``
    ``(T, n, 3)`` (``margin`` beyond, and 5 % of the side), drawn as a cube; returns its side.
    """
    lo = np.nanmin(q, axis=(0, 1)) - margin
    hi = np.nanmax(q, axis=(0, 1)) + margin
    centre = 0.5 * (lo + hi)
    half = 0.55 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    # a little smaller than the axes: the labels stay on the page as the camera turns
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=_ZOOM)
    ax.locator_params(nbins=5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    return 2.0 * half


class _Robots3D:
    """The robots of a frame in space: one scatter of points (a colour each, beyond
    :data:`~formationlab.plotting.many.COLLECTION_LIMIT` one colour), their trails, and
    their numbers when ``label``."""

    def __init__(self, ax: Any, across: NDArray[np.float64], *, label: bool) -> None:
        n = len(across)
        if n > COLLECTION_LIMIT:
            self.colors = np.tile(to_rgba_array(_SWARM), (n, 1))
            across = np.full(n, max(float(np.mean(across)), 1.0))
        else:
            self.colors = to_rgba_array(robot_colors(n))
            across = np.maximum(across, _SMALLEST)
        self.trails = _Lines3D(ax, n, colors=self.colors, linewidth=1.0, alpha=0.6)
        zero = np.zeros(n)
        self.points = ax.scatter(
            zero, zero, zero, s=across**2, c=self.colors, edgecolors=self.colors,
            depthshade=False, alpha=0.9,
        )  # fmt: skip
        self.labels = [ax.text(0.0, 0.0, 0.0, f" {i + 1}", fontsize=8) for i in range(n * label)]

    def draw(
        self, trail: NDArray[np.float64], dead: NDArray[np.bool_], ring: NDArray[np.bool_]
    ) -> list[Any]:
        """Draw the states ``trail`` ``(k, n, 3)`` (the last one now) with the robots
        ``dead`` grey and those with an active safety constraint (``ring``) rimmed red;
        returns the artists."""
        now = trail[-1]
        self.trails.set(np.swapaxes(trail, 0, 1))
        self.points.set_offsets(now[:, :2])
        self.points.set_3d_properties(now[:, 2], "z")
        face = self.colors.copy()
        face[dead] = _STOPPED
        edge = self.colors.copy()
        edge[dead] = (0.0, 0.0, 0.0, 1.0)
        edge[ring] = to_rgba_array(ACTIVE_COLOR)[0]
        self.points.set_facecolor(face)
        self.points.set_edgecolor(edge)
        self.points.set_linewidth(np.where(dead | ring, 1.5, 0.5))
        for i, text in enumerate(self.labels):
            text.set_position_3d(now[i])
        return [self.trails.artist, self.points, *self.labels]


class _Lines3D:
    """``k`` lines in space updated every frame: a 3-D collection (a colour each) up to
    :data:`~formationlab.plotting.many.COLLECTION_LIMIT`, one broken line beyond (as
    the plane's ``_Lines``)."""

    def __init__(self, ax: Any, k: int, *, colors: Any, linewidth: float, **style: Any) -> None:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        self.broken = k > COLLECTION_LIMIT
        self.artist: Any
        if self.broken:
            first = colors if isinstance(colors, str) else np.asarray(colors).reshape(-1, 4)[0]
            (self.artist,) = ax.plot([], [], [], color=first, linewidth=linewidth, **style)
        else:
            lines = segments(np.zeros((k, 2, 3)))
            self.artist = Line3DCollection(lines, colors=colors, linewidths=linewidth, **style)
            ax.add_collection3d(self.artist)

    def set(self, lines: NDArray[np.float64]) -> None:
        """Draw the lines ``(k, points, 3)``."""
        if self.broken:
            self.artist.set_data_3d(*broken_line(lines))
        else:
            self.artist.set_segments(segments(lines))
