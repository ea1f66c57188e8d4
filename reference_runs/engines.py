"""The established DEM codes the reference jobs run on: LIGGGHTS and LAMMPS behind one interface.

An :class:`Engine` says how to find, identify and call one code: its binary (``liggghts``,
``lmp``), the deck file name of its jobs (``in.liggghts``, ``in.lammps``), its Debian package
(``liggghts``, ``lammps``), how to install it, the regular expression of its log banner and the
command line of a job. :func:`get_engine` looks one up by name (``liggghts``, ``lammps``).

Both codes write the same log format (LIGGGHTS is a fork of LAMMPS): a banner as the first line
(``LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled ...)``, ``LAMMPS (29 Sep 2021 - Update 2)``),
the echoed deck, one thermo table per ``run`` headed by ``Step ...`` and ended by ``Loop time of
...``, and ``ERROR``/``WARNING`` lines (LAMMPS appends the source location, ``(src/...cpp:431)``).
Both take ``-in DECK -log LOG -screen none -nocite``, command-line variables ``-var NAME VALUE``
(:func:`check_variables`) and run under ``mpirun -np N``.

YADE (``yade``, Debian package ``yade``; docs/yade.md) is an independent code driven by a Python
script, not a deck: :class:`YadeEngine` runs ``yade -n -x -j1 -L gransim_yade_quiet SCRIPT`` (one
process; the ``-L`` module, written into the job directory by :mod:`reference_runs.yade.job`, keeps
YADE from opening its TCP servers), takes its version from ``yade --version`` and the job's own
``Welcome to Yade ...`` line, and its jobs have their own output accounting
(:func:`reference_runs.yade.job.run_yade_job`, which :func:`reference_runs.runner.run_job` hands
them to).
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass

from gransim.errors import InputError
from gransim.io.provenance import binary_identity, binary_version, package_version, run_probe

from .errors import ReferenceRunError


def check_variables(variables, option: str = "variables") -> dict:
    """Command-line variables of a job, the codes' ``-var NAME VALUE``, as {NAME: VALUE}.

    Both codes define each ``-var NAME VALUE`` as an index-style variable before the deck's first
    line (LAMMPS src/input.cpp:107-110 at commit 256531a2, LIGGGHTS-PUBLIC 3.8.0 src/input.cpp:141-144:
    ``variable->set(argv[iarg+1], ...)``, which is ``Variable::set(NAME, "index", VALUE)``:
    LAMMPS src/variable.cpp:378-388 at commit b8208f58, LIGGGHTS src/variable.cpp:436-448), and
    a later ``variable NAME index ...`` line of the deck is then skipped (``if (find(arg[0]) >=
    0) return;``, LAMMPS src/variable.cpp:152-154, LIGGGHTS src/variable.cpp:187-189): the
    command-line value wins over the deck's default.

    Parameters
    ----------
    variables : None, a mapping {NAME: VALUE} or an iterable of (NAME, VALUE) pairs. A NAME is
        letters, digits and underscores (the codes' rule for variable names); a VALUE is one
        word (text, or an int or float written with ``str``), as ``-var`` reads one argument per
        value.
    option : how the caller's input is named in the messages (``--var`` for the command line).

    Returns
    -------
    dict {NAME: VALUE} (text), in the order given; ``{}`` for None.

    Raises
    ------
    InputError naming the variable: a bad name (``variables NAME: expected letters, digits and
    underscores, got 'k-n'``), a name given twice (``variables kn: given twice``), a value that is
    not one word.
    """
    if variables is None:
        return {}
    pairs = variables.items() if isinstance(variables, Mapping) else variables
    out: dict = {}
    for pair in pairs:
        try:
            name, value = pair
        except (TypeError, ValueError):
            raise InputError(f"{option}: expected (NAME, VALUE) pairs, got {pair!r}") from None
        if (
            not isinstance(name, str)
            or not name
            or not name.isascii()
            or not all(c.isalnum() or c == "_" for c in name)
        ):
            raise InputError(f"{option} NAME: expected letters, digits and underscores, got {name!r}")
        if name in out:
            raise InputError(f"{option} {name}: given twice")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = str(value)
        if not isinstance(value, str) or not value or any(c.isspace() for c in value):
            raise InputError(f"{option} {name} VALUE: expected one word, got {value!r}")
        out[name] = value
    return out


def variables_text(variables: dict) -> str:
    """``-var a 1 -var b x`` for {a: 1, b: x} (sorted by name), ``no -var`` for none: how a job's
    command-line variables are named in messages."""
    return " ".join(f"-var {k} {v}" for k, v in sorted(variables.items())) or "no -var"


@dataclass(frozen=True)
class Engine:
    """One DEM code.

    Attributes
    ----------
    name : ``liggghts`` or ``lammps`` (what ``run_job(..., engine=...)`` takes).
    label : the code's display name (``LIGGGHTS``, ``LAMMPS``).
    binary : executable name looked up on PATH (``liggghts``, ``lmp``).
    deck_name : deck file of a job directory (``in.liggghts``, ``in.lammps``).
    package : Debian package holding the binary (``liggghts``, ``lammps``).
    package_label : prefix of :meth:`package_version` (``LIGGGHTS-PUBLIC``, ``LAMMPS``).
    banner : regular expression of the first log line; group 1 is the version.
    version_prefix : prepended to group 1 to form the version (``""``, ``"LAMMPS "``).
    install_hint : how to install the binary (quoted by :meth:`find`).
    """

    name: str
    label: str
    binary: str
    deck_name: str
    package: str
    package_label: str
    banner: str
    version_prefix: str
    install_hint: str

    @property
    def banner_re(self) -> re.Pattern:
        return re.compile(self.banner)

    def which(self) -> str | None:
        """Absolute path of the binary on PATH, or None."""
        exe = shutil.which(self.binary)
        return os.path.abspath(exe) if exe else None

    def available(self) -> bool:
        """True when the binary is on PATH."""
        return self.which() is not None

    def find(self) -> str:
        """Absolute path of the binary; :class:`ReferenceRunError` with :attr:`install_hint`."""
        exe = self.which()
        if exe is None:
            raise ReferenceRunError(
                f"the `{self.binary}` binary ({self.label}) was not found on PATH; {self.install_hint}"
            )
        return exe

    def version(self, binary=None) -> str | None:
        """Version from the binary's own banner with its path (``LIGGGHTS-PUBLIC 3.8.0
        (/usr/bin/liggghts)``, ``LAMMPS 29 Sep 2021 - Update 2 (/usr/bin/lmp)``), None when absent.
        Cached per binary path, modification time and size."""
        return binary_version(binary, self.binary, self.banner, self.label, self.version_prefix)

    def package_version(self, binary=None) -> str | None:
        """Debian package version of the binary (``LAMMPS 20220106.git7586adbb6a+ds1-2+b2
        (Debian)``), or None when absent or not a file of :attr:`package`."""
        return package_version(binary, self.binary, self.package, self.package_label)

    def log_version(self, line: str) -> str | None:
        """The version in a log banner line, or None when ``line`` is not this code's banner."""
        m = self.banner_re.match(line.strip())
        return self.version_prefix + m.group(1).strip() if m else None

    def command(self, deck: str, log: str, np: int = 1, exe: str | None = None, variables=None) -> list:
        """Command line of a job: ``BINARY -in DECK -log LOG -screen none -nocite [-var NAME VALUE
        ...]``, under ``mpirun [--allow-run-as-root] -np N`` when ``np > 1``. ``variables``
        ({NAME: VALUE} or (NAME, VALUE) pairs, :func:`check_variables`) become one ``-var NAME
        VALUE`` each, in the order given: index-style variables defined before the deck's first
        line (see :func:`check_variables`)."""
        exe = exe or self.find()
        cmd = [exe, "-in", deck, "-log", log, "-screen", "none", "-nocite"]
        for name, value in check_variables(variables).items():
            cmd += ["-var", name, value]
        if int(np) > 1:
            mpirun = shutil.which("mpirun")
            if mpirun is None:
                raise ReferenceRunError("np > 1 needs `mpirun` on PATH (OpenMPI: `apt-get install openmpi-bin`)")
            extra = ["--allow-run-as-root"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []
            cmd = [mpirun, *extra, "-np", str(int(np)), *cmd]
        return cmd

    def env(self, np: int = 1) -> dict:
        """Environment of a job of ``np`` MPI processes: the caller's, with ``OMP_NUM_THREADS=1``
        unless set (LAMMPS otherwise prints a notice and the benchmark would measure threads it did
        not ask for) and, for a serial job (``np == 1``), :data:`SERIAL_MPI_ENV` where the caller
        has not set those variables."""
        env = dict(os.environ)
        env.setdefault("OMP_NUM_THREADS", "1")
        if int(np) == 1:
            for key, value in SERIAL_MPI_ENV.items():
                env.setdefault(key, value)
        return env


#: Open MPI settings of a serial job (``np == 1``; Debian's LIGGGHTS and LAMMPS are Open MPI 4.1
#: programs, and a serial run is an MPI singleton): the singleton starts no ``orted`` daemon
#: (``ess_singleton_isolated``) and opens no transport but the process's own loopback (``btl self``,
#: ``pml ob1``). A single process exchanges no message, so the computation and every output are the
#: same (tests/reference_runs/test_ref_engines.py: a serial job's outputs byte for byte with and
#: without them); only the start-up is shorter: ``lmp -in /dev/null`` took 0.36-0.41 s of wall time
#: and 0.10-0.11 s with them (0.26-0.31 s with the first alone), of which 0.02-0.03 s of CPU either
#: way (docs/reference_runs.md). Jobs under ``mpirun`` (np > 1) keep Open MPI's defaults.
SERIAL_MPI_ENV = {"OMPI_MCA_ess_singleton_isolated": "1", "OMPI_MCA_btl": "self", "OMPI_MCA_pml": "ob1"}


LIGGGHTS = Engine(
    name="liggghts",
    label="LIGGGHTS",
    binary="liggghts",
    deck_name="in.liggghts",
    package="liggghts",
    package_label="LIGGGHTS-PUBLIC",
    banner=r"^LIGGGHTS \(Version ([^,)]*)",
    version_prefix="",
    install_hint=(
        "install LIGGGHTS-PUBLIC 3.8.0 with `sudo apt-get install liggghts` (Debian/Ubuntu), "
        "or put a `liggghts` binary on PATH"
    ),
)

LAMMPS = Engine(
    name="lammps",
    label="LAMMPS",
    binary="lmp",
    deck_name="in.lammps",
    package="lammps",
    package_label="LAMMPS",
    banner=r"^LAMMPS \(([^)]*)\)",
    version_prefix="LAMMPS ",
    install_hint=(
        "install LAMMPS with `sudo apt-get install lammps` (Debian/Ubuntu; the GRANULAR package "
        "is needed), or put an `lmp` binary on PATH"
    ),
)

#: the module ``yade -L`` imports first (written into each YADE job directory): it replaces
#: ``yade.remote.runServers``, which opens a Python prompt (port 9000+) and an XML-RPC server
#: (21000+) on every interface, by a function that opens nothing (docs/yade.md)
YADE_QUIET_MODULE = "gransim_yade_quiet"


@functools.lru_cache(maxsize=8)
def _yade_version(path: str, mtime_ns: int, size: int, banner: str) -> str:
    try:
        # like the other codes' probes: killed with gransim (even by SIGKILL), its group on a timeout
        with tempfile.TemporaryDirectory(prefix="dem-version-") as tmp:
            out = run_probe([path, "--version"], tmp, 60)
        text = out.stdout + out.stderr
    except (OSError, subprocess.SubprocessError) as exc:
        return f"unknown: `{path} --version` failed ({exc})"
    for line in text.splitlines():
        m = re.match(banner, line.strip())
        if m:
            return "YADE " + m.group(1)
    return f"unknown: `{path} --version` printed no 'Yade version:' line"


@dataclass(frozen=True)
class YadeEngine(Engine):
    """YADE: a Python script run by ``yade -n -x -j1 -L gransim_yade_quiet SCRIPT`` in the job
    directory (no display, exit at the script's end with status 1 on an exception, one OpenMP
    thread). Its jobs are run by :func:`reference_runs.yade.job.run_yade_job`."""

    def version(self, binary=None) -> str | None:
        """``YADE 2023.02a (/usr/bin/yade)`` from ``yade --version`` (cached per binary path,
        modification time and size), None when absent."""
        found = binary_identity(binary, self.binary)
        if found is None:
            return None
        path, mtime_ns, size = found
        return f"{_yade_version(path, mtime_ns, size, self.banner)} ({path})"

    def command(self, deck: str, log: str | None = None, np: int = 1, exe: str | None = None, variables=None) -> list:
        """``yade -n -x -j1 -L gransim_yade_quiet SCRIPT`` (``log`` is unused: YADE writes to
        stdout and stderr); :class:`ReferenceRunError` for ``np > 1`` (a YADE job is one process),
        :class:`~gransim.errors.InputError` for ``variables`` (a script takes no ``-var``)."""
        if int(np) != 1:
            raise ReferenceRunError(f"np={np}: a YADE job runs as one process (np=1)")
        if check_variables(variables):
            raise InputError("variables: a YADE job is a Python script; it takes no -var NAME VALUE")
        return [exe or self.find(), "-n", "-x", "-j1", "-L", YADE_QUIET_MODULE, deck]

    def env(self, np: int = 1) -> dict:
        """The caller's environment without ``DISPLAY`` and with ``OMP_NUM_THREADS=1`` (a YADE job is
        one process, ``np`` 1, and YADE's own modules start no MPI singleton)."""
        env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
        env["OMP_NUM_THREADS"] = "1"
        return env


YADE = YadeEngine(
    name="yade",
    label="YADE",
    binary="yade",
    deck_name="yade_job.py",
    package="yade",
    package_label="YADE",
    banner=r"^(?:Welcome to Yade|Yade version:) (\S+)",
    version_prefix="YADE ",
    install_hint=(
        "install YADE 2023.02a with `sudo apt-get install yade` (Debian/Ubuntu), or put a `yade` binary on PATH"
    ),
)

#: the known engines by name
ENGINES = {e.name: e for e in (LIGGGHTS, LAMMPS, YADE)}


def get_engine(name) -> Engine:
    """The :class:`Engine` called ``name`` (an Engine is returned as is); :class:`InputError`
    naming the known engines otherwise."""
    if isinstance(name, Engine):
        return name
    try:
        return ENGINES[str(name).strip().lower()]
    except KeyError:
        raise InputError(f"engine: unknown DEM code {name!r}; choose one of: {', '.join(ENGINES)}") from None


def engine_of_log(line: str) -> tuple[Engine, str] | tuple[None, None]:
    """``(engine, version)`` of a log banner line, or ``(None, None)``."""
    for e in ENGINES.values():
        v = e.log_version(line)
        if v is not None:
            return e, v
    return None, None


__all__ = [
    "ENGINES",
    "Engine",
    "LAMMPS",
    "LIGGGHTS",
    "YADE",
    "YadeEngine",
    "check_variables",
    "engine_of_log",
    "get_engine",
    "variables_text",
]
