"""Progress bars: tqdm on a terminal, quiet when stderr is not a TTY or when CI is set."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading


def progress(iterable=None, total=None, desc: str = "", **kw):
    """A tqdm progress bar on a terminal; silent when stderr is not a TTY or CI is set."""
    if "ipykernel" in sys.modules:  # a notebook: tqdm's widget bar
        from tqdm.auto import tqdm  # noqa: PLC0415 - start-up: tqdm.auto (~0.2 s)
    else:  # tqdm.auto also imports asyncio (for async iteration, unused here): ~0.03 s more
        from tqdm.std import tqdm  # noqa: PLC0415 - start-up: tqdm

    disable = (not sys.stderr.isatty()) or bool(os.environ.get("CI"))
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False, **kw)


# ----------------------------------------------------------------------------------- interrupts
# Python runs a signal handler between two bytecodes of the main thread, wherever it is: inside a
# weakref callback or a __del__ (h5py and numba objects have finalizers) the KeyboardInterrupt the
# default SIGINT handler raises is printed as "Exception ignored" and lost, and the run goes on to
# its end. So the long loops (a DEM run, a shear run, FIRE) run inside ``deferred_interrupts``:
# SIGINT and SIGTERM only record the signal there, and the loop calls ``check_interrupt`` between
# chunks of steps, at a point where an exception cannot be lost and the state is consistent.

#: signals that stop a run cleanly (the file is written as an incomplete, resumable run): Ctrl-C,
#: ``kill``/``timeout``, and the hang-up of the terminal or ssh session the command ran in (under
#: ``nohup`` SIGHUP is ignored and stays ignored)
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")

_INTERRUPT = {"pending": None, "depth": 0}
#: the command's results written complete so far (:func:`result_written`): an interrupt after them
#: says they are whole, so nobody redoes or distrusts a run that had ended
_WRITTEN: list[str] = []


class Interrupted(KeyboardInterrupt):
    """A run stopped by SIGINT (Ctrl-C), SIGTERM or SIGHUP. A :class:`KeyboardInterrupt`, so code
    that handles Ctrl-C handles it too; ``signum`` is the signal (the command line exits with
    128 + signum: 130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP); the message says what became of
    the output."""

    def __init__(self, signum: int, message: str = "", clean: bool = False):
        super().__init__(message)
        self.signum = int(signum)
        self.message = message
        #: raised by :func:`check_interrupt`, at a point the caller chose (not from the handler,
        #: at an arbitrary bytecode)
        self.clean = bool(clean)

    @property
    def signal_name(self) -> str:
        try:
            return signal.Signals(self.signum).name
        except ValueError:
            return f"signal {self.signum}"

    def __str__(self) -> str:
        return self.message or f"interrupted by {self.signal_name}"


def _on_signal(signum, frame):
    first = _INTERRUPT["pending"] is None
    if first:
        _INTERRUPT["pending"] = signum
    if _INTERRUPT["depth"] == 0 or not first:
        # outside a run loop (or a second signal: the user insists): stop at once; the signal stays
        # pending, so should this exception be lost in a finalizer the next check still stops
        raise Interrupted(signum)


def result_written(path) -> None:
    """Record that the command's result ``path`` is now written complete: should SIGINT or SIGTERM
    still stop the command (130 / 143), its message names ``path`` as complete."""
    _WRITTEN.append(str(path))


def written_results() -> tuple[str, ...]:
    """The results recorded by :func:`result_written` since the command started."""
    return tuple(_WRITTEN)


def pending_interrupt() -> int | None:
    """The signal received and not yet turned into :class:`Interrupted` (None: none)."""
    return _INTERRUPT["pending"]


def check_interrupt(message: str = "") -> None:
    """Raise :class:`Interrupted` (with ``message``) if SIGINT or SIGTERM arrived since the last
    check; the signal is then consumed. A no-op when none did (or when no handler is installed)."""
    signum = _INTERRUPT["pending"]
    if signum is not None:
        _INTERRUPT["pending"] = None
        raise Interrupted(signum, message, clean=True)


def _install():
    """Install :func:`_on_signal` for :data:`STOP_SIGNALS` (main thread only; a signal the
    process ignores stays ignored). Returns the previous handlers."""

    old = {}
    if threading.current_thread() is not threading.main_thread():
        return old
    for name in STOP_SIGNALS:
        s = getattr(signal, name)
        cur = signal.getsignal(s)
        if cur is signal.SIG_IGN or cur is None:
            continue
        old[s] = signal.signal(s, _on_signal)
    return old


def _restore(old: dict) -> None:
    for s, h in old.items():
        signal.signal(s, h)


@contextlib.contextmanager
def deferred_interrupts():
    """Within the block SIGINT and SIGTERM only record the signal; the loop calls
    :func:`check_interrupt` between chunks of work and stops cleanly there (a second signal
    stops at once). Off the main thread it only counts the nesting. The previous handlers are
    restored on exit; a signal still pending then stays pending for the caller's next check."""
    old = _install()
    _INTERRUPT["depth"] += 1
    try:
        yield
    finally:
        _INTERRUPT["depth"] -= 1
        _restore(old)


@contextlib.contextmanager
def stop_signals():
    """For a whole command: SIGINT and SIGTERM raise :class:`Interrupted` at once (outside the
    loops of :func:`deferred_interrupts`, which defer them), and a signal whose exception was lost
    (raised inside a finalizer, where Python ignores it) is raised when the block ends, so an
    interrupted command never reports success."""
    _INTERRUPT["pending"] = None
    _WRITTEN.clear()
    old = _install()
    try:
        yield
    except KeyboardInterrupt:
        _INTERRUPT["pending"] = None
        raise
    finally:
        _restore(old)
    check_interrupt()
