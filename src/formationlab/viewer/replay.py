"""A saved run played back in the viewer: the arrays of ``trajectory.nc`` and a time cursor.

The dataset comes from :func:`formationlab.io.netcdf.load_trajectory` (this
module reads no files). :class:`ReplaySession` speaks the interface of
:class:`~formationlab.viewer.session.LiveSession`; the commands that would
change the run are refused with a message.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import UserInputError
from ..outcomes.analysis import bearing_errors
from ..scenario.parse import Scenario, parse_scenario
from .export import SessionError, export_table, finish_export
from .frames import (
    EDGE_ERRORS_MAX,
    SURFACES_MAX,
    Frame,
    error_fields,
    finite_or_none,
    split_state,
    static_info,
    switch_times,
    worst_edges,
)
from .session import SERIES_MAX, law_parameters

__all__ = ["ReplaySession"]


class ReplaySession:
    """A saved run played back: the arrays of ``trajectory.nc`` and a time cursor.

    Parameters
    ----------
    dataset : xarray.Dataset
        As written by :func:`formationlab.io.netcdf.write_trajectory`
        (``q``, ``V``, ``distance_error``, ``diameter``, ``edge_robots``,
        optionally ``sigma`` and the ``scenario`` attribute).
    name : str
        Shown on the page.
    """

    mode = "replay"

    def __init__(self, dataset: Any, *, name: str = "replay") -> None:
        for var in ("q", "diameter", "edge_robots"):
            if var not in dataset:
                raise SessionError(
                    f"the trajectory has no {var!r}; give the folder of `formationlab run`"
                )
        self.name = str(dataset.attrs.get("scenario_name", name))
        self.t = np.asarray(dataset["time"].values, dtype=float)
        self.q = np.asarray(dataset["q"].values, dtype=float)
        n = self.q.shape[1]
        #: the space of the run: 2 (the plane) or 3 (``trajectory.nc`` with a ``z`` axis)
        self.dim = int(self.q.shape[-1])
        #: the full states ``(T, n, k)`` when the run stored them (else the positions)
        self.x = np.asarray(dataset["x"].values, dtype=float) if "x" in dataset else self.q
        self.state_names: tuple[str, ...] = (
            tuple(str(v) for v in dataset["state"].values) if "x" in dataset else ()
        )
        self.V = (
            np.asarray(dataset["V"].values, float)
            if "V" in dataset
            else np.full(len(self.t), np.nan)
        )
        self.err = (
            np.asarray(dataset["distance_error"].values, float)
            if "distance_error" in dataset
            else np.zeros((len(self.t), 0))
        )
        self.sigma = np.asarray(dataset["sigma"].values, float) if "sigma" in dataset else None
        self.errors_kind = "distance"
        self.scenario: Scenario | None = None
        text = dataset.attrs.get("scenario")
        if isinstance(text, str):
            try:
                self.scenario = parse_scenario(text, source="<replay>")
            except UserInputError:
                self.scenario = None  # an old or edited file: replay without surfaces
        if self.scenario is not None and self.scenario.formation.bearings is not None:
            if self.scenario.n == self.q.shape[1]:  # judged by its bearings: their errors
                self.err = bearing_errors(self.scenario.formation, self.q)
                self.errors_kind = "bearing"
        self.edges = np.asarray(dataset["edge_robots"].values, dtype=np.int64) - 1
        self.diameters = np.asarray(dataset["diameter"].values, dtype=float)
        self.distances = (
            np.asarray(dataset["desired_distance"].values, float)
            if "desired_distance" in dataset
            else np.zeros(len(self.edges))
        )
        self.n = n
        self.index = 0
        self._pos = 0.0  # fractional index while playing
        self.speed = 1.0
        self.paused = False

    def info(self) -> dict[str, Any]:
        if self.scenario is not None and self.scenario.n == self.n:
            static = static_info(self.scenario.formation, self.name)
        else:
            static = {
                "name": self.name,
                "n": self.n,
                "dim": self.dim,
                "diameters": self.diameters.tolist(),
                "edges": (self.edges + 1).tolist(),
                "distances": self.distances.tolist(),
                "surfaces": None,
                "edge_errors": len(self.edges) <= EDGE_ERRORS_MAX,
            }
        static["errors_kind"] = self.errors_kind
        if self.sigma is None or self.sigma.shape[-1] > SURFACES_MAX:
            static["surfaces"] = None
        stride = max(1, int(np.ceil(len(self.t) / SERIES_MAX)))
        sl = slice(None, None, stride)
        err = self.err[sl]
        series: dict[str, Any] = {
            "t": self.t[sl].tolist(),
            "V": [finite_or_none(v) for v in self.V[sl]],
            "err_max": np.max(np.abs(err), axis=-1).tolist() if err.shape[-1] else [],
        }
        if err.shape[-1]:
            series["band"] = [np.min(err, axis=-1).tolist(), np.max(err, axis=-1).tolist()]
            top = worst_edges(
                np.max(np.abs(np.nan_to_num(err, nan=np.inf)), axis=0)
            )  # the run's worst
            series["worst"] = {"edges": (top + 1).tolist(), "values": err[:, top].T.tolist()}
        if static["edge_errors"]:
            series["errors"] = err.T.tolist()
        series["switches"] = switch_times(self.t, self.sigma)
        law = None
        if self.scenario is not None:
            law = {"name": self.scenario.law.name, "params": law_parameters(self.scenario.law)}
        return {
            "mode": self.mode,
            **static,
            "law": law,
            "frames": len(self.t),
            "t_end": float(self.t[-1]),
            "series": series,
            "notices": [],
        }

    def frame(self) -> Frame:
        k = self.index
        pos, heading = split_state(self.x[k], self.state_names, self.dim)
        header: dict[str, Any] = {
            "t": float(self.t[k]),
            "V": finite_or_none(self.V[k]),
            **error_fields(self.err[k]),
            "active": None
            if self.sigma is None
            else (np.flatnonzero(self.sigma[k] >= 0) + 1).tolist(),
            "index": k,
            "paused": self.paused,
            "status": "replay",
            "message": "",
            "speed": self.speed,
        }
        return Frame(
            header=header,
            positions=pos.astype(np.float32),
            heading=None if heading is None else heading.astype(np.float32),
        )

    def advance(self, wall_dt: float) -> int:
        """Move the cursor by ``speed * wall_dt`` seconds of the run; stops at the end."""
        if self.paused or len(self.t) < 2:
            return 0
        target = self.t[self.index] + self.speed * max(wall_dt, 0.0)
        k = int(np.searchsorted(self.t, target, side="right")) - 1
        k = min(max(k, self.index), len(self.t) - 1)
        moved = k - self.index
        self.index = k
        if k == len(self.t) - 1:
            self.paused = True
        return moved

    def seek(self, index: int) -> None:
        if not 0 <= index < len(self.t):
            raise SessionError(
                f"frame {index} does not exist; the run has frames 0..{len(self.t) - 1}"
            )
        self.index = index

    def step(self, count: int = 1) -> int:
        k = min(self.index + count, len(self.t) - 1)
        moved, self.index = k - self.index, k
        return moved

    def set_paused(self, paused: bool) -> None:
        if not paused and self.index == len(self.t) - 1:
            self.index = 0  # play again from the start
        self.paused = paused

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)

    def reset(self) -> None:
        self.index = 0

    def export_scenario(self) -> tuple[str, str]:
        """The run's scenario with the positions of the frame shown now."""
        if self.scenario is None:
            raise SessionError("this run stores no scenario, so there is nothing to export")
        raw = export_table(self.scenario, self.x[self.index], float(self.t[self.index]))
        return finish_export(self.scenario.name, raw, float(self.t[self.index]))

    def _read_only(self, what: str) -> SessionError:
        return SessionError(f"a replay cannot {what}; run `formationlab view SCENARIO` to steer")

    def drag(self, robot: int, x: float, y: float, z: float | None = None) -> None:
        raise self._read_only("move robots")

    def release(self) -> None:
        return None

    def perturb(self, scale: float) -> None:
        raise self._read_only("perturb robots")

    def set_law(self, name: str, params: dict[str, float] | None = None) -> None:
        raise self._read_only("change the law")

    def set_params(self, params: dict[str, float]) -> None:
        raise self._read_only("change the law's gains")

    def set_integrator(self, name: str, dt: float) -> None:
        raise self._read_only("change the integrator")
