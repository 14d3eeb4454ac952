"""Safe file output: atomic writes and output folders that are never overwritten unasked.

Every file formationlab writes goes through :func:`atomic_write_bytes` (or a
writer that produces a temporary file and hands it to :func:`commit_file`):
the data go to a temporary file in the same folder, are flushed to disk, and
the temporary file is renamed over the target, so a reader never sees half a
file and an interrupted run leaves the previous file intact.
"""

from __future__ import annotations

import errno
import json
import os
import re
import secrets
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OutputError, OutputExistsError
from .claim import LOCK_NAME, claim_folder, release_claim

__all__ = [
    "KeptFolder",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "earlier_files",
    "output_error",
    "prepare_output_dir",
    "remove_stale",
    "remove_temporaries",
    "to_jsonable",
]

#: what to do about a failed write, by errno
_FIXES = {
    errno.EACCES: "choose a folder you can write to",
    errno.EPERM: "choose a folder you can write to",
    errno.EROFS: "the file system is read-only; choose another folder",
    errno.ENOSPC: "free some space or choose a folder on another disk",
    errno.EDQUOT: "your disk quota is used up; free some space or choose another folder",
    errno.EFBIG: "the file is larger than this system lets a file be (a file-size limit); "
    "choose another folder, or store fewer states with --save-every",
}


def output_error(
    exc: OSError, folder: str | os.PathLike[str], what: str = "write to"
) -> OutputError:
    """An :class:`~formationlab.errors.OutputError` naming ``folder`` and the reason of ``exc``.

    E.g. ``"cannot write to runs/a: permission denied; choose a folder you can write to"``.
    A path below a regular file is named as such (``"runs is a file, not a folder"``).
    """
    folder = Path(folder)
    reason = (exc.strerror or str(exc) or type(exc).__name__).rstrip(".")
    reason = reason[:1].lower() + reason[1:]
    fix = _FIXES.get(exc.errno or 0, "")
    if exc.errno in (errno.ENOTDIR, errno.EEXIST):
        for parent in (folder, *folder.parents):
            if parent.is_file():
                reason, fix = f"{parent} is a file, not a folder", "choose another folder"
                break
    return OutputError(f"cannot {what} {folder}: {reason}" + (f"; {fix}" if fix else ""))


@contextmanager
def atomic_path(target: str | os.PathLike[str], suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success rename it over ``target``.

    For writers that need a file name (matplotlib, netCDF, parquet). On an
    exception the temporary file is removed and ``target`` is untouched.
    Any ``OSError`` on the way (permission, disk full, a path under a file)
    becomes an :class:`~formationlab.errors.OutputError` naming the folder.
    """
    target = Path(target)
    tmp_path: Path | None = None
    try:
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            # the name is chosen before the file exists, so that a signal at any moment
            # (even inside the call that creates it) leaves a name to remove
            while True:
                tmp_path = _temporary_name(target, suffix or target.suffix)
                try:
                    os.close(os.open(tmp_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
                    break
                except FileExistsError:  # another writer's: not ours to remove
                    tmp_path = None
        except OSError as exc:
            raise output_error(exc, target.parent) from exc
        try:
            yield tmp_path
            with open(tmp_path, "rb+") as fh:
                os.fsync(fh.fileno())
            os.chmod(tmp_path, 0o666 & ~_umask())  # created private; files are not
            os.replace(tmp_path, target)
        except OSError as exc:
            raise output_error(exc, target.parent, f"write {target.name} in") from exc
    finally:
        if tmp_path is not None and tmp_path.exists():
            tmp_path.unlink()


def _temporary_name(target: Path, suffix: str) -> Path:
    """A hidden name beside ``target`` (``.NAME.RANDOM.SUFFIX``, as mkstemp would choose)."""
    return target.with_name(f".{target.name}.{secrets.token_hex(4)}{suffix}")


#: the names :func:`_temporary_name` chooses: ``.NAME.`` eight hex digits, the suffix
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.[0-9a-f]{8}(?P<suffix>\.[^./]+)?$")


def remove_temporaries(folder: str | os.PathLike[str]) -> list[str]:
    """Remove the temporary files (:func:`atomic_path`'s) that a killed writer left in
    ``folder``; returns their names.

    Only for a folder this process has claimed (:func:`~formationlab.io.claim.claim_folder`):
    no other writer is then using them.
    """
    folder = Path(folder)
    removed = []
    for p in sorted(folder.iterdir()):
        m = _TEMPORARY.match(p.name)
        if m and p.is_file() and (m["suffix"] or "") in ("", Path(m["name"]).suffix):
            try:
                p.unlink()
            except OSError as exc:
                raise output_error(exc, folder, f"remove the temporary file {p.name} from") from exc
            removed.append(p.name)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(target: str | os.PathLike[str], data: bytes | memoryview) -> Path:
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
    """Create ``out`` or check that it holds no earlier results, and claim it.

    The folder is claimed for this process (:func:`~formationlab.io.claim.claim_folder`)
    until the command ends (:func:`~formationlab.io.claim.release_claims`; at the latest
    when the process exits): a second command writing into it meanwhile is refused
    (:class:`~formationlab.errors.FolderBusyError`), whatever ``force``. A folder that
    exists and is not empty is refused unless ``force``; then the temporary files a
    killed writer left are removed (:func:`remove_temporaries`), files are replaced one by
    one, atomically, and the command removes what the earlier run wrote and this one does
    not (:func:`earlier_files`, :func:`remove_stale`) once its own results are written.

    Raises
    ------
    FolderBusyError
        When another process is writing into ``out``.
    OutputExistsError
        When ``out`` holds files and ``force`` is false, or is a file.
    OutputError
        When the folder cannot be created (permission, a path under a file, ...).
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputExistsError(f"output path {path} is a file, not a folder; choose another --out")
    created = not path.exists()
    try:
        path.mkdir(parents=True, exist_ok=True)
        claim_folder(path)
    except OutputError:
        raise
    except OSError as exc:
        raise output_error(exc, path, "create the folder" if created else "claim") from exc
    if not force and any(p.name != LOCK_NAME for p in path.iterdir()):
        release_claim(path)
        found = [m for m in markers if (path / m).exists()]
        what = f" (it holds {', '.join(found)})" if found else ""
        raise OutputExistsError(
            f"output folder {path} is not empty{what}; choose another --out, or pass --force "
            "to replace its files"
        )
    if force:
        remove_temporaries(path)
    return path


#: key of summary.json listing the files a command wrote (names relative to the folder)
MANIFEST = "manifest"


def earlier_files(folder: str | os.PathLike[str], patterns: Iterable[str] = ()) -> list[str]:
    """Names of the files an earlier run wrote in ``folder`` (to replace them under --force).

    The manifest of the folder's ``summary.json`` when it has one (key
    :data:`MANIFEST`, or ``files`` in summaries of older versions), and
    otherwise, or in addition, the files that match ``patterns`` (globs such as
    ``"*.png"``, for earlier runs without a manifest). Files of the user that
    neither names are never listed.
    """
    folder = Path(folder)
    names: set[str] = set()
    summary = folder / "summary.json"
    try:
        data = json.loads(summary.read_text(encoding="utf-8")) if summary.is_file() else {}
    except (OSError, ValueError):
        data = {}
    listed = data.get(MANIFEST, data.get("files")) if isinstance(data, dict) else None
    if isinstance(listed, list):
        names.update(n for n in listed if isinstance(n, str) and "/" not in n and n != "..")
    for pattern in patterns:
        names.update(p.name for p in folder.glob(pattern) if p.is_file())
    return sorted(n for n in names if (folder / n).is_file())


def remove_stale(
    folder: str | os.PathLike[str], earlier: Iterable[str], written: Iterable[str]
) -> list[str]:
    """Remove the files of ``earlier`` that are not in ``written``; returns their names.

    Called after a command has written its results under --force, so that the
    folder holds exactly one run's files (a stale ``animation.gif`` of an
    earlier run would otherwise sit beside the new results).
    """
    folder = Path(folder)
    keep = set(written)
    removed = []
    for name in earlier:
        if name not in keep and (folder / name).is_file():
            try:
                (folder / name).unlink()
            except OSError as exc:
                raise output_error(exc, folder, f"remove {name} of the earlier run from") from exc
            removed.append(name)
    return removed


class KeptFolder:
    """Work kept for ``--resume`` under ``DIR/<kind>/<fingerprint>/`` beside a
    ``manifest.json`` of the work's identity, so that another work's files are never
    taken: a study's chunks (:class:`formationlab.io.trials.ChunkFolder`), an equilibria
    search's settled starts (:class:`formationlab.io.equilibria.SettledFolder`)."""

    def __init__(self, out: str | os.PathLike[str], kind: str, identity: dict[str, Any],
                 fingerprint: str) -> None:  # fmt: skip
        self.root = Path(out) / kind
        self.identity = identity
        self.folder = self.root / fingerprint

    def start(self) -> None:
        """Create the folder and write the manifest (a fresh run)."""
        atomic_write_json(self.folder / "manifest.json", self.identity)
