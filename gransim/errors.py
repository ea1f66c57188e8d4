"""Exception types of gransim. All derive from :class:`GransimError` so the CLI can
print them as one-line messages."""


class GransimError(Exception):
    """Base class of every error gransim raises on purpose."""


class InputError(GransimError, ValueError):
    """An input has the wrong shape, dtype or value. The message names which."""


class ResultFileError(GransimError, OSError):
    """A results file is unreadable, foreign (not written by gransim) or of another schema."""


class ConvergenceError(GransimError, RuntimeError):
    """An iterative procedure (packing, Newton, servo) did not reach its target."""


class SimulationError(GransimError, RuntimeError):
    """A simulation became invalid (NaN, lost particle, unstable time step)."""
