"""The errors of reference jobs (LIGGGHTS, LAMMPS or YADE): a failed or untrustworthy job, a busy directory."""

from __future__ import annotations

from gransim.errors import GransimError


class ReferenceRunError(GransimError, RuntimeError):
    """A LIGGGHTS job failed or its evidence is incomplete: missing binary, ERROR/WARNING lines,
    lost atoms, non-zero exit, timeout, missing or truncated outputs, or a stored job that no longer
    matches its manifest.

    Attributes
    ----------
    job_dir : the job directory (or None when the job never started).
    log_lines : the relevant lines of ``log.lammps`` / stderr, as shown in the message.
    timed_out : True when the job (or the wait for another writer of the job) hit its timeout.
    problems : the individual problems found (e.g. by :func:`reference_runs.runner.verify_job`).
    """

    def __init__(self, message: str, job_dir=None, log_lines=(), timed_out: bool = False, problems=()):
        self.job_dir = job_dir
        self.log_lines = tuple(log_lines)
        self.timed_out = bool(timed_out)
        self.problems = tuple(problems)
        text = message
        if self.log_lines:
            text += "\n  relevant log lines:\n" + "\n".join("    | " + ln for ln in self.log_lines)
        super().__init__(text)


class DirectoryBusyError(GransimError, RuntimeError):
    """Another process holds the lock of a directory (see :class:`reference_runs.locks.DirectoryLock`).

    Attributes
    ----------
    path : the locked directory.
    holder_pid : pid of the holder as it recorded itself in the lock file (None when unknown).
    timed_out : True when a blocking wait gave up after its timeout.
    """

    def __init__(self, message: str, path=None, holder_pid=None, timed_out: bool = False):
        self.path = path
        self.holder_pid = holder_pid
        self.timed_out = bool(timed_out)
        super().__init__(message)
