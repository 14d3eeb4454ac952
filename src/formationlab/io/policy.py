"""Writing a trained policy: its parameters file (``.npz``) and its training curve (CSV).

The ``.npz`` holds the network's arrays ``W1, b1, W2, b2, ...``
(:func:`formationlab.controllers.network.network_arrays`, what the policy law reads), the
training curve as arrays ``curve_<column>`` and a JSON text ``meta`` (the command's
settings and the evaluation's fractions). Both files are written atomically.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..controllers.network import Network, network_arrays
from .files import atomic_write_bytes, atomic_write_text

__all__ = ["curve_csv", "read_curve", "write_policy"]


def curve_csv(curve: Mapping[str, NDArray[np.float64]]) -> str:
    """The training curve as CSV text, one row per generation (columns in order)."""
    names = list(curve)
    lines = [",".join(names)]
    for row in zip(*(curve[k] for k in names), strict=True):
        lines.append(",".join(f"{float(v):.10g}" for v in row))
    return "\n".join(lines) + "\n"


def write_policy(
    target: str | os.PathLike[str],
    network: Network,
    curve: Mapping[str, NDArray[np.float64]],
    meta: Mapping[str, Any],
) -> tuple[Path, Path]:
    """Write ``target`` (``.npz``) and the curve beside it (``<stem>-training.csv``).

    Returns
    -------
    (Path, Path)
        The parameters file and the CSV.
    """
    target = Path(target)
    arrays: dict[str, Any] = dict(network_arrays(network))
    arrays.update({f"curve_{k}": np.asarray(v, dtype=float) for k, v in curve.items()})
    arrays["meta"] = np.array(json.dumps(dict(meta), sort_keys=True))
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    atomic_write_bytes(target, buffer.getvalue())
    csv = target.with_name(f"{target.stem}-training.csv")
    atomic_write_text(csv, curve_csv(curve))
    return target, csv


def read_curve(path: str | os.PathLike[str]) -> tuple[dict[str, NDArray[np.float64]], dict]:
    """The training curve and the ``meta`` of a parameters file written by
    :func:`write_policy`."""
    with np.load(Path(path), allow_pickle=False) as data:
        curve = {name[6:]: data[name] for name in data.files if name.startswith("curve_")}
        meta = json.loads(str(data["meta"])) if "meta" in data.files else {}
    return curve, meta
