"""Reading and writing files. Only this package and the command line touch files."""

from .figures import FIGURE_FORMATS, figure_formats, save_figure, save_figures
from .files import (
    atomic_path,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    prepare_output_dir,
)
from .mcap import write_mcap

__all__ = [
    "FIGURE_FORMATS",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "figure_formats",
    "prepare_output_dir",
    "save_figure",
    "save_figures",
    "write_mcap",
]
