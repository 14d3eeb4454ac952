"""What the page draws of a closed loop: the static scene and one frame's numbers.

:func:`scene_info` describes what does not change from frame to frame (robots, graph,
switching surfaces, obstacles, the safety filter, marching, the robot model, sensing,
faults); :func:`live_header` the numbers of one state of a
:class:`~formationlab.dynamics.System` (``V``, distance errors at the law's points,
active surfaces, the robots whose commands the safety filter changed, the marching
reference). Robot and obstacle numbers that leave this module are 1-based.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..formation.spec import Formation
from ..marching import Marching
from ..outcomes.analysis import bearing_errors, distance_errors

__all__ = [
    "EDGE_ERRORS_MAX",
    "EDGE_TOP",
    "SURFACES_MAX",
    "Frame",
    "History",
    "live_header",
    "scene_info",
]

#: Edges whose errors go into each frame one by one (beyond: their maximum and RMS only).
EDGE_ERRORS_MAX = 24
#: Surfaces whose on/off state goes into each frame (beyond: none, no switching lines drawn).
SURFACES_MAX = 400
#: Edges whose errors the plot draws as lines (the worst); the rest as a band.
EDGE_TOP = 5
#: Most switching events a replay marks on its plots.
SWITCHES_MAX = 500


@dataclasses.dataclass(frozen=True, kw_only=True)
class Frame:
    """One state as the page draws it.

    Attributes
    ----------
    header : dict
        JSON-ready: ``t``, ``V``, error summary, active surfaces, status, ...
    positions : ndarray of float32, shape (n, d)
        Robot centres, ``d = 2`` in the plane and 3 in space.
    heading : ndarray of float32, shape (n,), optional
        Robot headings in radians, for models whose state has them.
    """

    header: dict[str, Any]
    positions: NDArray[np.float32]
    heading: NDArray[np.float32] | None = None


@dataclasses.dataclass(frozen=True, kw_only=True, eq=False)
class History:
    """What a viewer has shown: times, positions, V and the errors.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Seconds.
    positions : ndarray, shape (T, n, d)
        Robot centres at those times (robot 1 is column 0; ``d = 3`` in space).
    V : ndarray, shape (T,)
        The law's Lyapunov function (eq. 15 for the paper's law; NaN where unknown). It
        can be negative where the paper's V is: a held robot (a drag) is not bound by it.
    errors : ndarray, shape (T, m)
        Per edge (``formation.edges`` order): ``r_ij - d_ij`` in metres, or the bearing
        errors ``||g_ij - g*_ij||`` of a formation judged by its bearings.
    """

    t: NDArray[np.float64]
    positions: NDArray[np.float64]
    V: NDArray[np.float64]
    errors: NDArray[np.float64]


def split_state(
    state: NDArray[np.float64], names: tuple[str, ...] = (), dim: int = 2
) -> tuple[NDArray, Any]:
    """Positions ``(..., n, dim)`` and headings ``(..., n)`` (or None) of a state.

    ``names`` are the model's state columns in ``dim`` dimensions
    (:meth:`~formationlab.models.base.RobotModel.names_in`); without them a state of three
    numbers per robot in the plane (a saved unicycle run: x, y, heading) counts as one with
    headings. A formation in space (``dim = 3``) has no headings.
    """
    if "theta" in names:
        return state[..., :2], state[..., names.index("theta")]
    if not names and dim == 2 and state.shape[-1] == 3:
        return state[..., :2], state[..., 2]
    return state[..., :dim], None


def edge_errors(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """What the error plot shows per edge, shape ``(m,)``: ``r_ij - d_ij``, or
    ``||g_ij - g*_ij||`` for a formation judged by its bearings (:func:`errors_kind`)."""
    if formation.bearings is not None:
        return bearing_errors(formation, q)
    return distance_errors(formation, q)


def errors_kind(formation: Formation) -> str:
    """What the error plot shows: ``"bearing"`` for a formation judged by its bearings (the
    bearing law, docs/bearing.md), else ``"distance"``."""
    return "bearing" if formation.bearings is not None else "distance"


def worst_edges(err: NDArray[np.float64], k: int = EDGE_TOP) -> NDArray[np.intp]:
    """The 0-based edges of the ``k`` largest ``|err|`` (``err`` ``(m,)``), worst first
    (NaN counts as the worst)."""
    size = np.where(np.isnan(err), np.inf, np.abs(err))
    k = min(k, err.size)
    top = np.argpartition(-size, k - 1)[:k] if k else np.zeros(0, np.intp)
    return top[np.argsort(-size[top], kind="stable")]


def error_fields(err: NDArray[np.float64]) -> dict[str, Any]:
    """The frame's error summary: ``err_max``, ``err_rms``, ``band`` (the least and the
    largest error), ``worst`` (the 1-based edges of the :data:`EDGE_TOP` largest ``|err|``
    and their errors), and ``errors`` (every edge's) for few edges."""
    top = worst_edges(err)
    out: dict[str, Any] = {
        "err_max": float(np.max(np.abs(err))) if err.size else 0.0,
        "err_rms": float(np.sqrt(np.mean(err * err))) if err.size else 0.0,
        "band": [float(np.min(err)), float(np.max(err))] if err.size else None,
        "worst": {"edges": (top + 1).tolist(), "values": [float(err[e]) for e in top]},
    }
    if err.size <= EDGE_ERRORS_MAX:
        out["errors"] = [float(x) for x in err]
    return out


def switch_times(t: NDArray[np.float64], sigma: NDArray[np.float64] | None) -> list[float]:
    """The times ``t`` ``(T,)`` at which some restriction turned on or off between two
    saved states (``sigma`` ``(T, s)``: the switching functions; none without them), at
    most :data:`SWITCHES_MAX` (the first)."""
    if sigma is None or len(t) < 2 or sigma.shape[-1] == 0:
        return []
    on = np.asarray(sigma) >= 0
    changed = np.flatnonzero(np.any(on[1:] != on[:-1], axis=-1)) + 1
    return [float(v) for v in t[changed[:SWITCHES_MAX]]]


def finite_or_none(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def static_info(formation: Formation, name: str) -> dict[str, Any]:
    """What the page draws besides the positions: the space (``dim``, 2 or 3), diameters,
    graph, switching surfaces (triangles in the plane, restricted quadruples in space)."""
    space = formation.dim == 3
    tris, beta, _ = formation.chiral_surfaces if space else formation.surfaces
    surfaces = None
    if len(tris) <= SURFACES_MAX:
        surfaces = {
            "tetrahedra" if space else "triangles": (tris + 1).tolist(),
            "beta": [float(b) for b in beta],
        }
    return {
        "name": name,
        "n": formation.n,
        "dim": formation.dim,
        "diameters": [float(d) for d in formation.diameters],
        "edges": (formation.edges + 1).tolist(),
        "distances": [float(d) for d in formation.distances],
        "surfaces": surfaces,
        "edge_errors": len(formation.edges) <= EDGE_ERRORS_MAX,
        "errors_kind": errors_kind(formation),
    }


def obstacle_shapes(obstacles: Any) -> list[dict[str, Any]]:
    """The obstacles as the page draws them: ``{"kind": "circle", "center", "radius"}`` (in
    space a sphere: a centre of three coordinates), ``{"kind": "box", "center", "size"}``
    (space) or ``{"kind": "polygon", "vertices"}``, obstacle 1 first."""
    out: list[dict[str, Any]] = []
    for o in obstacles:
        if hasattr(o, "radius"):
            out.append({"kind": "circle", "center": [float(c) for c in o.center],
                        "radius": float(o.radius)})  # fmt: skip
        elif hasattr(o, "size"):
            out.append({"kind": "box", "center": [float(c) for c in o.center],
                        "size": [float(s) for s in o.size]})  # fmt: skip
        else:
            out.append({"kind": "polygon", "vertices": np.asarray(o.vertices).tolist()})
    return out


def scene_info(system: System) -> dict[str, Any]:
    """The closed loop's parts the page shows: obstacles, filter, marching, model, sensing."""
    march = system.marching
    marching = None
    if march is not None:
        marching = {
            "kind": "reference" if isinstance(march, Marching) else "motion-parameters",
            "leader": getattr(march, "leader", None),
        }
    return {
        "obstacles": obstacle_shapes(system.obstacles),
        "safety": system.safety.filter if system.filtered else None,  # type: ignore[union-attr]
        "marching": marching,
        "model": system.model.name,
        "state_names": list(type(system.model).state_names),
        "sensing": system.sensing.describe() if system.sensing is not None else None,
        "faults": system.faults.describe() if system.faults is not None else None,
    }


def live_header(system: System, x: NDArray[np.float64], t: float) -> dict[str, Any]:
    """The numbers of the state ``x`` ``(n, k)`` at time ``t`` that change every frame.

    ``errors`` and the summary at the law's points; ``active`` the 1-based surfaces whose
    restriction is on (``System.sigma >= 0``; None beyond :data:`SURFACES_MAX`);
    ``filtered`` the 1-based robots whose command the safety filter changed
    (:meth:`System.filter_result` at ``t``; None without a filter) and ``filter_status``;
    ``reference`` the marching reference velocity ``v_ref(t)`` (None without one; a list
    of rows, one per leader, when each leader has its own).
    """
    formation = system.formation
    p = system.model.points(x)
    sigma = np.asarray(system.sigma(x))
    out: dict[str, Any] = {
        **error_fields(edge_errors(formation, p)),
        "errors_kind": errors_kind(formation),
        "active": (np.flatnonzero(sigma >= 0) + 1).tolist() if sigma.size <= SURFACES_MAX else None,
        "filtered": None,
        "filter_status": None,
        "reference": None,
    }
    if system.filtered and np.all(np.isfinite(x)):
        res = system.filter_result(x, t)
        out["filtered"] = (np.flatnonzero(res.active) + 1).tolist()
        out["filter_status"] = res.worst.name.lower()
    if isinstance(system.marching, Marching):
        out["reference"] = np.asarray(system.marching.reference(t), dtype=float).tolist()
    return out
