"""The per-edge table of a run with many edges: ``distance_errors.parquet``.

A run's ``summary.json`` lists the final distance error of every edge by label
(``"1-2": -0.003``) up to :data:`formationlab.simulation.run.LIST_LIMIT` edges. A larger
formation (a 1,000-robot lattice has 2,883 edges) keeps the statistics there
(``distance_error_stats``) and writes every edge to this table instead, one row per
edge in the order of the formation's edges:

==================  =======  ==================================================
column              type     meaning
==================  =======  ==================================================
``edge``            string   label ``"i-j"`` (1-based robots)
``i``, ``j``        int64    the edge's robots, 1-based, ``i < j``
``desired_distance`` float64 ``d_ij``
``distance``        float64  ``r_ij`` at the end of the run (at the law's points)
``distance_error``  float64  ``r_ij - d_ij``
==================  =======  ==================================================

Read it with ``pandas.read_parquet`` or :func:`read_edge_table`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from .files import atomic_path

__all__ = ["EDGE_TABLE", "read_edge_table", "write_edge_table"]

#: file name of the per-edge table in a run's folder
EDGE_TABLE = "distance_errors.parquet"


def write_edge_table(columns: dict[str, NDArray[Any]], target: str | os.PathLike[str]) -> Path:
    """Write the columns of :meth:`SimulationResult.edge_table` to parquet atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({name: np.asarray(col) for name, col in columns.items()})
    with atomic_path(target) as tmp:
        pq.write_table(table, tmp, compression="zstd")
    return Path(target)


def read_edge_table(path: str | os.PathLike[str]) -> dict[str, NDArray[Any]]:
    """The columns of a table written by :func:`write_edge_table`, as numpy arrays.

    Raises
    ------
    ParameterError
        The file is not a parquet table (damaged, truncated, another kind of file).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise
    except (OSError, pa.ArrowException) as exc:
        reason = getattr(exc, "strerror", None) or str(exc).split("\n")[0]
        raise ParameterError(f"cannot read {path} as an edge table (parquet): {reason}") from None
    return {name: table.column(name).to_numpy() for name in table.column_names}
