"""Reading and writing files. Only this package and the command line touch files."""

from .figures import save_figure
from .files import (
    atomic_path,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    prepare_output_dir,
)
from .mcap import write_mcap

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "prepare_output_dir",
    "save_figure",
    "write_mcap",
]
