"""Peak memory of benchmark jobs, each run in a child process (Linux).

The reading is ``VmHWM`` of ``/proc/<pid>/status``: the peak resident set of the process's address
space, which starts afresh at ``exec``. (``ru_maxrss`` from ``wait4``/``getrusage`` would not do:
the kernel carries the pre-``exec`` high-water mark over, so a child forked from a benchmark process
holding 300 MB reports at least 300 MB; only a small launcher such as ``/usr/bin/time`` avoids it.)

* :func:`own_peak_kib` is the process's own ``VmHWM``: a child that runs one engine in-process
  (threads included) reports it at its end. Exact.
* :class:`PeakSampler` polls the ``VmHWM`` of every descendant of a process (e.g. ``mpirun`` and
  its ranks, or the one serial ``liggghts`` process), ``interval`` seconds apart, keeping each
  process's last reading. Per process it is a lower bound, short by any growth within the last
  interval before the process exits (LIGGGHTS' arrays only grow, so a process is at its peak near
  its end); summed over MPI ranks it is their total peak.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class ChildRun:
    """Outcome of :func:`run_child`: exit code (negative: killed by that signal), output, wall
    time (s)."""

    returncode: int
    stdout: str
    stderr: str
    wall_s: float


def run_child(argv, env=None, cwd=None, timeout: float | None = None) -> ChildRun:
    """Run ``argv`` in a new session and return its :class:`ChildRun`.

    On timeout the child's process group is killed and ``returncode`` is negative (the signal).
    """
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            argv, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=env, cwd=cwd, start_new_session=True
        )
        timer = None
        if timeout is not None:

            def _kill():
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass

            timer = threading.Timer(timeout, _kill)
            timer.start()
        try:
            proc.wait()
        finally:
            if timer is not None:
                timer.cancel()
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        return ChildRun(proc.returncode, out.read().decode(errors="replace"), err.read().decode(errors="replace"), wall)


def own_peak_kib() -> int:
    """``VmHWM`` of this process (KiB): its peak resident set since ``exec``."""
    kib = vm_hwm_kib(os.getpid())
    if kib is None:
        raise OSError("no VmHWM in /proc/self/status (not Linux?)")
    return kib


def vm_hwm_kib(pid: int) -> int | None:
    """``VmHWM`` (peak resident set, KiB) of a live process, or None (gone, or a kernel thread)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return None


def descendants(root: int) -> dict:
    """{pid: command name} of the live descendants of ``root`` (from ``/proc/*/stat``)."""
    parent, name = {}, {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
        except OSError:
            continue
        close = stat.rindex(")")
        parent[int(d)] = int(stat[close + 2 :].split()[1])
        name[int(d)] = stat[stat.index("(") + 1 : close]
    out, todo = {}, [root]
    kids = {}
    for pid, pp in parent.items():
        kids.setdefault(pp, []).append(pid)
    while todo:
        for k in kids.get(todo.pop(), ()):
            out[k] = name[k]
            todo.append(k)
    return out


class PeakSampler(threading.Thread):
    """Poll the ``VmHWM`` of the descendants of ``root`` (default: this process) whose command name is
    in ``names`` (None: all) until :meth:`stop`; ``peaks`` is {pid: (name, KiB)} (last reading)."""

    def __init__(self, root: int | None = None, names=None, interval: float = 0.1):
        super().__init__(daemon=True)
        self.root = os.getpid() if root is None else int(root)
        self.names = None if names is None else set(names)
        self.interval = float(interval)
        self.peaks: dict = {}
        self._known: dict = {}
        self._tick = -1
        self._halt = threading.Event()

    def run(self):
        while True:
            self.sample()
            if self._halt.wait(self.interval):
                break

    def sample(self) -> None:
        """One reading of every matching descendant. The process tree is rescanned (all of /proc)
        at every sample for the first 2 s and while none matches, then once a second, so that
        polling costs little CPU next to the job measured."""
        self._tick += 1
        per_s = max(1, round(1.0 / self.interval))
        if not self._known or self._tick < 2 * per_s or self._tick % per_s == 0:
            self._known = {
                pid: nm for pid, nm in descendants(self.root).items() if self.names is None or nm in self.names
            }
        for pid, nm in list(self._known.items()):
            kib = vm_hwm_kib(pid)
            if kib is None:
                del self._known[pid]  # exited: keep its last reading
            else:
                self.peaks[pid] = (nm, max(kib, self.peaks.get(pid, (nm, 0))[1]))

    def stop(self) -> dict:
        """Stop polling; returns ``peaks``."""
        self._halt.set()
        self.join()
        return self.peaks

    @property
    def total_kib(self) -> int:
        return sum(k for _, k in self.peaks.values())


__all__ = ["ChildRun", "PeakSampler", "descendants", "own_peak_kib", "run_child", "vm_hwm_kib"]
