"""The viewer's Export TOML: the state shown, as a scenario file that runs from it.

Every table of the scenario is kept (robots and their model, formation, controller,
simulation, marching, obstacles, safety, sensing, faults, study, ...); what changes is
the start: ``[robots] positions`` and the model's other state (``headings`` of a
unicycle, ``velocities`` of a double integrator) become the state shown, and robots that
stop at ``t_stop`` ([faults]) stop at ``t_stop - t`` (at once if they already have). What
cannot be carried to a new start is refused by name (:class:`SessionError`): a marching
reference that is a function of time, or a state column no ``[robots]`` key holds.
The text is validated before it is handed out.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from ..errors import UserInputError
from ..scenario.parse import Scenario, parse_scenario

__all__ = ["export_table", "finish_export", "plain"]

#: The ``[robots]`` key that holds each extra state column of a model.
STATE_KEYS = {"headings": ("theta",), "velocities": ("vx", "vy", "vz")}


class SessionError(UserInputError):
    """A command the session cannot carry out (the message says why and what to do)."""


def plain(obj: Any) -> Any:
    """Numpy scalars to Python numbers, through dicts (TOML's own types)."""
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _model_state(scenario: Scenario, x: NDArray[np.float64]) -> dict[str, Any]:
    """The ``[robots]`` keys of the model's state beyond the positions, from ``x`` ``(n, k)``."""
    dim = scenario.formation.dim
    names = tuple(scenario.model.names_in(dim))
    if x.shape[-1] != len(names):
        raise SessionError(
            f"[robots] model {scenario.model.name!r} has the state {', '.join(names)}, but only "
            f"{x.shape[-1]} numbers per robot are known here (a run saved without its full "
            "state): nothing to export the start from"
        )
    out: dict[str, Any] = {}
    covered = set(names[:dim])  # the positions
    for key, cols in STATE_KEYS.items():
        cols = tuple(c for c in cols if c in names)  # (vz in space only)
        if cols and (len(cols) == 1 or len(cols) == dim):
            idx = [names.index(c) for c in cols]
            value = x[:, idx[0]] if len(idx) == 1 else x[:, idx]
            out[key] = np.asarray(value, dtype=float).tolist()
            covered.update(cols)
    missing = [c for c in names if c not in covered]
    if missing:
        raise SessionError(
            f"[robots] model {scenario.model.name!r}: no [robots] key holds the state "
            f"column(s) {', '.join(missing)}, so the state shown cannot be exported as a start"
        )
    return out


def export_table(
    scenario: Scenario, x: NDArray[np.float64], t: float
) -> dict[str, Any]:  # fmt: skip
    """The scenario's tables with the start replaced by the state ``x`` ``(n, k)`` at ``t``."""
    march = scenario.marching
    if march is not None and march.time_dependent and t > 0:
        raise SessionError(
            f"[marching]: the reference velocity is a function of time; a file started at the "
            f"state of t = {t:g} s would restart it at 0. Export at t = 0 (Reset), or give a "
            "constant velocity"
        )
    raw = copy.deepcopy(scenario.raw)
    x = np.asarray(x, dtype=float)
    robots = raw.setdefault("robots", {})
    robots["positions"] = x[:, : scenario.formation.dim].tolist()
    robots.update(_model_state(scenario, x))
    if scenario.faults is not None and "faults" in raw:
        raw["faults"]["stop"] = [
            {"robot": int(s.robot), "at": s.at if math.isinf(s.at) else max(s.at - t, 0.0)}
            for s in scenario.faults.stop
        ]
    raw["name"] = f"{scenario.name}-t{t:.3f}".replace(".", "_")
    text = f"state of {scenario.name!r} at t = {t:.6g} s, exported from the viewer"
    raw["description"] = f"{scenario.description} ({text})" if scenario.description else text
    return raw


def finish_export(name: str, raw: dict[str, Any], t: float) -> tuple[str, str]:
    """``(file name, TOML text)``, validated: a file that does not parse is never handed out."""
    text = tomli_w.dumps(raw)
    parse_scenario(text, source="<export>")
    return f"{name}-t{t:.3f}.toml".replace(" ", "_"), text
