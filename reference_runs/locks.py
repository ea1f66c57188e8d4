"""Directory locks: one writer at a time for a reference job directory (LIGGGHTS, LAMMPS or YADE) or a
results directory.

:class:`DirectoryLock` takes ``fcntl.flock`` on ``<dir>/.lock`` (created if missing). ``flock``
locks belong to the open file, so the kernel releases them when the holder exits or is killed:
a lock never outlives its process and needs no stale-lock cleaning. The holder writes its pid,
host and start time into the lock file so that a waiting or refused process can name it.

Usage::

    from reference_runs.locks import DirectoryLock

    with DirectoryLock("results"):                     # fail fast: DirectoryBusyError if held
        ...
    with DirectoryLock(job_dir, fail_fast=False, timeout=600, clean_tmp=True):
        ...                                            # waits (printing one line) up to 600 s

Locks are advisory: only code that takes them is kept out. They work between processes and
between threads of one process (each :class:`DirectoryLock` opens the file anew). On file
systems without ``flock`` (some network mounts) the lock degrades to a no-op with no error.
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import os
import socket
import sys
import time
from pathlib import Path

from .errors import DirectoryBusyError

LOCK_NAME = ".lock"
#: seconds between attempts while waiting for a lock
POLL_S = 0.1


def _read_holder(path: Path) -> tuple[int | None, str]:
    """(pid, description) of the holder, from the lock file's text (pid host start)."""
    try:
        text = path.read_text().strip()
    except OSError:
        return None, "unknown holder"
    words = text.split()
    pid = int(words[0]) if words and words[0].isdigit() else None
    return pid, (f"pid {pid}" + (f" on {words[1]}" if len(words) > 1 else "")) if pid else "unknown holder"


def remove_stray_tmp(directory, recursive: bool = True) -> list:
    """Remove temporaries of :func:`gransim.io.atomic_path` left by a killed writer.

    They are named ``.<name>.<random><suffix>`` with a suffix ending in ``.tmp`` (``.tmp``,
    ``.json.tmp``, ``.h5.tmp``), next to their target, anywhere below ``directory`` (only in it
    when ``recursive`` is False). Call it only while holding the directory's lock (a live
    writer's temporary would be removed too). Returns the removed paths.
    """
    removed = []
    d = Path(directory)
    for p in d.rglob(".*.tmp") if recursive else d.glob(".*.tmp"):
        if p.is_file() and p.name.count(".") >= 3:
            try:
                p.unlink()
                removed.append(p)
            except OSError:
                pass
    return removed


class DirectoryLock:
    """An exclusive lock on a directory (``flock`` of ``<path>/.lock``), as a context manager.

    Parameters
    ----------
    path : the directory (created if missing).
    fail_fast : True: raise :class:`~reference_runs.errors.DirectoryBusyError` at once when
        another process holds the lock (message naming the directory and the holder's pid).
        False: wait for it, printing one line ``waiting for <what> (pid N) ...`` to ``echo``.
    timeout : seconds to wait when ``fail_fast`` is False (None: no limit); then
        ``DirectoryBusyError`` with ``timed_out=True``.
    what : how messages name the directory (default ``directory <path>``).
    clean_tmp : once the lock is taken, remove stray ``atomic_path`` temporaries below the
        directory (:func:`remove_stray_tmp`); ``removed`` lists them.
    echo : where the waiting line goes (default: print to stderr).
    """

    def __init__(
        self,
        path,
        fail_fast: bool = True,
        timeout: float | None = None,
        what: str | None = None,
        clean_tmp: bool = False,
        echo=None,
    ):
        self.path = Path(path)
        self.lock_path = self.path / LOCK_NAME
        self.fail_fast = bool(fail_fast)
        self.timeout = timeout
        self.what = what or f"directory {self.path}"
        self.clean_tmp = bool(clean_tmp)
        self.echo = echo or (lambda msg: print(msg, file=sys.stderr, flush=True))
        self.removed: list = []
        self.waited_s = 0.0
        self._fh = None

    @property
    def held(self) -> bool:
        return self._fh is not None

    def _try(self, fh) -> bool:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            return False
        except OSError:  # no flock on this file system: run unlocked
            return True

    def acquire(self) -> DirectoryLock:
        if self._fh is not None:
            raise RuntimeError(f"{self.what}: lock already held by this object")
        self.path.mkdir(parents=True, exist_ok=True)
        fh = open(self.lock_path, "a+")
        t0 = time.monotonic()
        announced = False
        try:
            while not self._try(fh):
                pid, who = _read_holder(self.lock_path)
                if self.fail_fast:
                    raise DirectoryBusyError(
                        f"{self.what} is in use by another gransim process ({who}; lock file "
                        f"{self.lock_path}); wait for it to finish or stop it, then retry",
                        path=self.path,
                        holder_pid=pid,
                    )
                waited = time.monotonic() - t0
                if self.timeout is not None and waited > self.timeout:
                    raise DirectoryBusyError(
                        f"gave up waiting for {self.what} after {waited:.0f} s: still held by {who} "
                        f"(lock file {self.lock_path})",
                        path=self.path,
                        holder_pid=pid,
                        timed_out=True,
                    )
                if not announced:
                    limit = "" if self.timeout is None else f", up to {self.timeout:g} s"
                    self.echo(f"waiting for {self.what} ({who}{limit})")
                    announced = True
                time.sleep(POLL_S)
        except BaseException:
            fh.close()
            raise
        self.waited_s = time.monotonic() - t0
        fh.seek(0)
        fh.truncate()
        stamp = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        fh.write(f"{os.getpid()} {socket.gethostname()} {stamp}\n")
        fh.flush()
        self._fh = fh
        if self.clean_tmp:
            self.removed = remove_stray_tmp(self.path)
        return self

    def release(self) -> None:
        fh, self._fh = self._fh, None
        if fh is None:
            return
        try:
            fh.seek(0)
            fh.truncate()
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        except OSError:
            pass
        finally:
            fh.close()

    def __enter__(self) -> DirectoryLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


__all__ = ["LOCK_NAME", "DirectoryBusyError", "DirectoryLock", "remove_stray_tmp"]
