"""The error of a failed LIGGGHTS reference job."""

from __future__ import annotations

from gransim.errors import GransimError


class ReferenceRunError(GransimError, RuntimeError):
    """A LIGGGHTS job failed: missing binary, ERROR/WARNING lines, lost atoms, non-zero exit,
    timeout or missing outputs.

    Attributes
    ----------
    job_dir : the job directory (or None when the job never started).
    log_lines : the relevant lines of ``log.lammps`` / stderr, as shown in the message.
    """

    def __init__(self, message: str, job_dir=None, log_lines=()):
        self.job_dir = job_dir
        self.log_lines = tuple(log_lines)
        text = message
        if self.log_lines:
            text += "\n  relevant log lines:\n" + "\n".join("    | " + ln for ln in self.log_lines)
        super().__init__(text)
