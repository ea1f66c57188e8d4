"""Timing summaries of LIGGGHTS 3.8.0 logs: loop time, its breakdown, memory estimate, list builds.

After each ``run`` LIGGGHTS 3.8.0 prints (``Finish::end``, as in LAMMPS of 2013)::

    Loop time of 0.00389683 on 1 procs for 200 steps with 110 atoms, finish time ...

    Pair  time (%) = 0.00329059 (84.4429)
    Neigh time (%) = 0.000111637 (2.86482)
    Comm  time (%) = 9.7005e-05 (2.48933)
    Outpt time (%) = 3.2807e-05 (0.84189)
    Other time (%) = 0.000364785 (9.36108)
    ...
    Neighbor list builds = 12
    Dangerous builds = 0

and before the thermo table ``Memory usage per processor = 7.5833 Mbytes``. The loop time is
the wall time of the time-step loop on process 0 after a barrier: the run's set-up (reading
nothing, but the first neighbour build, ghost exchange and force evaluation) is not in it.
The breakdown is process 0's (the ``Pair`` etc. of the other ranks are not printed), in
seconds and percent of the loop; ``Other`` is the remainder, which holds the integrator and
the fixes (there is no ``Modify`` line in this version). ``Memory usage`` is LIGGGHTS' own
estimate of its per-atom and neighbour arrays on one process, not the resident set size.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from gransim.errors import ResultFileError

_LOOP = re.compile(r"^Loop time of (\S+) on (\d+) procs? for (\d+) steps with (\d+) atoms")
_PART = re.compile(r"^(\w+)\s+time \(%\) = (\S+) \((\S+)\)\s*$")
_MEM = re.compile(r"^Memory usage per processor = (\S+) Mbytes")
_BUILDS = re.compile(r"^Neighbor list builds = (\d+)")
_DANGER = re.compile(r"^Dangerous builds = (\d+)")
_SETUP = re.compile(r"^Setting up run")


@dataclass(frozen=True)
class LoopTiming:
    """Timing summary of one ``run`` command.

    Attributes
    ----------
    loop_s : wall time of the step loop (s), process 0.
    procs : MPI processes.
    steps : steps of the run.
    atoms : atoms at the end of the run.
    breakdown : {name: (seconds, percent of loop_s)} in log order (``Pair``, ``Neigh``,
        ``Comm``, ``Outpt``, ``Other``), process 0; empty when not printed.
    memory_mb : ``Memory usage per processor`` (Mbytes, LIGGGHTS' estimate) or None.
    neighbour_builds, dangerous_builds : counts printed after the run, or None.
    """

    loop_s: float
    procs: int
    steps: int
    atoms: int
    breakdown: dict
    memory_mb: float | None
    neighbour_builds: int | None
    dangerous_builds: int | None

    @property
    def particle_steps_per_s(self) -> float:
        """atoms * steps / loop_s (the throughput of the run)."""
        return self.atoms * self.steps / self.loop_s

    def fraction(self, name: str) -> float:
        """Share of the loop spent in ``name`` (``Pair``...), from the printed seconds."""
        return self.breakdown[name][0] / self.loop_s


def _float(text: str, what: str, lineno: int) -> float:
    try:
        return float(text)
    except ValueError:
        raise ResultFileError(f"line {lineno}: {what} {text!r} is not a number") from None


def parse_loop_timings(source) -> tuple:
    """Timing summaries of the complete runs of a LIGGGHTS log (path or text), in order.

    A run that stopped before its ``Loop time of`` line gives no entry. Raises
    :class:`~gransim.errors.ResultFileError` when a number in these lines does not parse.
    """
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and Path(source).exists()):
        try:
            text = Path(source).read_text(errors="replace")
        except OSError as exc:
            raise ResultFileError(f"{source}: cannot read log ({exc})") from None
    else:
        text = str(source)
    out = []
    mem = None
    cur = None  # fields of the run whose Loop line was seen, until the next set-up

    def close():
        if cur is not None:
            out.append(LoopTiming(**cur))

    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if _SETUP.match(s):
            close()
            cur, mem = None, None
            continue
        m = _MEM.match(s)
        if m:
            mem = _float(m.group(1), "memory usage", n)
            continue
        m = _LOOP.match(s)
        if m:
            close()
            cur = {
                "loop_s": _float(m.group(1), "loop time", n),
                "procs": int(m.group(2)),
                "steps": int(m.group(3)),
                "atoms": int(m.group(4)),
                "breakdown": {},
                "memory_mb": mem,
                "neighbour_builds": None,
                "dangerous_builds": None,
            }
            continue
        if cur is None:
            continue
        m = _PART.match(s)
        if m:
            cur["breakdown"][m.group(1)] = (_float(m.group(2), "time", n), _float(m.group(3), "percent", n))
            continue
        m = _BUILDS.match(s)
        if m:
            cur["neighbour_builds"] = int(m.group(1))
            continue
        m = _DANGER.match(s)
        if m:
            cur["dangerous_builds"] = int(m.group(1))
    close()
    return tuple(out)


__all__ = ["LoopTiming", "parse_loop_timings"]
