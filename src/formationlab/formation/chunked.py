"""Functions of saved states evaluated over a long time axis in slices of bounded memory.

After a run, the Lyapunov function, the switching functions and the distance
errors are evaluated at every saved state ``(T, n, k)``. Evaluated at once, their
temporaries grow with ``T`` times the formation's size (pairs, edges, restricted
triples): a 60-second run of ten robots needs half a gigabyte of scratch space
for ``V`` alone. :func:`over_time` evaluates such a function on consecutive
slices of the leading axis, each small enough that its temporaries stay within a
budget, and stacks the results. The budget grows with what is saved
(:func:`slice_budget`: :data:`SCALE` times the states' bytes, at least :data:`FLOOR`,
at most :data:`BUDGET`), so that memory is what is saved plus at most a few times it
(or a few megabytes), for a run of few states as for one of many.

The functions evaluated this way compute each state on its own (no sum or
choice across states), so a slice gives the rows the whole would: bit for bit
where the arithmetic does not depend on the states around it, and to rounding
where a slice's candidate pairs (``neighbours.close_pairs`` over the states of
the slice, beyond ``DENSE_LIMIT`` robots) differ from the whole run's (the
extra pairs contribute exact zeros).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .spec import DENSE_LIMIT, Formation

__all__ = ["BUDGET", "FLOOR", "SCALE", "over_time", "row_bytes", "slice_budget", "time_slices"]

#: most bytes of temporaries one slice may allocate (the estimate of :func:`row_bytes` per
#: state)
BUDGET = 128 * 2**20

#: a slice's temporaries may take this many times the bytes of the states they are read
#: from (the saved trajectory) ...
SCALE = 4

#: ... and at least this many bytes (a slice holds at least one state all the same)
FLOOR = 2**20

#: scratch float64 numbers of the post-processing per listed item (edge, triple, pair) and
#: state (tracemalloc: 17 MB per state for V of the 100,000-robot lattice, estimated 25 MB;
#: 0.26 MB for the angle-restricted 200-robot lattice, estimated 0.31 MB)
_COPIES = 4


def row_bytes(formation: Formation, k: int = 2) -> int:
    """Estimated scratch bytes per state of the post-processing functions of ``formation``.

    Proportional to what one state's evaluation lists: the state (``n k``), the edges,
    the restricted triples and their surfaces, and the pairs Khatib's repulsion reaches
    (every pair up to ``DENSE_LIMIT`` robots, about ``3 n`` close pairs beyond).
    """
    n = formation.n
    pairs = n * (n - 1) // 2 if n <= DENSE_LIMIT else 3 * n
    items = n * k + len(formation.edges) + 4 * len(formation.restricted_halves) + pairs
    return 8 * _COPIES * items


def slice_budget(x: NDArray[Any]) -> float:
    """Bytes of temporaries a slice of the states ``x`` may allocate: :data:`SCALE` times
    ``x``'s own bytes, at least :data:`FLOOR`, at most :data:`BUDGET`."""
    return float(min(BUDGET, max(FLOOR, SCALE * x.nbytes)))


def time_slices(rows: int, per_row: float, budget: float | None = None) -> Iterator[slice]:
    """Consecutive slices of ``range(rows)`` of at most ``budget / per_row`` rows (at least 1);
    ``budget`` defaults to :data:`BUDGET`."""
    budget = BUDGET if budget is None else budget
    step = max(1, int(budget // max(per_row, 1.0)))
    for a in range(0, rows, step):
        yield slice(a, min(rows, a + step))


def over_time(
    fn: Callable[[NDArray[np.float64]], NDArray[Any]],
    x: NDArray[np.float64],
    per_row: float,
    budget: float | None = None,
) -> NDArray[Any]:
    """``fn(x)`` for states ``x`` ``(T, ...)``, evaluated slice by slice along ``T``.

    ``fn`` maps states ``(t, ...)`` to values ``(t, ...)`` row by row; ``per_row`` is its
    scratch memory per state (:func:`row_bytes`); ``budget`` that of a slice, by default
    :func:`slice_budget` of ``x``. An input without a time axis, or one whose rows fit
    the budget, is passed to ``fn`` whole.
    """
    x = np.asarray(x)
    budget = slice_budget(x) if budget is None else budget
    if x.ndim < 3 or x.shape[0] * per_row <= budget:
        return fn(x)
    parts = [fn(x[s]) for s in time_slices(x.shape[0], per_row, budget)]
    return np.concatenate(parts, axis=0)
