"""Text a user wrote (scenario names) in figures: fallback fonts, and no glyph warnings.

matplotlib draws each character with the first font of ``font.family`` that
has it (font fallback, matplotlib >= 3.6), and warns once per missing glyph,
with a source line, when none does. :func:`font_context` sets a fallback list
of the installed fonts among :data:`FALLBACK` (DejaVu Sans, which matplotlib
ships, first), and :func:`displayable` replaces the characters that none of
them has with ``?`` (and escapes ``$``, which would start mathtext), so a
name such as ``"Fórmation — 三角形"`` renders as far as the fonts allow and
never warns. :func:`missing_characters` says which characters were replaced,
for a note on the command line.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from functools import lru_cache

import matplotlib as mpl
from matplotlib import font_manager

__all__ = ["FALLBACK", "displayable", "font_context", "font_families", "missing_characters"]

#: fonts tried in order, where installed (common Linux, macOS and Windows families
#: covering Latin, Greek, Cyrillic and CJK)
FALLBACK = (
    "DejaVu Sans",
    "Noto Sans",
    "Noto Sans CJK SC",
    "Noto Sans CJK JP",
    "Noto Sans CJK KR",
    "Noto Sans CJK TC",
    "Source Han Sans SC",
    "WenQuanYi Zen Hei",
    "WenQuanYi Micro Hei",
    "Droid Sans Fallback",
    "Arial Unicode MS",
    "Microsoft YaHei",
    "PingFang SC",
    "Hiragino Sans",
    "Liberation Sans",
)


@lru_cache(maxsize=1)
def _fonts() -> tuple[tuple[str, frozenset[int]], ...]:
    """Installed fallback families with the code points of their regular font."""
    from matplotlib.ft2font import FT2Font

    out = []
    for family in FALLBACK:
        try:
            path = font_manager.findfont(
                font_manager.FontProperties(family=family), fallback_to_default=False
            )
            chars = frozenset(FT2Font(path).get_charmap())
        except (ValueError, OSError, RuntimeError):
            continue  # not installed (findfont raises ValueError) or unreadable
        out.append((family, chars))
    return tuple(out)


def font_families() -> list[str]:
    """The installed families of :data:`FALLBACK`, in order (DejaVu Sans at least)."""
    return [family for family, _ in _fonts()] or ["DejaVu Sans"]


@contextlib.contextmanager
def font_context() -> Iterator[None]:
    """Create figures inside this context to give their text the fallback fonts."""
    with mpl.rc_context({"font.family": font_families()}):
        yield


def _has(char: str) -> bool:
    return char.isspace() or any(ord(char) in chars for _, chars in _fonts())


def missing_characters(text: str) -> str:
    """The characters of ``text`` that no installed fallback font has (each once)."""
    return "".join(dict.fromkeys(c for c in text if not _has(c)))


def displayable(text: str) -> str:
    """``text`` for a figure: characters no installed font has become ``?``; ``$`` is
    escaped (matplotlib would read it as the start of a formula)."""
    return "".join(c if _has(c) else "?" for c in text).replace("$", r"\$")
