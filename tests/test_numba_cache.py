"""The guard of numba's cache (formationlab/_numba_cache.py): an edit of a callee in another
module must not leave a cached caller with the old code."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from formationlab._numba_cache import STAMP, check

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef g(x):\n    return x + {k}\n"
CALLER = textwrap.dedent(
    """\
    from numba import njit

    from .callee import g


    @njit(cache=True)
    def f(x):
        return g(x)
    """
)
RUN = "import sys; sys.path.insert(0, {root!r}); {guard}from pkg.caller import f; print(f(1))"


def _package(tmp_path: Path, k: int) -> Path:
    pkg = tmp_path / "pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(CALLEE.format(k=k))
    return pkg


def _call(tmp_path: Path, guarded: bool, cache_dir: Path | None = None) -> int:
    pkg = str(tmp_path / "pkg")
    check_it = (
        f"from formationlab._numba_cache import check; check(__import__('pathlib').Path({pkg!r})); "
    )
    guard = check_it if guarded else ""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", RUN.format(root=str(tmp_path), guard=guard)],
        capture_output=True, text=True, env=env, check=True,
    )  # fmt: skip
    return int(out.stdout.split()[-1])


def test_an_edited_callee_is_compiled_again(tmp_path: Path) -> None:
    _package(tmp_path, 1)
    assert _call(tmp_path, guarded=True) == 2  # compiled and cached
    assert list((tmp_path / "pkg" / "__pycache__").glob("caller.f-*.nbi"))
    _package(tmp_path, 2)  # only the callee changes
    assert _call(tmp_path, guarded=True) == 3  # the cached caller was dropped


def test_only_the_packages_kernels_are_removed_and_only_when_sources_change(
    tmp_path: Path,
) -> None:
    pkg = _package(tmp_path, 1)
    cache = pkg / "__pycache__"
    cache.mkdir()
    mine = [cache / "caller.f-7.py311.nbi", cache / "caller.f-7.py311.1.nbc"]
    others = [cache / "caller.cpython-311.pyc", cache / "elsewhere.h-3.py311.nbi"]
    for p in mine + others:
        p.write_bytes(b"x")
    check(pkg)
    assert not any(p.exists() for p in mine) and all(p.exists() for p in others)
    stamp = (cache / STAMP).read_text()
    for p in mine:  # compiled again from these sources: kept by the next check
        p.write_bytes(b"x")
    check(pkg)
    assert all(p.exists() for p in mine)
    (pkg / "__init__.py").write_text("# no kernel here: not part of the digest\n")
    check(pkg)
    assert all(p.exists() for p in mine) and (cache / STAMP).read_text() == stamp
    (pkg / "callee.py").write_text(CALLEE.format(k=5))
    check(pkg)
    assert not any(p.exists() for p in mine) and (cache / STAMP).read_text() != stamp


def test_a_cache_folder_of_ones_own_is_kept_from_one_process_to_the_next(tmp_path: Path) -> None:
    """NUMBA_CACHE_DIR empty at the first import: the stamp is written before numba's first
    kernel, so the next process loads the kernels instead of compiling them again."""
    _package(tmp_path, 1)
    cache = tmp_path / "numba-cache"
    assert _call(tmp_path, guarded=True, cache_dir=cache) == 2
    (index,) = cache.glob("*/caller.f-*.nbi")
    stamp = index.stat().st_mtime_ns
    assert _call(tmp_path, guarded=True, cache_dir=cache) == 2
    assert index.exists() and index.stat().st_mtime_ns == stamp  # loaded, not rebuilt
    _package(tmp_path, 2)
    assert _call(tmp_path, guarded=True, cache_dir=cache) == 3
