"""What the machine can hold: memory available, and refusing work that will not fit.

A formation too large for memory is refused by an estimate before anything is allocated
(:func:`check_memory`), with the size, what is available and what to change, instead of
numpy's allocation error after minutes, or the system's out-of-memory killer.
"""

from __future__ import annotations

import os
from importlib.metadata import PackageNotFoundError, version

from .errors import FormationError

__all__ = ["SHARE", "available_memory", "check_memory", "package_version", "size"]


def package_version() -> str:
    """The installed package's version ("0.0.0" when run from a source tree)."""
    try:
        return version("formationlab")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0.0.0"


def available_memory() -> float | None:
    """Memory available to a new allocation, bytes; None if unknown.

    The machine's (Linux ``MemAvailable``), less when the process runs under a limit: the
    room left below its address-space limit (``ulimit -v``, ``RLIMIT_AS``) or its control
    group's ``memory.max`` (a container's limit), so that a run is refused by its estimate
    instead of failing to allocate.
    """
    found = [
        v for v in (_meminfo("MemAvailable:"), _address_room(), _cgroup_room()) if v is not None
    ]
    if not found:
        try:
            found.append(float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")))
        except (ValueError, OSError, AttributeError):
            return None
    return max(0.0, min(found))


def _meminfo(field: str, path: str = "/proc/meminfo") -> float | None:
    """A ``kB`` field of ``/proc/meminfo`` (or ``/proc/self/status``) in bytes, or None."""
    try:
        with open(path, encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _address_room() -> float | None:
    """Bytes left below the address-space limit (``RLIMIT_AS``), or None without one."""
    try:
        import resource  # (not on Windows)

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError):
        return None
    if limit == resource.RLIM_INFINITY:
        return None
    used = _meminfo("VmSize:", "/proc/self/status")
    return float(limit) - (used or 0.0)


def _cgroup_room() -> float | None:
    """Bytes left below the control group's ``memory.max`` (cgroup v2), or None."""
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as fh:
            limit = fh.read().strip()
        if limit == "max":
            return None
        with open("/sys/fs/cgroup/memory.current", encoding="ascii") as fh:
            return float(limit) - float(fh.read().strip())
    except (OSError, ValueError):
        return None


def size(n: float) -> str:
    """A number of bytes for a person: ``"91.9 MB"``, ``"32.9 GB"``."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 999.5 or unit == "TB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{n:.0f} B"
        n /= 1e3
    raise AssertionError("unreachable")


#: the share of the available memory that building a formation may take: a run needs at
#: least as much again (the law's lists, the states, the results)
SHARE = 0.5


def check_memory(need: float, what: str, *, key: str, fix: str) -> None:
    """Refuse ``what`` (a :class:`FormationError` with ``key``) when its estimated ``need``
    in bytes exceeds :data:`SHARE` of the memory available; ``fix`` says what to change."""
    free = available_memory()
    if free is not None and need > SHARE * free:
        raise FormationError(
            f"{what} needs about {size(need)} of memory to build, {size(free)} available "
            f"(at most half of it: a run needs as much again); {fix}",
            key=key,
        )
