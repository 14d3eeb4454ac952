"""Safe file output: atomic writes and output folders that are never overwritten unasked.

Every file formationlab writes goes through :func:`atomic_write_bytes` (or a
writer that produces a temporary file and hands it to :func:`commit_file`):
the data go to a temporary file in the same folder, are flushed to disk, and
the temporary file is renamed over the target, so a reader never sees half a
file and an interrupted run leaves the previous file intact.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OutputExistsError

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "prepare_output_dir",
    "to_jsonable",
]


@contextmanager
def atomic_path(target: str | os.PathLike[str], suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success rename it over ``target``.

    For writers that need a file name (matplotlib, netCDF, parquet). On an
    exception the temporary file is removed and ``target`` is untouched.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=suffix or target.suffix, dir=target.parent
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes it private; files are not
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(target: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically; returns the path."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)


def atomic_write_text(target: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``target`` atomically."""
    return atomic_write_bytes(target, text.encode("utf-8"))


#: Keys whose values count things (steps, evaluations, events): written as integers.
COUNT_KEY = re.compile(r"^(steps|events)$|_(steps|count|evaluations|events)$")


def _count(key: str, value: Any) -> Any:
    """``10000.0`` -> ``10000`` under a count's key (statistics are kept as floats)."""
    if COUNT_KEY.search(key) and isinstance(value, float | np.floating):
        f = float(value)
        if np.isfinite(f) and f.is_integer():
            return int(f)
    return value


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars and arrays (recursively) to plain JSON values; NaN becomes null.

    Integral values under count keys (``steps``, ``rhs_evaluations``, ``switch_count``,
    ...: :data:`COUNT_KEY`) become integers.
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(_count(str(k), v)) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        f = float(obj)
        return f if np.isfinite(f) else None
    return obj


def atomic_write_json(target: str | os.PathLike[str], data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (numpy values converted)."""
    text = json.dumps(to_jsonable(data), indent=2, allow_nan=False) + "\n"
    return atomic_write_text(target, text)


def prepare_output_dir(
    out: str | os.PathLike[str],
    *,
    force: bool = False,
    markers: tuple[str, ...] = ("summary.json",),
    describe: Callable[[Path], str] | None = None,
) -> Path:
    """Create ``out`` or check that it holds no earlier results.

    A folder that exists and is not empty is refused unless ``force`` (then
    files are replaced one by one, atomically; nothing else is deleted).

    Raises
    ------
    OutputExistsError
        When ``out`` holds files and ``force`` is false, or is a file.
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputExistsError(f"output path {path} is a file, not a folder; choose another --out")
    if path.is_dir() and any(path.iterdir()) and not force:
        found = [m for m in markers if (path / m).exists()]
        what = f" (it holds {', '.join(found)})" if found else ""
        raise OutputExistsError(
            f"output folder {path} is not empty{what}; choose another --out, or pass --force "
            "to replace its files"
        )
    path.mkdir(parents=True, exist_ok=True)
    return path
