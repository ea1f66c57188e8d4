"""gransim: micromechanics of 2D granular materials.

Layers (imports flow one way): geometry -> contacts -> generation | rve | dem | voidcell -> fem;
io and cli sit on top. ``reference_runs`` and ``validation`` import gransim, never the reverse.
"""

__version__ = "0.1.0"

from .errors import GransimError, InputError  # noqa: E402
from .geometry import Packing  # noqa: E402

__all__ = ["GransimError", "InputError", "Packing", "__version__"]
