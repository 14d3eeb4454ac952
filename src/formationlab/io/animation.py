"""Saving animations: GIF (pillow), MP4 (ffmpeg), HTML player.

MP4 needs an ffmpeg executable: the one of ``imageio-ffmpeg`` (the ``video``
extra: ``pip install formationlab[video]``) or one on the ``PATH``;
:func:`missing_writer` says when there is none. Every file is written to a
temporary name and renamed into place, so an interrupted save never leaves
half an animation behind.
"""

from __future__ import annotations

import html
import os
import re
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .files import atomic_path, atomic_write_text

__all__ = ["FORMATS", "ffmpeg_executable", "missing_writer", "save_animation"]

#: The formats :func:`save_animation` writes, with their file suffixes.
FORMATS = {"gif": ".gif", "mp4": ".mp4", "html": ".html"}


def ffmpeg_executable() -> str | None:
    """Path of an ffmpeg executable: imageio-ffmpeg's, else one on the PATH; None if none."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return shutil.which("ffmpeg")
    return str(imageio_ffmpeg.get_ffmpeg_exe())


def missing_writer(fmt: str) -> str | None:
    """Why ``fmt`` cannot be written here (what to install), or None when it can."""
    if fmt == "mp4" and ffmpeg_executable() is None:
        return (
            "MP4 export needs the 'video' extra: pip install formationlab[video] "
            "(or an ffmpeg on the PATH)"
        )
    return None


def save_animation(
    anim: Any,
    stem: str | os.PathLike[str],
    *,
    formats: Iterable[str] = ("gif", "mp4", "html"),
    fps: int = 15,
    written: list[Path] | None = None,
) -> list[Path]:
    """Save a :class:`matplotlib.animation.Animation` as ``stem.gif``, ``stem.mp4``, ``stem.html``.

    Parameters
    ----------
    anim : matplotlib.animation.Animation
        E.g. from :func:`formationlab.plotting.animation.animate_run`.
    stem : path-like
        Target path without suffix.
    formats : iterable of {"gif", "mp4", "html"}
        Which files to write. The HTML file is self-contained (frames embedded
        as base64 PNG, with matplotlib's JavaScript player).
    fps : int
        Frames per second.
    written : list, optional
        Each file is appended as soon as it is complete, so that a caller
        interrupted during a later format knows which files exist.

    Returns
    -------
    list of Path
        The files written.
    """
    import matplotlib as mpl
    from matplotlib.animation import FFMpegWriter, PillowWriter

    stem = Path(stem)
    written = [] if written is None else written
    for fmt in formats:
        if fmt not in FORMATS:
            raise ValueError(f"unknown animation format {fmt!r}; choose from {', '.join(FORMATS)}")
        target = stem.with_suffix(FORMATS[fmt])
        if fmt == "gif":
            with atomic_path(target) as tmp:
                anim.save(tmp, writer=PillowWriter(fps=fps))
        elif fmt == "mp4":
            missing = missing_writer(fmt)
            if missing:
                raise ModuleNotFoundError(missing)
            with (
                mpl.rc_context({"animation.ffmpeg_path": ffmpeg_executable()}),
                atomic_path(target) as tmp,
            ):
                # yuv420p + even frame size: playable in browsers and common players
                writer = FFMpegWriter(
                    fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p", "-vf", _EVEN]
                )
                anim.save(tmp, writer=writer)
        else:
            with mpl.rc_context({"animation.embed_limit": 200.0}):  # MB; frames are bounded
                player = anim.to_jshtml(fps=fps, default_mode="once")
            atomic_write_text(target, _page(player, stem.name))
        written.append(target)
    return written


_EVEN = "pad=ceil(iw/2)*2:ceil(ih/2)*2"


#: matplotlib's player links Font Awesome from a CDN for its button icons; the
#: page replaces that link with these glyphs so that it works offline.
_ICONS = {
    "fast-backward": "\\23EE",
    "step-backward": "\\23F4\\23F4",
    "play": "\\25B6",
    "pause": "\\23F8",
    "step-forward": "\\23F5\\23F5",
    "fast-forward": "\\23ED",
    "minus": "\\2212",
    "plus": "+",
}
_CSS = (
    ".fa { font-style: normal; font-family: sans-serif; }\n"
    ".fa-flip-horizontal { display: inline-block; transform: scaleX(-1); }\n"
    + "".join(f'.fa-{name}:before {{ content: "{glyph}"; }}\n' for name, glyph in _ICONS.items())
)
_CDN = re.compile(r"<link[^>]*font-awesome[^>]*>", re.DOTALL)


def _page(player: str, title: str) -> str:
    """A self-contained HTML page around matplotlib's player (no network needed)."""
    player = _CDN.sub(lambda _: f"<style>\n{_CSS}</style>", player)
    return (
        "<!DOCTYPE html>\n<html>\n<head>\n<meta charset='utf-8'>\n"
        f"<title>{html.escape(title)}</title>\n</head>\n<body>\n{player}\n</body>\n</html>\n"
    )
