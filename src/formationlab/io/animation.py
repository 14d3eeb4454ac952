"""Saving animations: GIF (pillow), MP4 (ffmpeg from ``imageio-ffmpeg``), HTML player.

Every file is written to a temporary name and renamed into place, so an
interrupted save never leaves half an animation behind.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .files import atomic_path, atomic_write_text

__all__ = ["FORMATS", "save_animation"]

#: The formats :func:`save_animation` writes, with their file suffixes.
FORMATS = {"gif": ".gif", "mp4": ".mp4", "html": ".html"}


def save_animation(
    anim: Any,
    stem: str | os.PathLike[str],
    *,
    formats: Iterable[str] = ("gif", "mp4", "html"),
    fps: int = 15,
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

    Returns
    -------
    list of Path
        The files written.
    """
    import matplotlib as mpl
    from matplotlib.animation import FFMpegWriter, PillowWriter

    stem = Path(stem)
    written = []
    for fmt in formats:
        if fmt not in FORMATS:
            raise ValueError(f"unknown animation format {fmt!r}; choose from {', '.join(FORMATS)}")
        target = stem.with_suffix(FORMATS[fmt])
        if fmt == "gif":
            with atomic_path(target) as tmp:
                anim.save(tmp, writer=PillowWriter(fps=fps))
        elif fmt == "mp4":
            import imageio_ffmpeg

            with (
                mpl.rc_context({"animation.ffmpeg_path": imageio_ffmpeg.get_ffmpeg_exe()}),
                atomic_path(target) as tmp,
            ):
                # yuv420p + even frame size: playable in browsers and common players
                writer = FFMpegWriter(
                    fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p", "-vf", _EVEN]
                )
                anim.save(tmp, writer=writer)
        else:
            with mpl.rc_context({"animation.embed_limit": 200.0}):  # MB; frames are bounded
                html = anim.to_jshtml(fps=fps, default_mode="once")
            atomic_write_text(target, _page(html, stem.name))
        written.append(target)
    return written


_EVEN = "pad=ceil(iw/2)*2:ceil(ih/2)*2"


def _page(player: str, title: str) -> str:
    return (
        "<!DOCTYPE html>\n<html>\n<head>\n<meta charset='utf-8'>\n"
        f"<title>{title}</title>\n</head>\n<body>\n{player}\n</body>\n</html>\n"
    )
