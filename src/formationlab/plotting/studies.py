"""Plots of a Monte-Carlo study: outcome fractions against a swept parameter, final shapes.

They read what ``formationlab study`` writes: the ``groups`` of ``summary.json``
and the trials table (``trials.parquet``), so a study can be re-plotted later.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from .units import with_unit

if TYPE_CHECKING:  # pandas only names the type of a study's table (importing it costs ~1 s)
    import pandas as pd

__all__ = [
    "OUTCOME_COLORS",
    "desired_figure",
    "draw_velocity",
    "fractions_figure",
    "plot_fractions",
    "plot_shape",
    "shapes_figure",
    "study_figures",
]

#: One colour per outcome, the same in every study plot.
OUTCOME_COLORS = {
    "desired": "tab:green",
    "mirror": "tab:blue",
    "incorrect": "tab:orange",
    "collision": "tab:red",
    "drifting": "tab:purple",
    "rotating": "tab:brown",
    "not-converged": "tab:gray",
    "diverged": "black",
}


def _new_axes(ax: Axes | None, figsize: tuple[float, float] = (5.0, 3.5)) -> Axes:
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=figsize)
    return ax


def _err(g: dict[str, Any], outcome: str) -> tuple[float, float, float]:
    p = g["fractions"][outcome]
    lo, hi = g["ci95"][outcome]
    return p, max(p - lo, 0.0), max(hi - p, 0.0)


def plot_fractions(
    groups: Sequence[dict[str, Any]],
    parameter: str | None,
    ax: Axes | None = None,
    *,
    outcomes: Sequence[str] | None = None,
    title: str | None = None,
) -> list[Any]:
    """Outcome fractions of one law's groups against ``parameter``, with 95 % Wilson bars.

    Parameters
    ----------
    groups : sequence of dict
        Entries of ``summary["groups"]`` of one law (``parameters``, ``fractions``, ``ci95``).
    parameter : str or None
        The swept parameter on the x axis. A law that does not have it (one group,
        ``parameter`` not in its ``parameters``) is drawn as a horizontal line with
        its interval shaded, for comparison across the whole axis.
    outcomes : sequence of str, optional
        Outcomes to draw (default: those that occur in some group).

    Returns
    -------
    list of artists
    """
    ax = _new_axes(ax)
    outs = list(outcomes or _present(groups))
    artists: list[Any] = []
    flat = parameter is None or any(parameter not in g["parameters"] for g in groups)
    for o in outs:
        c = OUTCOME_COLORS.get(o)
        if flat:
            p, lo, hi = _err(groups[0], o)
            artists.append(ax.axhline(p, color=c, label=o, lw=1.5))
            artists.append(ax.axhspan(p - lo, p + hi, color=c, alpha=0.15, lw=0))
            continue
        xs = np.array([g["parameters"][parameter] for g in groups], dtype=float)
        order = np.argsort(xs)
        vals = np.array([_err(g, o) for g in groups])[order]
        artists.append(
            ax.errorbar(
                xs[order],
                vals[:, 0],
                yerr=vals[:, 1:].T,
                color=c,
                marker="o",
                ms=4,
                capsize=3,
                label=o,
            )
        )
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("fraction of trials (dimensionless)")
    if parameter is not None:
        ax.set_xlabel(with_unit(parameter))
        if not flat:
            _log_if_wide(ax, [g["parameters"][parameter] for g in groups])
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    return artists


def _log_if_wide(ax: Axes, values: Sequence[float]) -> None:
    """A logarithmic x axis for positive values spanning a factor of 20 or more."""
    v = np.asarray(values, dtype=float)
    if v.size and np.all(v > 0) and v.max() >= 20 * v.min():
        ax.set_xscale("log")


def _present(groups: Sequence[dict[str, Any]]) -> list[str]:
    outs = list(groups[0]["fractions"]) if groups else []
    return [o for o in outs if any(g["counts"][o] > 0 for g in groups)] or outs[:1]


def _laws(groups: Sequence[dict[str, Any]]) -> list[str]:
    return list(dict.fromkeys(g["law"] for g in groups))


def fractions_figure(
    groups: Sequence[dict[str, Any]], parameter: str | None, *, title: str | None = None
) -> Figure:
    """One panel per law: outcome fractions against ``parameter`` (:func:`plot_fractions`)."""
    import matplotlib.pyplot as plt

    laws = _laws(groups)
    outs = _present(groups)
    fig, axes = plt.subplots(
        1,
        len(laws),
        figsize=(3.6 * len(laws) + 0.6, 3.8),
        sharex=True,
        sharey=True,
        squeeze=False,
        layout="constrained",
    )
    for ax, law in zip(axes[0], laws, strict=True):
        mine = [g for g in groups if g["law"] == law]
        plot_fractions(mine, parameter, ax, outcomes=outs, title=law)
        if ax is not axes[0, 0]:
            ax.set_ylabel("")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    ncol = len(outs) if len(laws) > 1 else min(len(outs), 3)
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, frameon=False)
    if title:
        fig.suptitle(title)
    return fig


def desired_figure(
    groups: Sequence[dict[str, Any]], parameter: str | None, *, title: str | None = None
) -> Figure:
    """Fraction ending in the desired formation, every law on one axes, 95 % Wilson bars."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    laws = _laws(groups)
    styles = itertools.cycle(["o-", "s--", "^-.", "D:", "v-"])
    colors = [f"C{i}" for i in range(10)]
    swept: list[float] = []
    for law, style, color in zip(laws, styles, itertools.cycle(colors), strict=False):
        mine = [g for g in groups if g["law"] == law]
        if parameter is None or any(parameter not in g["parameters"] for g in mine):
            p, lo, hi = _err(mine[0], "desired")
            ax.axhline(p, ls=style[1:] or "-", label=f"{law} (no {parameter})", color=color)
            ax.axhspan(p - lo, p + hi, alpha=0.12, lw=0, color=color)
            continue
        swept += [g["parameters"][parameter] for g in mine]
        xs = np.array([g["parameters"][parameter] for g in mine], dtype=float)
        order = np.argsort(xs)
        vals = np.array([_err(g, "desired") for g in mine])[order]
        ax.errorbar(
            xs[order],
            vals[:, 0],
            yerr=vals[:, 1:].T,
            fmt=style,
            ms=4,
            capsize=3,
            label=law,
            color=color,
        )
    ax.set_ylim(-0.02, 1.02)
    xlabel = with_unit(parameter) if parameter else ""
    return _finish(fig, ax, swept, xlabel, "fraction desired (dimensionless)", title)


def _finish(
    fig: Figure, ax: Axes, swept: Sequence[float], xlabel: str, ylabel: str, title: str | None
) -> Figure:
    """Labels, grid, legend and title of a figure against a swept parameter."""
    _log_if_wide(ax, swept)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def plot_shape(
    q: np.ndarray,
    edges: np.ndarray,
    diameters: np.ndarray,
    ax: Axes | None = None,
    *,
    color: Any = "k",
    labels: bool = True,
) -> list[Any]:
    """A formation's shape: robots as discs of their diameter, edges as lines.

    ``q`` ``(n, 2)``; ``edges`` ``(m, 2)`` 0-based; robots labelled 1-based.
    """
    ax = _new_axes(ax, (2.5, 2.5))
    q = np.asarray(q, dtype=float)
    segs = np.stack([q[edges[:, 0]], q[edges[:, 1]]], axis=1)
    lc = LineCollection(list(segs), colors=color, linewidths=1.0, alpha=0.7)
    ax.add_collection(lc)
    artists: list[Any] = [lc]
    for i, (x, y) in enumerate(q):
        disc = Circle((x, y), 0.5 * float(diameters[i]), fc="white", ec=color, lw=1.0, zorder=3)
        ax.add_patch(disc)
        artists.append(disc)
        if labels:
            artists.append(
                ax.text(x, y, str(i + 1), ha="center", va="center", fontsize=6, zorder=4)
            )
    ax.set_aspect("equal")
    ax.autoscale_view()
    return artists


def shapes_figure(
    trials: pd.DataFrame,
    edges: np.ndarray,
    diameters: dict[int, np.ndarray],
    *,
    law: str,
    per_outcome: int = 6,
    skip: Sequence[str] = ("desired",),
) -> Figure | None:
    """Final shapes of a law's trials that did not end in the desired formation.

    One row per outcome (mirror, incorrect, collision, drifting, rotating,
    not-converged: those that occur), up to ``per_outcome`` trials each, the first
    ones by group and trial; a drifting or rotating shape carries the arrow of its
    centroid's velocity (one second of motion, less where that would leave the panel).
    Each panel is centred on the shape's centroid. ``diameters`` maps a group to its
    robots' diameters. Returns None when every trial of the law ended as desired.
    """
    import matplotlib.pyplot as plt

    rows = trials[(trials["law"] == law) & ~trials["outcome"].isin(list(skip))]
    outs = [o for o in OUTCOME_COLORS if o not in skip and (rows["outcome"] == o).any()]
    if not outs:
        return None
    n = max(int(c[1:]) for c in trials.columns if c[:1] == "x" and c[1:].isdigit())
    cols = [[f"{a}{i + 1}" for i in range(n)] for a in "xyz" if f"{a}1" in trials.columns]
    fig, axes = plt.subplots(
        len(outs), per_outcome, figsize=(1.6 * per_outcome, 1.75 * len(outs)), squeeze=False
    )
    params = [c for c in trials.columns if c not in _FIXED and not _is_position(c)]
    for r, o in enumerate(outs):
        pick = rows[rows["outcome"] == o].head(per_outcome)
        for c in range(per_outcome):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c >= len(pick):
                ax.axis("off")
                continue
            row = pick.iloc[c]
            q = np.stack([row[c].to_numpy(float) for c in cols], axis=1)
            q = q - q.mean(axis=0)
            # in space: seen along its least extent (its two principal axes on the panel)
            basis = np.linalg.svd(q, full_matrices=False)[2][:2] if q.shape[1] == 3 else None
            if basis is not None:
                q = q @ basis.T
            plot_shape(q, edges, diameters[int(row["group"])], ax, color=OUTCOME_COLORS[o])
            extra = "".join(f" {p}={row[p]:g}" for p in params if np.isfinite(row[p]))
            err = f"\n|e|max={row['max_distance_error']:.2g} m"
            if np.isfinite(row.get("max_bearing_error", np.nan)):  # judged by its bearings
                err = f"\n|g-g*|max={row['max_bearing_error']:.2g}"
            if o in ("drifting", "rotating") and "drift_vx" in row:
                v = np.array([row[f"drift_v{a}"] for a in "xyz"[: len(cols)]], dtype=float)
                v = v if basis is None else basis @ v
                extent = float(np.ptp(q, axis=0).max())
                speed = max(float(np.hypot(*v)), 1e-300)
                draw_velocity(
                    ax,
                    np.zeros(2),
                    v,
                    color=OUTCOME_COLORS[o],
                    scale=min(1.0, 0.4 * extent / speed),
                )
                err += f" |v|={np.hypot(*v):.2f} m/s"
                if o == "rotating":
                    err += f" w={row['drift_omega']:.2f} rad/s"
            ax.set_title(f"#{int(row['trial'])}{extra}{err}", fontsize=7)
            if c == 0:
                ax.set_ylabel(o, fontsize=8, color=OUTCOME_COLORS[o])
    fig.suptitle(f"{law}: final shapes that are not the desired formation", fontsize=9)
    fig.tight_layout()
    return fig


_FIXED = {
    "group",
    "trial",
    "seed",
    "law",
    "outcome",
    "settled",
    "settled_outcome",
    "max_distance_error",
    "max_bearing_error",
    "converged_time",
    "net_speed",
    "min_clearance",
    "steps",
    "drift_vx",
    "drift_vy",
    "drift_vz",
    "drift_speed",
    "drift_omega",
    "drift_cx",
    "drift_cy",
    "drift_cz",
    "drift_ax",
    "drift_ay",
    "drift_az",
    "shape_rate",
}


def draw_velocity(
    ax: Axes, at: np.ndarray, v: np.ndarray, *, color: str | None = None, scale: float = 1.0
) -> Any:
    """An arrow of the velocity ``v`` ``(2,)`` from the point ``at`` (``scale`` s of motion)."""
    return ax.annotate(
        "",
        xy=(at[0] + scale * v[0], at[1] + scale * v[1]),
        xytext=(at[0], at[1]),
        arrowprops={"arrowstyle": "-|>", "color": color or "k", "lw": 1.2},
    )


def _is_position(c: str) -> bool:
    return c[:1] in ("x", "y", "z") and c[1:].split("_")[0].isdigit()


def shape_error_figure(
    groups: Sequence[dict[str, Any]], parameter: str, *, title: str | None = None
) -> Figure | None:
    """Steady-state shape error (median, 10-90 % band) of every law against ``parameter``.

    None when no group has a shape error (every trial collided).
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    drawn = False
    swept: list[float] = []
    for law, style, color in zip(
        _laws(groups), itertools.cycle(["o-", "s--", "^-.", "D:", "v-"]),
        itertools.cycle([f"C{i}" for i in range(10)]), strict=False,
    ):  # fmt: skip
        mine = [g for g in groups if g["law"] == law and g.get("shape_error")]
        mine = [g for g in mine if parameter in g["parameters"]]
        if not mine:
            continue
        xs = np.array([g["parameters"][parameter] for g in mine], dtype=float)
        order = np.argsort(xs)
        med, lo, hi = (
            np.array([g["shape_error"][k] for g in mine])[order] for k in ("median", "p10", "p90")
        )
        ax.plot(xs[order], med, style, ms=4, color=color, label=law)
        ax.fill_between(xs[order], lo, hi, color=color, alpha=0.15, lw=0)
        swept += list(xs)
        drawn = True
    if not drawn:
        plt.close(fig)
        return None
    ax.set_yscale("symlog", linthresh=1e-3)  # the error can be 0: linear below 1e-3
    ylabel = r"final max $|r_{ij} - d_{ij}|$ [m], symlog: linear below 0.001"
    return _finish(fig, ax, swept, with_unit(parameter), ylabel, title)


def study_figures(
    summary: dict[str, Any], trials: pd.DataFrame, edges: np.ndarray
) -> dict[str, Figure]:
    """Every figure of a study by file stem.

    ``fractions[_K=V...]``: outcome fractions per law against the first swept
    parameter (one figure per value of the other swept parameters);
    ``desired[...]``: the desired fraction of every law on one axes;
    ``shape_error[...]``: the steady-state shape error of every law (with a sweep);
    ``shapes_<law>``: final shapes of the non-desired outcomes.
    """
    groups = summary["groups"]
    keys = list(summary.get("sweep") or {})
    x = keys[0] if keys else None
    others = keys[1:]
    figs: dict[str, Figure] = {}
    combos = itertools.product(*(summary["sweep"][k] for k in others)) if others else [()]
    for combo in combos:
        fix = dict(zip(others, combo, strict=True))
        mine = [g for g in groups if all(g["parameters"].get(k, v) == v for k, v in fix.items())]
        tag = "".join(f"_{k}={v:g}" for k, v in fix.items())
        title = ", ".join(f"{k} = {v:g}" for k, v in fix.items()) or None
        figs[f"fractions{tag}"] = fractions_figure(mine, x, title=title)
        figs[f"desired{tag}"] = desired_figure(mine, x, title=title)
        if x is not None:
            err = shape_error_figure(mine, x, title=title)
            if err is not None:
                figs[f"shape_error{tag}"] = err
    diam = {int(g["group"]): np.asarray(g["diameters"], dtype=float) for g in groups}
    for law in _laws(groups):
        fig = shapes_figure(trials, np.asarray(edges), diam, law=law)
        if fig is not None:
            figs[f"shapes_{law}"] = fig
    return figs
