"""Saving animations: GIF (pillow), MP4 (ffmpeg), HTML player (that plays on opening).

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
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import Any

from ..engine.signals import held_signals
from .files import atomic_path, atomic_write_text

__all__ = ["FORMATS", "Progress", "ffmpeg_executable", "missing_writer", "save_animation"]

#: ``update(frames done, frames in all)``, called as the frames of a file are drawn
Progress = Callable[[int, int], None]

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
    progress: Callable[[str], AbstractContextManager[Progress]] | None = None,
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
    progress : callable, optional
        ``progress(file name)``: a context manager yielding ``update(done, total)``,
        called as the frames of each file are drawn (e.g. a progress bar).

    Returns
    -------
    list of Path
        The files written.
    """
    stem = Path(stem)
    written = [] if written is None else written
    for fmt in formats:
        if fmt not in FORMATS:
            raise ValueError(f"unknown animation format {fmt!r}; choose from {', '.join(FORMATS)}")
        target = stem.with_suffix(FORMATS[fmt])
        try:
            with nullcontext(None) if progress is None else progress(target.name) as update:
                _save(anim, fmt, target, fps, update)
        except BaseException as exc:
            # stopped (Ctrl-C) before its first frame: matplotlib would warn, as the
            # animation is deleted, that it was never rendered; its own flag says it was
            anim._draw_was_started = True
            interrupt = _interrupt_behind(exc)
            if interrupt is not None and interrupt is not exc:
                # a writer's clean-up that failed on the way out of the interrupt (Pillow's
                # with no frame yet: an IndexError): the interrupt is what happened
                raise interrupt from None
            raise
        written.append(target)
    return written


def _interrupt_behind(exc: BaseException) -> BaseException | None:
    """``exc`` or the exception it was raised while handling, if that is a Ctrl-C."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return seen
        seen = seen.__context__
    return None


def _save(anim: Any, fmt: str, target: Path, fps: int, update: Progress | None) -> None:
    """Write one format of ``anim`` to ``target`` atomically (each frame drawn once)."""
    import matplotlib as mpl
    from matplotlib.animation import FFMpegWriter, HTMLWriter, PillowWriter

    def callback(done: int, total: int) -> None:
        if update is not None:
            update(done + 1, total)

    if fmt == "gif":
        with atomic_path(target) as tmp:
            anim.save(tmp, writer=PillowWriter(fps=fps), progress_callback=callback)
    elif fmt == "mp4":
        missing = missing_writer(fmt)
        if missing:
            raise ModuleNotFoundError(missing)
        with (
            mpl.rc_context({"animation.ffmpeg_path": ffmpeg_executable()}),
            atomic_path(target) as tmp,
        ):
            # yuv420p + even frame size: playable in browsers and common players
            writer = _encoder(FFMpegWriter)(
                fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p", "-vf", _EVEN]
            )
            anim.save(tmp, writer=writer, progress_callback=callback)
    else:  # what Animation.to_jshtml does, with the progress callback
        with (
            mpl.rc_context({"animation.embed_limit": 200.0}),  # MB; frames are bounded
            tempfile.TemporaryDirectory() as tmpdir,
        ):
            page = Path(tmpdir, "player.html")
            html_writer = HTMLWriter(fps=fps, embed_frames=True, default_mode="once")
            anim.save(str(page), writer=html_writer, progress_callback=callback)
            player = page.read_text(encoding="utf-8")
        atomic_write_text(target, _page(player, target.stem))


_EVEN = "pad=ceil(iw/2)*2:ceil(ih/2)*2"


def _encoder(base: type) -> type:
    """matplotlib's ffmpeg writer ``base`` whose encoder never outlives a save that stopped
    (Ctrl-C or SIGTERM to formationlab alone, at any frame, the first and the last too).

    matplotlib ends the encoder only once it has started the frames: a signal while the
    encoder's process started (inside ``subprocess.Popen``) left it running unknown, and it
    wrote the temporary file after :func:`~formationlab.io.files.atomic_path` had removed it
    (a ``.animation.mp4.*`` left behind); one while the last frames were encoded left it
    encoding. Here the process starts whole (signals held meanwhile), and is killed and
    waited for before the save goes on stopping.
    """

    class Encoder(base):  # type: ignore[misc,valid-type]
        def setup(self, *args: Any, **kwargs: Any) -> None:
            with held_signals():  # (started whole: its process is known when a signal stops it)
                super().setup(*args, **kwargs)

        @contextmanager
        def saving(self, *args: Any, **kwargs: Any) -> Iterator[Any]:
            try:
                with super().saving(*args, **kwargs) as writer:
                    yield writer
            except BaseException:
                with held_signals():  # (a second Ctrl-C waits until it has ended)
                    proc = getattr(self, "_proc", None)
                    if proc is not None:
                        if proc.poll() is None:
                            proc.kill()
                        proc.communicate()  # (waited for, its pipes closed)
                raise

    return Encoder


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
#: the name of the player object in matplotlib's page (``anim<hex id> = new Animation(``)
_PLAYER = re.compile(r"\b(anim[0-9a-f]+) = new Animation\(")
#: plays the animation once the page has loaded (the player is made at the first timeout)
_AUTOPLAY = (
    "<script>\nwindow.addEventListener('load', function () {{\n"
    "  setTimeout(function () {{ {name}.play_animation(); }}, 50);\n}});\n</script>\n"
)


def _page(player: str, title: str) -> str:
    """A self-contained HTML page around matplotlib's player (no network needed) that
    starts playing when it is opened."""
    player = _CDN.sub(lambda _: f"<style>\n{_CSS}</style>", player)
    found = _PLAYER.search(player)
    autoplay = _AUTOPLAY.format(name=found.group(1)) if found else ""
    return (
        "<!DOCTYPE html>\n<html>\n<head>\n<meta charset='utf-8'>\n"
        f"<title>{html.escape(title)}</title>\n</head>\n<body>\n{player}\n{autoplay}"
        "</body>\n</html>\n"
    )
