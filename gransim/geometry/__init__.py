"""Periodic cells and packings (the bottom layer: imports nothing else of gransim)."""

from .cell import cell_area, cell_heights, check_cell, minimum_image, to_cartesian, to_fractional, wrap
from .packing import Packing

__all__ = [
    "Packing",
    "cell_area",
    "cell_heights",
    "check_cell",
    "minimum_image",
    "to_cartesian",
    "to_fractional",
    "wrap",
]
