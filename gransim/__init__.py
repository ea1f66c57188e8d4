"""gransim: micromechanics of 2D granular materials.

Layers (imports flow one way): geometry -> contacts -> generation | rve | dem | voidcell -> fem;
io and cli sit on top. The packages built on gransim, ``reference_runs`` (LIGGGHTS and LAMMPS
decks, runner, parsers) and above it ``validation``, import gransim, never the reverse; their
``gransim`` sub-commands (``reference``, ``replay``, ``validate``) are plug-ins of the entry-point
group ``gransim.commands`` that :mod:`gransim.cli` discovers. tests/test_boundaries.py checks
the direction of every import.
"""

__version__ = "0.1.0"

from .errors import GransimError, InputError  # noqa: E402
from .geometry import Packing  # noqa: E402

__all__ = ["GransimError", "InputError", "Packing", "__version__"]
