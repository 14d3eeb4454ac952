"""Counting outcomes: fractions per group with Wilson score intervals.

The ``groups`` of a study's ``summary.json`` come from :func:`summarize_groups`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..outcomes.analysis import OUTCOMES

__all__ = ["Z95", "study_outcomes", "summarize_groups", "wilson_interval"]

#: Outcomes that a study reports only when some trial has them (before or after
#: settling): a study without moving rigid formations keeps today's tables.
OPTIONAL_OUTCOMES = ("drifting", "rotating", "diverged")

#: The standard normal quantile of 0.975: two-sided 95 % intervals.
Z95 = 1.959963984540054


def wilson_interval(
    successes: ArrayLike, trials: ArrayLike, z: float = Z95
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Wilson score interval of a binomial proportion ``k / n``.

    ``(p + z^2/2n -+ z sqrt(p(1 - p)/n + z^2/4n^2)) / (1 + z^2/n)`` with
    ``p = k / n`` (Wilson 1927). Unlike the normal approximation it stays in
    ``[0, 1]`` and is not empty at ``k = 0`` or ``k = n``: for ``k = 0`` it is
    ``[0, z^2 / (n + z^2)]``.

    Parameters
    ----------
    successes, trials : array_like
        ``k`` and ``n`` (broadcast together), ``0 <= k <= n``, ``n >= 1``.
    z : float
        Normal quantile; the default gives 95 % intervals.

    Returns
    -------
    low, high : ndarray
        The interval's ends, shape of the broadcast inputs.
    """
    k = np.asarray(successes, dtype=float)
    n = np.asarray(trials, dtype=float)
    if np.any(n < 1) or np.any(k < 0) or np.any(k > n):
        raise ValueError("the Wilson interval needs 0 <= successes <= trials and trials >= 1")
    p = k / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denom
    half = z * np.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denom
    # exact ends at k = 0 and k = n (rounding would leave them a hair off 0 and 1)
    low = np.where(k == 0, 0.0, np.clip(centre - half, 0.0, 1.0))
    high = np.where(k == n, 1.0, np.clip(centre + half, 0.0, 1.0))
    return low, high


def study_outcomes(trials: pd.DataFrame) -> list[str]:
    """The outcomes a study reports, in the order of :data:`OUTCOMES`.

    Every outcome except ``drifting`` and ``rotating``, which are listed only when
    some trial of the table has them (column ``outcome`` or ``settled_outcome``).
    """
    seen: set[str] = set()
    for column in ("outcome", "settled_outcome"):
        if column in trials:
            seen.update(str(x) for x in pd.unique(trials[column]))
    return [o for o in OUTCOMES if o not in OPTIONAL_OUTCOMES or o in seen]


def summarize_groups(
    trials: pd.DataFrame,
    groups: list[dict[str, Any]],
    outcomes: list[str] | None = None,
) -> list[dict[str, Any]]:
    """One summary entry per group, in the order of ``groups``.

    Parameters
    ----------
    trials : DataFrame
        One row per trial with at least the columns ``group``, ``outcome``,
        ``converged_time`` and ``steps``.
    groups : list of dict
        Per group (index = ``group`` column): ``law``, ``parameters`` and
        anything else to carry over (``law_parameters``, ...).
    outcomes : list of str, optional
        The outcomes counted; default :func:`study_outcomes` of ``trials``.

    Returns
    -------
    list of dict
        ``law``, ``parameters``, ..., ``trials``, ``counts``, ``fractions`` and
        ``ci95`` (``[low, high]``) keyed by every outcome in ``outcomes``,
        ``median_converged_time`` (of the trials that converged, or None),
        ``trial_steps`` and ``below_safety_distance`` (how many trials had a pair of
        robots closer than the safety filter's ``D_s``: the filter's promise broken);
        then ``settled`` (how many trials were settled with
        implicit Euler) and ``settled_counts``, ``settled_fractions`` and
        ``settled_ci95`` of the outcomes after settling (column
        ``settled_outcome``; ``outcome`` where the table has no such column); and
        ``shape_error`` (``median``, ``p10``, ``p90`` of the final ``max |r_ij - d_ij|``
        of the trials that did not collide: the steady-state shape error under noise or
        faults) and ``drift`` (median ``speed`` and ``|omega|`` of the rigid motion fitted
        over the drift window, where the table has it), or None without such trials.
    """
    outs = study_outcomes(trials) if outcomes is None else list(outcomes)
    out = []
    after = "settled_outcome" if "settled_outcome" in trials else "outcome"
    by_group = dict(tuple(trials.groupby("group", sort=True)))
    for g, meta in enumerate(groups):
        rows = by_group.get(g)
        n = 0 if rows is None else len(rows)
        entry = dict(meta)
        entry["trials"] = n
        entry.update(_fractions(rows, "outcome", n, outs))
        if rows is not None and n:
            ct = rows["converged_time"].to_numpy(dtype=float)
            ct = ct[np.isfinite(ct)]
            entry["median_converged_time"] = float(np.median(ct)) if ct.size else None
            entry["trial_steps"] = int(rows["steps"].sum())
        else:
            entry["median_converged_time"] = None
            entry["trial_steps"] = 0
        entry["shape_error"], entry["drift"] = _steady(rows)
        settled = 0 if rows is None or "settled" not in rows else int(rows["settled"].sum())
        below = "below_safety_distance"
        entry[below] = 0 if rows is None or below not in rows else int(rows[below].sum())
        entry["settled"] = settled
        entry.update({f"settled_{k}": v for k, v in _fractions(rows, after, n, outs).items()})
        out.append(entry)
    return out


def _steady(
    rows: pd.DataFrame | None,
) -> tuple[dict[str, float] | None, dict[str, float | None] | None]:
    """Steady-state shape error and drift of the trials that did not collide: the largest
    distance error, or bearing error for a law judged by its bearings."""
    if rows is None or "max_distance_error" not in rows:
        return None, None
    ok = rows[rows["outcome"] != "collision"]
    err = ok["max_distance_error"].to_numpy(dtype=float)
    if "max_bearing_error" in ok and np.isfinite(ok["max_bearing_error"].to_numpy(float)).any():
        err = ok["max_bearing_error"].to_numpy(dtype=float)
    err = err[np.isfinite(err)]
    if not err.size:
        return None, None
    shape = {
        "median": float(np.median(err)),
        "p10": float(np.quantile(err, 0.1)),
        "p90": float(np.quantile(err, 0.9)),
    }
    drift = None
    if "drift_speed" in ok:
        sp = ok["drift_speed"].to_numpy(dtype=float)
        om = np.abs(ok["drift_omega"].to_numpy(dtype=float))
        if np.isfinite(sp).any():
            drift = {
                "median_speed": float(np.nanmedian(sp)),
                "median_abs_omega": float(np.nanmedian(om)) if np.isfinite(om).any() else None,
            }
    return shape, drift


def _fractions(rows: pd.DataFrame | None, column: str, n: int, outs: list[str]) -> dict[str, Any]:
    """``counts``, ``fractions`` and Wilson ``ci95`` of the outcomes ``outs`` in ``column``."""
    counts: dict[str, int] = {o: 0 for o in outs}
    if rows is not None:
        for o, c in rows[column].value_counts().items():
            counts[str(o)] = int(c)
    if not n:
        return {
            "counts": counts,
            "fractions": {o: math.nan for o in outs},
            "ci95": {o: [math.nan, math.nan] for o in outs},
        }
    lo, hi = wilson_interval(np.array([counts[o] for o in outs]), n)
    return {
        "counts": counts,
        "fractions": {o: counts[o] / n for o in outs},
        "ci95": {o: [float(a), float(b)] for o, a, b in zip(outs, lo, hi, strict=True)},
    }
