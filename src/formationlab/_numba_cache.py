"""Numba's on-disk cache kept consistent with the package's source.

numba caches each compiled function beside the file that defines it and checks only that
file for changes: a cached caller keeps the old code of a callee defined in another module
(the engine's loop of ``engine/loop.py`` over ``engine/lists.py``, or over
``models/trig.py``) after an edit or an upgrade that changed only the callee,
and would give silently wrong results.

:func:`check` runs when this module is imported, before any other of the package's: it
hashes every module of the package that uses numba and compares the digest with the one stored
in each cache folder numba may use for those modules (``__pycache__`` beside them,
``NUMBA_CACHE_DIR``, the user-wide cache). Where the digest differs, the package's cached
kernels in that folder are removed, so numba compiles them afresh, and the new digest is
stored. Folders that cannot be written are left alone, and any failure here leaves numba's
own behaviour unchanged.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path

#: name of the file that holds the digest in a cache folder
STAMP = "formationlab-numba-sources.sha256"


def kernel_modules(root: Path) -> list[Path]:
    """The package's modules that use numba, sorted."""
    return sorted(p for p in root.rglob("*.py") if b"numba" in p.read_bytes())


def digest(files: list[Path], root: Path) -> str:
    """SHA-256 over the relative names and contents of ``files``."""
    h = hashlib.sha256()
    for p in files:
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def cache_folders(package_dir: Path) -> list[tuple[Path, bool]]:
    """Folders where numba may cache the kernels of the modules in ``package_dir``, each with
    whether to create it when missing: the in-tree ``__pycache__`` and the sub-folder numba
    derives from the folder's path under ``NUMBA_CACHE_DIR`` (created, so that the stamp
    is there before numba's first kernel), and under the user-wide cache (numba's choice when
    the package's folder cannot be written; left alone until numba makes it)."""
    folders = [(package_dir / "__pycache__", True)]
    try:
        from numba.core.caching import _CacheLocator
        from numba.misc.appdirs import AppDirs

        sub = _CacheLocator.get_suitable_cache_subpath(str(package_dir / "x.py"))
        user_wide = AppDirs(appname="numba", appauthor=False).user_cache_dir
        if os.environ.get("NUMBA_CACHE_DIR"):
            folders.append((Path(os.environ["NUMBA_CACHE_DIR"]) / sub, True))
        folders.append((Path(user_wide) / sub, False))
    except Exception:  # numba's internals moved: the in-tree folder only
        pass
    return folders


def purge(folder: Path, stems: set[str], new: str) -> bool:
    """Remove the cached kernels of modules ``stems`` from ``folder`` unless its stamp says
    ``new`` (kernels without a stamp are of unknown sources: removed too); store ``new``.
    False when the folder cannot be written."""
    stamp = folder / STAMP
    with contextlib.suppress(OSError):
        if stamp.read_text() == new:
            return True
    try:
        for f in folder.iterdir():
            if f.suffix in (".nbi", ".nbc") and f.name.split(".", 1)[0] in stems:
                with contextlib.suppress(FileNotFoundError):
                    f.unlink()
        tmp = folder / f"{STAMP}.{os.getpid()}"
        tmp.write_text(new)
        tmp.replace(stamp)
    except OSError:
        return False
    return True


def check(root: Path | None = None) -> None:
    """Remove cached kernels that were compiled from other sources than the package's now."""
    try:
        root = root or Path(__file__).parent
        files = kernel_modules(root)
        new = digest(files, root)
        by_dir: dict[Path, set[str]] = {}
        for p in files:
            by_dir.setdefault(p.parent, set()).add(p.stem)
        for package_dir, stems in by_dir.items():
            for folder, create in cache_folders(package_dir):
                if create and not folder.is_dir():
                    with contextlib.suppress(OSError):
                        folder.mkdir(parents=True, exist_ok=True)
                if folder.is_dir():
                    purge(folder, stems, new)
    except Exception:  # never stop the import: numba's own cache rules apply
        pass


check()
