"""gransim: micromechanics of 2D granular materials.

Layers (imports flow one way): geometry -> contacts -> generation | rve | dem | voidcell -> fem;
io and cli sit on top. The packages built on gransim, ``reference_runs`` (LIGGGHTS and LAMMPS
decks, runner, parsers) and above it ``validation``, import gransim, never the reverse; their
``gransim`` sub-commands (``reference``, ``replay``, ``validate``) are plug-ins of the entry-point
group ``gransim.commands`` that :mod:`gransim.cli` discovers. tests/test_boundaries.py checks
the direction of every import.
"""

__version__ = "0.1.0"

import os as _os
import sys as _sys


def _numba_cache_dir(prefix: str, base_prefix: str, environ) -> str:
    """Where numba's disk cache goes when ``NUMBA_CACHE_DIR`` is unset (gransim._numba docstring).

    Inside a virtual environment (``prefix != base_prefix``) whose prefix is writable:
    ``<prefix>/numba-cache`` (for the checkout's ``.venv`` that is ``.venv/numba-cache``, what
    ``make`` exports). Otherwise the user's cache directory: ``$XDG_CACHE_HOME/gransim/numba``,
    default ``~/.cache/gransim/numba``.
    """
    if prefix != base_prefix and _os.access(prefix, _os.W_OK):
        return _os.path.join(prefix, "numba-cache")
    root = environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    return _os.path.join(root, "gransim", "numba")


def _default_numba_cache() -> None:
    """Give every process that imports gransim the same numba cache (see gransim._numba)."""
    if "NUMBA_CACHE_DIR" in _os.environ:  # the user's (or make's) choice, even an empty one
        return
    path = _numba_cache_dir(_sys.prefix, _sys.base_prefix, _os.environ)
    _os.environ["NUMBA_CACHE_DIR"] = path  # read by numba at import; inherited by child processes
    numba = _sys.modules.get("numba")
    if numba is not None:  # imported before gransim: numba has read its environment already
        numba.config.CACHE_DIR = path
        try:  # keep numba's next reload_config() from seeing a changed environment and resetting
            numba.config._env_reloader.old_environ["NUMBA_CACHE_DIR"] = path  # config attributes
        except AttributeError:  # pragma: no cover - a numba without the private reloader
            pass


_default_numba_cache()

from .errors import GransimError, InputError  # noqa: E402 (after the cache directory is set)


def __getattr__(name: str):
    """``gransim.Packing`` on first use: importing it imports numpy (0.1-0.4 s here), which
    ``gransim --help`` and the commands' argument checks do not need (PEP 562)."""
    if name == "Packing":
        from .geometry import Packing  # noqa: PLC0415 - start-up: numpy, see the docstring

        globals()["Packing"] = Packing
        return Packing
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["GransimError", "InputError", "Packing", "__version__"]
