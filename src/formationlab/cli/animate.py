"""Command ``animate`` and the animation step of ``run``: a run's trajectory as GIF, MP4, HTML."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from numpy.typing import NDArray

from ..errors import OutputExistsError, ParameterError, UserInputError
from ._app import INTERRUPTED, command, err_console, fail, warn
from ._progress import progress_bar, shows_progress

__all__: list[str] = []

ANIMATION_STEM = "animation"
FORMATS_ALL = ("gif", "mp4", "html")


def usable_formats(formats: tuple[str, ...], *, explicit: bool) -> tuple[str, ...]:
    """The formats that can be written; a missing writer is an error when the format was
    asked for by name, else a warning and the format is left out."""
    from ..io.animation import missing_writer

    keep = []
    for f in formats:
        missing = missing_writer(f)
        if missing and explicit:
            raise ParameterError(missing)
        if missing:
            warn(f"{ANIMATION_STEM}.{f} left out: {missing}")
        else:
            keep.append(f)
    return tuple(keep)


def write_animation(
    folder: Path,
    result_or_ds: Any,
    title: str,
    frames: int,
    formats: tuple[str, ...] = FORMATS_ALL,
    done: list[Path] | None = None,
    *,
    progress: bool = False,
) -> list[Path]:
    """Animate a run (a SimulationResult, or the Dataset of its trajectory.nc, opened lazily)
    into ``folder/animation.*``; each file is appended to ``done`` once complete.

    Only the saved states the animation draws are read (its frames and its trails'
    states, :func:`formationlab.plotting.animation.used_indices`), so memory is bounded
    by the frames, not by the run. ``progress`` shows a bar per file on a terminal.
    """
    from ..io.animation import FORMATS, save_animation
    from ..io.files import atomic_write_text
    from ..plotting.animation import animate_run, frame_indices, used_indices
    from ..plotting.html_player import player_page
    from ..plotting.many import LABEL_LIMIT

    safety: dict[str, Any] = {}
    faults: dict[str, Any] | None = None
    if hasattr(result_or_ds, "formation"):
        r = result_or_ds
        faults = None if r.faults is None else r.faults.describe()
        rows = used_indices(r.t, frames, r.formation.n, r.q)
        t, q, edges, diam = r.t[rows], r.q[rows], r.formation.edges, r.formation.diameters
        headings = None if r.headings is None else r.headings[rows]
        points = None if r.points is r.q else r.points[rows]
        if r.safety is not None:
            safety = {
                "obstacles": r.safety.obstacles,
                "active": r.safety.active[rows],
                "active_pairs": _pairs_at(np.asarray(r.safety.active_pairs), rows),
            }
    else:
        ds = result_or_ds
        try:
            t_all = ds["time"].values
            rows = used_indices(t_all, frames, ds.sizes["robot"], ds["q"])  # lazily: its rows
            part = ds.isel(time=rows)
            t, q = t_all[rows], part["q"].values
            edges, diam = ds["edge_robots"].values - 1, ds["diameter"].values
            headings = part["theta"].values if "theta" in ds else None
            points = part["point"].values if "point" in ds else None
            faults = json.loads(str(ds.attrs["faults"])) if "faults" in ds.attrs else None
            if "filter_active" in ds:
                safety = {
                    "obstacles": json.loads(str(ds.attrs.get("obstacles", "[]"))),
                    "active": part["filter_active"].values.astype(bool),
                    "active_pairs": _pairs_at(
                        ds["active_pair"].values.reshape(-1, 3) - [0, 1, 1], rows
                    ),
                }
        except (OSError, RuntimeError, KeyError, ValueError) as exc:  # h5py's, on a damaged file
            raise damaged(ds.encoding.get("source", "trajectory.nc"), exc) from None
    stops = [(s["robot"] - 1, s["at"]) for s in (faults or {}).get("stop", [])]
    # a run in the plane of discs and edges only: its HTML page draws the states itself
    page = "html" in formats and q.shape[-1] == 2 and q.shape[1] <= LABEL_LIMIT
    same = points is None or np.array_equal(points, q)  # the law's points are the robots'
    page = page and headings is None and same and not safety and not stops
    drawn = tuple(f for f in formats if not (page and f == "html"))
    written = done if done is not None else []
    if drawn:
        anim = animate_run(
            t, q, edges=edges, diameters=diam, max_frames=frames, title=title,
            headings=headings, points=points, **safety, stops=stops,
        )  # fmt: skip
        save_animation(
            anim, folder / ANIMATION_STEM, formats=drawn, written=written,
            progress=_frames_progress() if progress else None,
        )  # fmt: skip
    if page:
        target = (folder / ANIMATION_STEM).with_suffix(FORMATS["html"])
        if progress and not shows_progress(False):
            _note_writing(target.name)
        text = player_page(
            t, q, frame_indices(t, frames, q), edges=edges, diameters=diam, title=title
        )
        atomic_write_text(target, text)
        written.append(target)
    return list(written)


def _pairs_at(pairs: NDArray[np.int64], rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """Active pair constraints ``(time index, i, j)`` at the saved states ``rows``, with the
    time index renumbered into ``rows``."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 3)
    keep = np.isin(pairs[:, 0], rows)
    out = pairs[keep].copy()
    out[:, 0] = np.searchsorted(rows, out[:, 0])
    return out


@contextmanager
def _progress_bar(label: str) -> Iterator[Callable[[int, int], None]]:
    """A transient progress bar of the frames of one file; yields ``update(done, total)``."""
    with progress_bar(f"writing {label}") as update:
        yield update


def _frames_progress() -> Callable[[str], Any]:
    """A bar per file on a terminal, a line per file in a log."""
    return _progress_bar if shows_progress(False) else _progress_line


@contextmanager
def _progress_line(label: str) -> Iterator[Callable[[int, int], None]]:
    """In a log (not a terminal): one line as the frames of a file start being drawn."""
    _note_writing(label)
    yield lambda done, total: None


def run_trajectory(folder: Path) -> Path:
    """``folder/trajectory.nc``, or an error saying what to give: the ``--out`` folder of
    ``formationlab run``."""
    if not folder.is_dir():
        raise UserInputError(
            f"{folder} is not a folder; give the --out folder of `formationlab run`"
        )
    nc = folder / "trajectory.nc"
    if not nc.is_file():
        raise UserInputError(
            f"{folder} holds no trajectory.nc; run `formationlab run SCENARIO --out {folder}` first"
        )
    return nc


def damaged(nc: Any, exc: BaseException) -> UserInputError:
    """The error of a run's file that cannot be read whole (damaged: overwritten, cut short)."""
    reason = str(exc).strip() or type(exc).__name__
    reason = reason[:1].lower() + reason[1:]
    return UserInputError(
        f"cannot read {nc}: {reason}; the file is damaged: run `formationlab run` again to "
        "write it anew"
    )


def open_run(nc: Path) -> Any:
    """The run's ``trajectory.nc`` opened lazily (close it), checked to be formationlab's."""
    from ..io.netcdf import open_trajectory

    try:
        ds = open_trajectory(nc)
    except (OSError, ValueError) as exc:
        raise UserInputError(f"cannot read {nc} as netCDF: {exc}") from None
    if "q" not in ds or "edge_robots" not in ds:
        ds.close()
        raise UserInputError(f"{nc} is not a formationlab trajectory (no q or edge_robots)")
    return ds


def _note_writing(label: str) -> None:
    err_console.print(f"writing {label} ...", markup=False, highlight=False)


@command(
    "animate",
    epilog="Example:  formationlab animate runs/sim2 --frames 100 --format gif,html",
)
def animate_cmd(
    folder: Annotated[Path, typer.Argument(help="Output folder of `formationlab run`.")],
    frames: Annotated[
        int, typer.Option(min=2, help="Most frames in the animation (the run is thinned).")
    ] = 150,
    fmt: Annotated[
        list[str] | None,
        typer.Option(
            "--format", "-f", help="gif, mp4 or html, a comma-separated list (default: all three)."
        ),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Replace an existing animation in the folder.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress.")] = False,
) -> None:
    """Animate a finished run: robots as discs of their diameters and the graph's edges.

    A run in space (axis x, y, z) is drawn on 3-D axes of one scale, the robots as
    numbered points, under a camera that turns a degree per frame.

    Reads DIR/trajectory.nc and writes DIR/animation.gif (pillow),
    DIR/animation.mp4 (ffmpeg from imageio-ffmpeg) and DIR/animation.html (a
    self-contained player that plays when opened; for a run in the plane of up to 12
    robots without obstacles, filter, headings or stops, a page that draws the states
    itself, a few hundred kB), with at most --frames frames, spaced half by time and half
    by the robots' motion (the transient gets most of them).
    """
    from ..io.animation import FORMATS
    from ..io.figures import chosen_formats

    formats = tuple(FORMATS)
    if fmt:  # (a comma-separated list, or the option repeated)
        formats = chosen_formats(fmt, FORMATS, what="animation", example="gif,html")
    formats = usable_formats(formats, explicit=bool(fmt))
    nc = run_trajectory(folder)
    from ..io.claim import claim_folder

    claim_folder(folder)  # (no other command writes into the run's folder meanwhile)
    existing = [
        (folder / ANIMATION_STEM).with_suffix(FORMATS[f]).name
        for f in formats
        if (folder / ANIMATION_STEM).with_suffix(FORMATS[f]).exists()
    ]
    if existing and not force:
        raise OutputExistsError(
            f"{folder} already holds {', '.join(existing)}; pass --force to replace it"
        )
    from ..engine.signals import held_signals

    done: list[Path] = []
    stopped = False
    with open_run(nc) as ds:
        title = str(ds.attrs.get("scenario_name", folder.name))
        try:
            write_animation(folder, ds, title, frames, formats, done, progress=not quiet)
        except (KeyboardInterrupt, subprocess.CalledProcessError):  # Ctrl-C, also killing ffmpeg
            stopped = True
    try:  # what was written is listed and said whole; a signal meanwhile comes after it
        with held_signals():
            add_to_manifest(folder, [p.name for p in done])
            for p in done:
                typer.echo(f"wrote {p}")
    except KeyboardInterrupt:
        stopped = True
    if stopped:
        fail(_kept(folder, done, formats), INTERRUPTED)


def _kept(folder: Path, done: list[Path], formats: tuple[str, ...]) -> str:
    """What an interrupted ``animate`` says: which animations it wrote whole, which not."""
    if not done:
        return f"interrupted before an animation was written whole; {folder} is as it was"
    names = [p.name for p in done]
    left = [f for f in formats if (folder / ANIMATION_STEM).with_suffix(f".{f}").name not in names]
    rest = f" (not {', '.join(f'{ANIMATION_STEM}.{f}' for f in left)})" if left else ""
    return f"interrupted; {', '.join(names)} written whole in {folder}{rest}"


def add_to_manifest(folder: Path, names: list[str]) -> None:
    """List ``names`` in the manifest of the run's summary.json (when there is one)."""
    from ..io.files import MANIFEST, atomic_write_json

    path = folder / "summary.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return  # no summary (an interrupted run's folder, or not ours): nothing to list in
    if isinstance(data, dict) and isinstance(data.get(MANIFEST), list):
        data[MANIFEST] = [*data[MANIFEST], *(n for n in names if n not in data[MANIFEST])]
        atomic_write_json(path, data)
