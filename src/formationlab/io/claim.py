"""One writer per output folder: a command claims the folder it writes before it writes.

A claim is the lock file :data:`LOCK_NAME` in the folder, locked with ``fcntl.flock``
(exclusive, not waiting) for as long as the command runs, and holding who claimed it
(process id, host, start time, command line) so that a second command refused the folder
can name the first. The kernel releases the lock when its process ends, however it ends:
a lock file whose lock is free was left by a process that was killed (SIGKILL, a crash),
and is taken over with a warning. The claim ends with :func:`release_claims` (the command
line calls it when a command ends; also at exit), which removes the lock file.

A claim made again by the same process is the same claim (``run --animate`` animates the
folder it claimed). On a system without ``fcntl`` (Windows) the lock file is created with
``O_CREAT | O_EXCL`` and a file left behind by a process that no longer runs (on this host)
is taken over.
"""

from __future__ import annotations

import atexit
import json
import os
import socket
import sys
import time
import warnings
from pathlib import Path
from typing import Any

from ..errors import FolderBusyError, FormationlabWarning

try:
    import fcntl
except ImportError:  # pragma: no cover  (Windows: the O_EXCL lock file alone)
    fcntl = None  # type: ignore[assignment]

__all__ = ["LOCK_NAME", "claim_folder", "release_claim", "release_claims"]

#: the lock file of a claimed folder (hidden; removed when the command ends)
LOCK_NAME = ".formationlab.lock"


#: this process's claims: the folder (resolved) -> the open, locked lock file's descriptor
_claims: dict[Path, int] = {}


def claim_folder(folder: str | os.PathLike[str]) -> Path:
    """Claim ``folder`` (which must exist) for this process's writing; returns its path.

    Raises
    ------
    FolderBusyError
        When another process that runs holds the claim (named by its process id, host,
        start time and command).
    OSError
        When the lock file cannot be written (permission, a full disk, ...).
    """
    folder = Path(folder)
    key = folder.resolve()
    if key in _claims:
        return folder
    lock = folder / LOCK_NAME
    fd = None
    while fd is None:  # until the lock file at the path is the one this process locked
        fd = _open_lock(lock)
    previous = _read(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(_holder()) + "\n").encode("utf-8"), 0)
    except OSError:
        _close(fd, lock)
        raise
    _claims[key] = fd
    if previous:
        warnings.warn(
            f"{folder} was claimed by {_describe(previous)}, which no longer runs (it was "
            "killed while writing); taking the folder over",
            FormationlabWarning,
            stacklevel=2,
        )
    return folder


def _open_lock(lock: Path) -> int | None:
    """The lock file opened and locked by this process (None: removed meanwhile, retry)."""
    if fcntl is None:  # pragma: no cover
        return _open_exclusive(lock)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _read(fd)
        os.close(fd)
        raise _busy(lock.parent, holder) from None
    except BaseException:
        os.close(fd)
        raise
    try:  # locked: still the file at the path? (its holder may have removed it)
        same = os.stat(lock).st_ino == os.fstat(fd).st_ino
    except FileNotFoundError:
        same = False
    if not same:
        os.close(fd)
        return None
    return fd


def _open_exclusive(lock: Path) -> int | None:  # pragma: no cover  (Windows)
    try:
        return os.open(lock, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        pass
    try:
        holder = json.loads(lock.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        holder = {}
    if holder.get("host") == socket.gethostname() and not _runs(int(holder.get("pid", -1))):
        lock.unlink(missing_ok=True)  # left by a process that no longer runs
        return None
    raise _busy(lock.parent, holder)


def _runs(pid: int) -> bool:  # pragma: no cover  (Windows)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, ValueError):
        return pid > 0
    return True


def _holder() -> dict[str, Any]:
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": " ".join(["formationlab", *sys.argv[1:]])[:300],
    }


def _read(fd: int) -> dict[str, Any]:
    try:
        data = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _describe(holder: dict[str, Any]) -> str:
    """``process 1234 on host (since 2026-...: formationlab run ...)``."""
    if not holder:
        return "another process"
    who = f"process {holder.get('pid', '?')} on {holder.get('host', '?')}"
    since = f"since {holder['started']}" if "started" in holder else ""
    what = f"`{holder['command']}`" if "command" in holder else ""
    extra = ": ".join(s for s in (since, what) if s)
    return who + (f" ({extra})" if extra else "")


def _busy(folder: Path, holder: dict[str, Any]) -> FolderBusyError:
    return FolderBusyError(
        f"{folder} is being written by {_describe(holder)}; wait for it to end, or choose "
        "another --out"
    )


def _close(fd: int, lock: Path) -> None:
    try:
        lock.unlink(missing_ok=True)  # while locked: nobody else holds this file
    finally:
        os.close(fd)


def release_claim(folder: str | os.PathLike[str]) -> None:
    """End this process's claim of ``folder`` (if it has one): remove its lock file."""
    key = Path(folder).resolve()
    fd = _claims.pop(key, None)
    if fd is not None:
        _close(fd, key / LOCK_NAME)


def release_claims() -> None:
    """End this process's claims: remove their lock files and unlock them."""
    while _claims:
        release_claim(next(iter(_claims)))


atexit.register(release_claims)
