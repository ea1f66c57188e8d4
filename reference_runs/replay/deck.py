"""Reader of a user's LIGGGHTS 3.8.0 or LAMMPS (29 Sep 2021) deck of 2D periodic disks.

Only a subset of either input language is accepted (:data:`SUPPORTED`): everything else stops
the reader with an :class:`~gransim.errors.InputError` naming the file, the line and the
command, and listing the supported commands. Nothing is skipped silently: commands that are
accepted but have no effect on the native run (output settings, memory options) are listed in
:attr:`ReplayDeck.notes`, which the replay report prints.

The subset (see docs/replay.md):

======================  ====================================  =====================================
command                 LIGGGHTS                              LAMMPS
======================  ====================================  =====================================
contact law             ``fix ID all property/global kn|kt|   ``pair_style gran/hooke/history
                        gamman|gammat|coefficientFriction     KN KT GAMMAN GAMMAT MU 1``
                        peratomtypepair 1 V`` + ``pair_style  (KT, GAMMAT may be ``NULL``: 2 KN/7,
                        gran model hooke/stiffness            GAMMAN/2; DAMPFLAG 0: GAMMAT = 0)
                        tangential history``
2D masses               data file density = mass per area     ``set group all density/disc RHO``
integrator              ``fix ID all nve/sphere``             ``fix ID all nve/sphere disc``
ghost velocities        ``communicate single vel yes``        ``comm_modify [mode single] vel yes``
======================  ====================================  =====================================

and, common to both: ``units si``, ``dimension 2``, ``boundary p p p``, ``atom_style sphere``,
``atom_modify map ... sort N BIN``, ``newton off``, ``read_data FILE`` (any box origin),
``neighbor SKIN bin``, ``neigh_modify delay 0 every 1 check yes [one N] [page N]``,
``pair_coeff * *``, ``timestep DT``, ``fix ID all enforce2d``, ``fix ID all deform N x|y
erate|trate|vel|final|delta|scale ... remap x [units box|lattice] [flip yes|no]``,
``compute ID all pressure TEMP [ke] [pair|virial]``, ``thermo N``, ``thermo_style custom step ...``,
``thermo_modify format float|line F norm yes|no flush yes|no``, ``dump ID all custom N FILE
cols``, ``dump_modify ID sort id format ...``, ``variable NAME equal EXPR`` (a number may be
used as ``${NAME}`` or ``$N``; other expressions only as thermo columns ``v_NAME``, printed, not
compared), ``variable NAME index V``, the command-line variables (``--var``: the codes' ``-var``),
``compute temp``, ``compute property/atom``, ``compute pair/gran/local`` (LIGGGHTS), ``compute
pair/local`` and ``property/local`` (LAMMPS), ``dump local``, ``undump``, and several ``run N``
(``run 0`` included) with only output commands between them (:data:`BETWEEN_RUNS`).
Sheared LAMMPS decks: ``change_box all triclinic`` (or a data file
with ``XY 0 0 xy xz yz``) and ``fix ID all deform N xy erate|trate|vel|final|delta V remap v``, run
natively through :class:`gransim.dem.sheared.ShearEngine`; what it cannot express, and any tilt
in a LIGGGHTS deck (its triclinic box loses the periodic ghosts), is refused naming the line.
"""

from __future__ import annotations

import dataclasses
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gransim.dem.settings import DEMSettings
from gransim.dem.sheared import ShearLoading, tilt_stop
from gransim.errors import InputError
from gransim.geometry import Packing
from reference_runs.parsers import pair_gran_local_names

from .deform import STYLES, TILT_STYLES, AxisDeform, DeformSpec

#: why a LIGGGHTS deck with a tilt is refused
LIGGGHTS_TILT = (
    "LIGGGHTS 3.8.0's triclinic box loses the periodic ghosts (contacts across the tilted "
    "boundary are missed; docs/liggghts.md), so a sheared LIGGGHTS deck is not "
    "replayed: use a LAMMPS deck (`change_box all triclinic`, `fix deform 1 xy erate R remap v`)"
)

ENGINES = ("liggghts", "lammps")

#: the accepted commands (LIGGGHTS-only and LAMMPS-only ones are marked)
SUPPORTED = (
    "units si",
    "dimension 2",
    "boundary p p p",
    "atom_style sphere",
    "atom_modify",
    "newton off",
    "communicate single vel yes (LIGGGHTS)",
    "comm_modify vel yes (LAMMPS)",
    "read_data",
    "set group all density/disc (LAMMPS)",
    "neighbor SKIN bin",
    "neigh_modify delay 0 every 1 check yes",
    "fix property/global kn|kt|gamman|gammat|coefficientFriction peratomtypepair 1 (LIGGGHTS)",
    "pair_style gran model hooke/stiffness tangential history (LIGGGHTS)",
    "pair_style gran/hooke/history (LAMMPS)",
    "pair_coeff * *",
    "timestep",
    "fix nve/sphere (LAMMPS: nve/sphere disc)",
    "fix enforce2d",
    "fix deform (x/y erate|trate|vel|final|delta|scale, remap x)",
    "change_box all triclinic + fix deform N xy erate|trate|vel|final|delta remap v (LAMMPS)",
    "compute pressure TEMP [ke] [pair|virial]",
    "compute temp",
    "compute property/atom",
    "compute pair/gran/local (LIGGGHTS)",
    "compute pair/local, compute property/local (LAMMPS)",
    "thermo",
    "thermo_style custom",
    "thermo_modify",
    "dump custom",
    "dump local",
    "dump_modify",
    "undump",
    "variable equal|index",
    "run (several; output commands between them)",
)

#: commands accepted after the first ``run``: they change what is printed, not the dynamics
BETWEEN_RUNS = (
    "thermo",
    "thermo_style",
    "thermo_modify",
    "dump",
    "dump_modify",
    "undump",
    "compute",
    "variable",
    "run",
)

#: thermo keywords accepted (besides c_ID[k] of a compute pressure and v_NAME)
THERMO_KEYWORDS = (
    "step",
    "elapsed",
    "elaplong",
    "time",
    "dt",
    "cpu",
    "tpcpu",
    "spcpu",
    "cpuremain",
    "atoms",
    "ke",
    "temp",
    "pe",
    "etotal",
    "press",
    "pxx",
    "pyy",
    "pzz",
    "pxy",
    "pxz",
    "pyz",
    "lx",
    "ly",
    "lz",
    "xlo",
    "xhi",
    "ylo",
    "yhi",
    "zlo",
    "zhi",
    "vol",
    "xy",
    "xz",
    "yz",
)
#: thermo keywords LIGGGHTS 3.8.0 does not have (thermo.cpp: no temp/pressure/energy keywords
#: beyond ``ke``; it stops with "Invalid keyword in thermo_style custom command")
LAMMPS_ONLY_THERMO = ("temp", "pe", "etotal", "press", "pxx", "pyy", "pzz", "pxy", "pxz", "pyz")
#: thermo keywords that are printed and not compared (timings; the native run has its own)
UNCOMPARED_THERMO = ("elapsed", "elaplong", "cpu", "tpcpu", "spcpu", "cpuremain")
#: keywords of ``compute pair/local`` (LAMMPS) and ``compute property/local`` accepted
PAIR_LOCAL_KEYWORDS = ("dist", "eng", "force", "fx", "fy", "fz")
PROPERTY_LOCAL_KEYWORDS = ("patom1", "patom2", "ptype1", "ptype2")
#: dump custom columns accepted
DUMP_COLUMNS = (
    "id",
    "type",
    "x",
    "y",
    "z",
    "vx",
    "vy",
    "vz",
    "omegax",
    "omegay",
    "omegaz",
    "fx",
    "fy",
    "fz",
    "tqx",
    "tqy",
    "tqz",
    "mass",
    "radius",
    "diameter",
)
_LIG_LAW = ("kn", "kt", "gamman", "gammat", "coefficientFriction")


@dataclass(frozen=True)
class DumpSpec:
    """One ``dump ID all custom|local N FILE cols``: ``every`` N steps, the file name as in the
    deck, the columns, ``sort_id`` (``dump_modify ID sort id``), ``format`` (``dump_modify`` format
    text or None), the deck line, ``style`` (custom or local), ``first_run`` (index of the first
    ``run`` after the definition) and ``last_run`` (index of the last run it is active in: the
    run before its ``undump``; None: to the end)."""

    id: str
    every: int
    file: str
    columns: tuple
    sort_id: bool = False
    format: str | None = None
    line: int = 0
    style: str = "custom"
    first_run: int = 0
    last_run: int | None = None

    def active_in(self, k: int) -> bool:
        """The dump writes during run ``k`` (0-based)."""
        return self.first_run <= k and (self.last_run is None or k <= self.last_run)


@dataclass(frozen=True)
class ComputeSpec:
    """One ``compute ID all STYLE ARGS`` of the subset: style, arguments, deck line.

    ``pressure``: args (TEMP, keyword...); ``keflag``/``virial`` say whether the kinetic and the
    virial parts are included (no keyword: both; ``compute_pressure.cpp``). ``temp``: no args.
    ``property/atom``, ``pair/gran/local``, ``pair/local``, ``property/local``: the keywords.
    """

    id: str
    style: str
    args: tuple
    line: int

    @property
    def keflag(self) -> bool:
        kw = self.args[1:]
        return self.style == "pressure" and (not kw or "ke" in kw)

    @property
    def virial(self) -> bool:
        kw = self.args[1:]
        return self.style == "pressure" and (not kw or "virial" in kw or "pair" in kw)


@dataclass(frozen=True)
class RunSpec:
    """One ``run N``: its length, deck line, first step, and the output in force during it:
    ``thermo_every`` (0: first and last step only), ``thermo_columns`` (keywords of ``thermo_style
    custom``)."""

    nsteps: int
    line: int
    start: int
    thermo_every: int
    thermo_columns: tuple

    @property
    def end(self) -> int:
        return self.start + self.nsteps

    def thermo_steps(self) -> list:
        """Steps of the thermo rows: the first step, the multiples of ``thermo N`` within the
        run, and the last step (``Output::setup``, ``Output::write``; ``run 0``: one row)."""
        steps = {self.start, self.end}
        if self.thermo_every:
            e = self.thermo_every
            steps.update(range((self.start + e - 1) // e * e, self.end + 1, e))
        return sorted(steps)


@dataclass(frozen=True, eq=False)
class ReplayDeck:
    """A deck of the supported subset, read and checked.

    Attributes
    ----------
    engine : "liggghts" or "lammps" (from the syntax, or as given).
    path : the deck file. data_path : the data file read (``read_data`` or ``--data``).
    data_name : the file name as written in the deck's ``read_data``.
    packing : gransim Packing: centres (N, 2) in file order (m), radii (N,) = diameter/2 (m),
        cell diag(hi - lo) (m), density (kg/m^2: mass per area, m = pi r^2 rho). The box origin
        is kept in ``box_lo``/``box_hi`` (and in packing.metadata).
    box_lo, box_hi : (2,) box corners of x and y from the data file (m).
    ids : (N,) int64 atom ids in file order.
    velocities : (N, 2) m/s, spins : (N,) rad/s (zero without a Velocities section).
    settings : DEMSettings of the law and the step (flavour "lammps" for a LAMMPS deck when
        the installed DEMSettings has that field).
    deform : DeformSpec or None. nsteps : the ``run`` length.
    thermo_every : thermo period (0: first and last step only). thermo_columns : keywords of
        ``thermo_style custom``. thermo_float_format : the ``thermo_modify format float`` text or
        None. pressure : {compute ID: deck line} of the ``compute pressure ... virial``.
    dumps : tuple of DumpSpec. sorting : atom sorting is on (``atom_modify sort`` not 0).
    notes : accepted commands without effect on the native run, and other remarks (str).
    lines : the deck's source lines.
    tilt : the box's xy tilt at the start (m; 0 for an orthogonal box).
    sheared : the deck runs in a triclinic box (``change_box all triclinic`` or a data file with
        an ``xy xz yz`` line, LAMMPS only): natively through
        :class:`gransim.dem.sheared.ShearEngine`; then ``packing.cell`` is [[Lx, xy], [0, Ly]].
    shear : for a sheared deck, the :class:`gransim.dem.sheared.ShearLoading` of the run (the
        ``xy`` style expressed as the engine's erate, see :func:`_shear_loading`), else None.
    runs : the ``run`` commands in order (:class:`RunSpec`); ``nsteps`` is the last step.
    computes : {ID: :class:`ComputeSpec`} of every compute of the deck.
    variables : the command-line variables (``--var NAME VALUE``, the codes' ``-var``) as given.
    """

    engine: str
    path: Path
    data_path: Path
    data_name: str
    packing: Packing
    box_lo: np.ndarray
    box_hi: np.ndarray
    ids: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    settings: DEMSettings
    deform: DeformSpec | None
    nsteps: int
    thermo_every: int
    thermo_columns: tuple
    thermo_float_format: str | None
    pressure: dict
    dumps: tuple
    sorting: bool
    notes: tuple
    lines: tuple = field(repr=False, default=())
    tilt: float = 0.0
    sheared: bool = False
    shear: object = None
    runs: tuple = ()
    computes: dict = field(default_factory=dict)
    variables: dict = field(default_factory=dict)

    @property
    def d50(self) -> float:
        """Median diameter (m): the length scale of the position tolerance."""
        return float(np.median(2.0 * self.packing.radii))


class _Err:
    """Error messages naming the file and the line."""

    def __init__(self, path: Path):
        self.path = path

    def __call__(self, lineno: int, msg: str) -> InputError:
        return InputError(f"{self.path}:{lineno}: {msg}")


def _supported_text() -> str:
    return "supported commands: " + "; ".join(SUPPORTED)


def _float(err, lineno, word, what):
    try:
        v = float(word)
    except (TypeError, ValueError):
        raise err(lineno, f"{what}: expected a number, got {word!r}") from None
    if not np.isfinite(v):
        raise err(lineno, f"{what}: expected a finite number, got {word!r}")
    return v


def _int(err, lineno, word, what, minimum=None):
    try:
        v = int(word)
    except (TypeError, ValueError):
        raise err(lineno, f"{what}: expected an integer, got {word!r}") from None
    if minimum is not None and v < minimum:
        raise err(lineno, f"{what}: expected an integer >= {minimum}, got {v}")
    return v


def _logical_lines(text: str):
    """(first line number, text) of each command: comments removed (``#`` outside quotes),
    ``&`` continuations joined, blank lines dropped."""
    out = []
    buf, start = "", 0
    for n, raw in enumerate(text.splitlines(), start=1):
        line = _strip_comment(raw).rstrip()
        if not buf:
            start = n
        if line.endswith("&"):
            buf += line[:-1] + " "
            continue
        buf += line
        if buf.strip():
            out.append((start, buf.strip()))
        buf = ""
    if buf.strip():
        out.append((start, buf.strip()))
    return out


def _strip_comment(line: str) -> str:
    quote = None
    for i, c in enumerate(line):
        if quote:
            if c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c == "#":
            return line[:i]
    return line


_VAR = re.compile(r"\$\{([A-Za-z0-9_]+)\}|\$([A-Za-z0-9_])")


def read_deck(path, data=None, engine: str | None = None, variables=None) -> ReplayDeck:
    """Read and check a deck of the supported subset (see the module docstring).

    Parameters
    ----------
    path : the deck file.
    data : the data file to use instead of the one ``read_data`` names (optional).
    engine : "liggghts" or "lammps" to insist on one syntax (default: detected).
    variables : {NAME: VALUE} (or (NAME, VALUE) pairs) given on the command line, as the codes'
        ``-var NAME VALUE``: index-style variables defined before the deck's first line
        (``Variable::set`` of ``-var``), substituted as text; a deck's ``variable NAME index ...``
        of the same name is then ignored, as the codes do.

    Raises
    ------
    InputError naming the file, the line and the command for anything outside the subset, a
    malformed number or a missing required command.
    """
    path = Path(path)
    if engine is not None and engine not in ENGINES:
        raise InputError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the deck ({exc})") from None
    err = _Err(path)
    st = _State(path, err, engine)
    st.command_line(variables)
    for lineno, line in _logical_lines(text):
        line = st.substitute(lineno, line)
        try:
            words = shlex.split(line, posix=True)
        except ValueError as exc:
            raise err(lineno, f"cannot split the line ({exc}): {line!r}") from None
        st.command(lineno, words, line)
    return st.finish(text, data)


class _State:
    def __init__(self, path: Path, err, engine):
        self.path, self.err = path, err
        self.engine_given = engine
        self.votes: list = []  # (engine, line, why)
        self.seen: dict = {}
        self.notes: list = []
        self.variables: dict = {}  # name -> (substitution text or None, expr, line, style)
        self.cmdline: dict = {}  # the --var variables, as given
        self.law_lig: dict = {}
        self.law_lmp = None
        self.pair_line = 0
        self.density_disc = None
        self.read_data = None
        self.skin = None
        self.neigh = None
        self.dt = None
        self.nve = None
        self.enforce2d = None
        self.deform = None
        self.pressure: dict = {}
        self.computes: dict = {}
        self.runs: list = []  # RunSpec
        self.step = 0
        self.undumped: dict = {}  # dump id -> line of its undump
        self.thermo_every = 0
        self.thermo_columns = None
        self.thermo_line = 0
        self.lammps_thermo: dict = {}  # LAMMPS-only thermo keyword -> line
        self.thermo_float = None
        self.dumps: dict = {}
        self.dump_mod: dict = {}
        self.sorting = True
        self.newton_off = None
        self.comm_vel = None
        self.law_style = None
        self.neigh_line = 0
        self.triclinic = None

    # ---------------------------------------------------------------- helpers
    def vote(self, engine, lineno, why):
        self.votes.append((engine, lineno, why))

    def command_line(self, variables):
        """The ``--var NAME VALUE`` variables: index style, defined before the deck's first line."""
        pairs = list(variables.items()) if isinstance(variables, dict) else list(variables or ())
        for name, value in pairs:
            if not re.fullmatch(r"[A-Za-z0-9_]+", str(name)):
                raise InputError(f"--var {name!r}: a variable name is letters, digits and underscores")
            if name in self.cmdline:
                raise InputError(f"--var {name}: given twice")
            value = str(value)
            if not value or any(c.isspace() for c in value):
                raise InputError(f"--var {name} {value!r}: the value is one word (as the codes' -var)")
            self.cmdline[name] = value
            self.variables[name] = (value, value, 0, "index")

    def substitute(self, lineno, line):
        if "$(" in line:
            raise self.err(lineno, "immediate variables $(...) are not in the supported subset")

        def rep(m):
            name = m.group(1) or m.group(2)
            if name not in self.variables:
                raise self.err(
                    lineno,
                    f"${{{name}}}: no variable {name!r} defined before this line (one given on the "
                    "command line: --var NAME VALUE, as the codes' -var)",
                )
            val = self.variables[name][0]
            if val is None:
                raise self.err(
                    lineno,
                    f"${{{name}}}: only variables holding a number or an index value may be "
                    f"substituted (variable {name} is {self.variables[name][1]!r})",
                )
            return val

        return _VAR.sub(rep, line)

    def unsupported(self, lineno, what):
        return self.err(lineno, f"{what} is not in the supported subset of `gransim replay`; " + _supported_text())

    def once(self, lineno, key):
        if key in self.seen:
            raise self.err(lineno, f"`{key}` given twice (first at line {self.seen[key]}); the replay accepts it once")
        self.seen[key] = lineno

    def expect(self, lineno, words, want, cmd):
        if [w.lower() for w in words[1:]] != [w.lower() for w in want]:
            raise self.err(lineno, f"`{' '.join(words)}`: the subset needs `{cmd} {' '.join(want)}`")

    def group_all(self, lineno, words):
        if len(words) < 3 or words[2] != "all":
            raise self.err(lineno, f"`{' '.join(words[:4])}`: only the group `all` is supported")

    # ---------------------------------------------------------------- commands
    def command(self, lineno, w, line):
        cmd = w[0]
        h = getattr(self, "c_" + cmd.replace("/", "_"), None)
        if h is None:
            raise self.unsupported(lineno, f"command `{cmd}`")
        if self.runs and cmd not in BETWEEN_RUNS:
            raise self.err(
                lineno,
                f"`{cmd}` after a `run` (line {self.runs[0].line}) may change the dynamics between "
                f"runs; the replay accepts only output commands there ({', '.join(BETWEEN_RUNS)})",
            )
        h(lineno, w)

    def c_units(self, n, w):
        self.once(n, "units")
        self.expect(n, w, ["si"], "units")

    def c_dimension(self, n, w):
        self.once(n, "dimension")
        self.expect(n, w, ["2"], "dimension")

    def c_boundary(self, n, w):
        self.once(n, "boundary")
        self.expect(n, w, ["p", "p", "p"], "boundary")

    def c_atom_style(self, n, w):
        self.once(n, "atom_style")
        self.expect(n, w, ["sphere"], "atom_style")

    def c_atom_modify(self, n, w):
        k = 1
        while k < len(w):
            key = w[k]
            if key == "map" and k + 1 < len(w) and w[k + 1] in ("array", "hash", "yes"):
                k += 2
            elif key == "sort" and k + 2 < len(w):
                every = _int(self.err, n, w[k + 1], "atom_modify sort Nfreq", minimum=0)
                _float(self.err, n, w[k + 2], "atom_modify sort binsize")
                self.sorting = every != 0
                k += 3
            else:
                raise self.err(
                    n, f"atom_modify keyword {key!r}: supported are `map array|hash|yes` and `sort Nfreq binsize`"
                )

    def c_newton(self, n, w):
        self.once(n, "newton")
        if [x.lower() for x in w[1:]] not in (["off"], ["off", "off"]):
            raise self.err(
                n,
                f"`{' '.join(w)}`: the native engine mirrors `newton off` (granular "
                "history needs it in LIGGGHTS); write `newton off`",
            )
        self.newton_off = n

    def c_communicate(self, n, w):
        self.vote("liggghts", n, "communicate")
        self.once(n, "communicate")
        if w[1:] != ["single", "vel", "yes"]:
            raise self.err(
                n, f"`{' '.join(w)}`: the subset needs `communicate single vel yes` (ghost atoms carry velocities)"
            )
        self.comm_vel = n

    def c_comm_modify(self, n, w):
        self.vote("lammps", n, "comm_modify")
        self.once(n, "comm_modify")
        if w[1:] not in (["mode", "single", "vel", "yes"], ["vel", "yes"], ["vel", "yes", "mode", "single"]):
            raise self.err(
                n, f"`{' '.join(w)}`: the subset needs `comm_modify mode single vel yes` (ghost atoms carry velocities)"
            )
        self.comm_vel = n

    def c_read_data(self, n, w):
        self.once(n, "read_data")
        if len(w) != 2:
            raise self.err(n, f"`{' '.join(w)}`: the subset needs `read_data FILE` without keywords")
        self.read_data = (w[1], n)

    def c_set(self, n, w):
        self.vote("lammps", n, "set density/disc")
        if len(w) != 5 or w[1:4] != ["group", "all", "density/disc"]:
            raise self.err(n, f"`{' '.join(w)}`: only `set group all density/disc RHO` is supported")
        if self.read_data is None:
            raise self.err(n, "`set group all density/disc` before `read_data`: it must follow it")
        rho = _float(self.err, n, w[4], "set density/disc RHO")
        if rho <= 0:
            raise self.err(n, f"set density/disc RHO: expected > 0 (kg/m^2), got {w[4]!r}")
        self.once(n, "set")
        self.density_disc = (rho, n)

    def c_change_box(self, n, w):
        self.vote("lammps", n, "change_box all triclinic")
        if w[1:] != ["all", "triclinic"]:
            raise self.err(n, f"`{' '.join(w)}`: the subset accepts only `change_box all triclinic`")
        if self.read_data is None:
            raise self.err(n, "`change_box all triclinic` before `read_data`: it must follow it")
        self.once(n, "change_box")
        self.triclinic = n

    def c_neighbor(self, n, w):
        self.once(n, "neighbor")
        if len(w) != 3 or w[2] != "bin":
            raise self.err(n, f"`{' '.join(w)}`: the subset needs `neighbor SKIN bin`")
        skin = _float(self.err, n, w[1], "neighbor SKIN")
        if skin <= 0:
            raise self.err(n, f"neighbor SKIN: expected > 0 (m), got {w[1]!r}")
        self.skin = (skin, n)

    def c_neigh_modify(self, n, w):
        got = dict(self.neigh or {})
        k = 1
        while k < len(w):
            key = w[k]
            if k + 1 >= len(w):
                raise self.err(n, f"neigh_modify {key}: a value is missing")
            val = w[k + 1]
            if key in ("delay", "every", "check"):
                got[key] = val
            elif key in ("one", "page"):
                _int(self.err, n, val, f"neigh_modify {key}", minimum=1)
                self.notes.append(f"line {n}: neigh_modify {key} {val} (list memory only; no effect on the native run)")
            else:
                raise self.err(n, f"neigh_modify keyword {key!r}: supported are delay, every, check, one, page")
            k += 2
        self.neigh = got
        self.neigh_line = n

    def c_fix(self, n, w):
        if len(w) < 4:
            raise self.err(n, f"`{' '.join(w)}`: a fix needs ID group style")
        style = w[3]
        self.group_all(n, w)
        if style == "property/global":
            self.vote("liggghts", n, "fix property/global")
            if len(w) < 6 or w[4] not in _LIG_LAW:
                raise self.err(
                    n,
                    f"fix property/global {w[4] if len(w) > 4 else ''}: the subset reads "
                    f"{', '.join(_LIG_LAW)} (hooke/stiffness)",
                )
            if len(w) != 8 or w[5] != "peratomtypepair" or w[6] != "1":
                raise self.err(
                    n, f"fix property/global {w[4]}: expected `{w[4]} peratomtypepair 1 VALUE` (one atom type)"
                )
            v = _float(self.err, n, w[7], f"fix property/global {w[4]} coefficient")
            if v < 0:
                raise self.err(n, f"fix property/global {w[4]} coefficient: expected >= 0, got {w[7]!r}")
            if w[4] in self.law_lig:
                raise self.err(n, f"fix property/global {w[4]} given twice (line {self.law_lig[w[4]][1]})")
            self.law_lig[w[4]] = (v, n)
        elif style == "nve/sphere":
            if self.nve is not None:
                raise self.err(n, f"a second integrator (first at line {self.nve[1]})")
            if w[4:] == ["disc"]:
                self.vote("lammps", n, "nve/sphere disc")
            elif w[4:]:
                raise self.err(
                    n, f"`{' '.join(w)}`: supported are `nve/sphere` (LIGGGHTS) and `nve/sphere disc` (LAMMPS)"
                )
            self.nve = (w[4:], n)
        elif style == "enforce2d":
            if w[4:]:
                raise self.err(n, f"`{' '.join(w)}`: enforce2d takes no arguments here")
            self.enforce2d = n
        elif style == "deform":
            self.c_deform(n, w)
        else:
            raise self.unsupported(n, f"fix style `{style}`")

    def c_deform(self, n, w):
        if self.deform is not None:
            raise self.err(n, f"a second fix deform (first at line {self.deform.line})")
        if len(w) < 5:
            raise self.err(n, "fix deform: N (every) is missing")
        every = _int(self.err, n, w[4], "fix deform N", minimum=1)
        axes = [None, None]
        tilt = None
        k = 5
        remap, units = "x", None
        while k < len(w):
            key = w[k]
            if key in ("x", "y"):
                if k + 1 >= len(w):
                    raise self.err(n, f"fix deform {key}: the style is missing")
                style = w[k + 1]
                if style not in STYLES:
                    if style in ("volume", "wiggle", "variable"):
                        raise self.err(
                            n, f"fix deform {key} {style}: not in the subset (supported styles: {', '.join(STYLES)})"
                        )
                    raise self.err(n, f"fix deform {key} {style!r}: unknown style (supported: {', '.join(STYLES)})")
                m = STYLES[style]
                if k + 2 + m > len(w):
                    raise self.err(n, f"fix deform {key} {style}: expected {m} number(s)")
                vals = tuple(_float(self.err, n, v, f"fix deform {key} {style} value") for v in w[k + 2 : k + 2 + m])
                d = 0 if key == "x" else 1
                if axes[d] is not None:
                    raise self.err(n, f"fix deform: axis {key} given twice")
                axes[d] = AxisDeform(style, vals)
                k += 2 + m
            elif key == "z":
                raise self.err(n, "fix deform z: the z extent of a 2D deck must stay (not in the subset)")
            elif key in ("xz", "yz"):
                raise self.err(n, f"fix deform {key}: a 2D deck has no {key} tilt (only xy)")
            elif key == "xy":
                style = w[k + 1] if k + 1 < len(w) else None
                if style not in TILT_STYLES:
                    raise self.err(
                        n,
                        f"fix deform xy {style}: not in the subset (supported tilt styles: "
                        f"{', '.join(TILT_STYLES)}; the triclinic (sheared) periodic cell "
                        "runs natively through ShearEngine)",
                    )
                if k + 2 >= len(w):
                    raise self.err(n, f"fix deform xy {style}: expected 1 number")
                tilt = (style, _float(self.err, n, w[k + 2], f"fix deform xy {style} value"))
                k += 3
            elif key == "remap":
                if k + 1 >= len(w):
                    raise self.err(n, "fix deform remap: the value is missing")
                remap = w[k + 1]
                if remap not in ("x", "v"):
                    raise self.err(
                        n,
                        f"fix deform remap {remap}: supported are remap x (orthogonal box) "
                        "and remap v (sheared box, LAMMPS)",
                    )
                k += 2
            elif key == "units":
                if k + 1 >= len(w) or w[k + 1] not in ("box", "lattice"):
                    raise self.err(n, "fix deform units: expected box or lattice")
                units = w[k + 1]
                k += 2
            elif key == "flip":
                if k + 1 >= len(w) or w[k + 1] not in ("yes", "no"):
                    raise self.err(n, "fix deform flip: expected yes or no")
                self.notes.append(
                    f"line {n}: fix deform flip {w[k + 1]} (no flip happens: a tilt beyond "
                    "Lx/2 is refused before the run)"
                )
                k += 2
            else:
                raise self.err(n, f"fix deform keyword {key!r}: supported are x, y, remap, units, flip")
        if axes == [None, None] and tilt is None:
            raise self.err(n, "fix deform: no x, y or xy setting")
        self.deform = DeformSpec(every, tuple(axes), remap, units or "", n, tilt)

    def c_pair_style(self, n, w):
        self.once(n, "pair_style")
        self.pair_line = n
        if w[1:2] == ["gran"]:
            self.vote("liggghts", n, "pair_style gran model")
            if w[2:] != ["model", "hooke/stiffness", "tangential", "history"]:
                raise self.err(
                    n,
                    f"`{' '.join(w)}`: the subset needs `pair_style gran model hooke/stiffness "
                    "tangential history` (no further model options)",
                )
            self.law_style = "liggghts"
        elif w[1:2] == ["gran/hooke/history"]:
            self.vote("lammps", n, "pair_style gran/hooke/history")
            a = w[2:]
            if len(a) != 6:
                raise self.err(
                    n,
                    f"pair_style gran/hooke/history: expected 6 arguments KN KT GAMMAN GAMMAT "
                    f"XMU DAMPFLAG, got {len(a)}",
                )
            names = ("KN", "KT", "GAMMAN", "GAMMAT", "XMU")
            v = {}
            for name, word in zip(names, a[:5]):
                if word == "NULL" and name in ("KT", "GAMMAT"):
                    v[name] = None
                else:
                    v[name] = _float(self.err, n, word, f"pair_style gran/hooke/history {name}")
                    if v[name] < 0:
                        raise self.err(n, f"pair_style gran/hooke/history {name}: expected >= 0, got {word!r}")
            if a[5] not in ("0", "1"):
                raise self.err(n, f"pair_style gran/hooke/history DAMPFLAG: expected 0 or 1, got {a[5]!r}")
            # LAMMPS PairGranHookeHistory::settings: NULL kt = kn*2/7, NULL gammat = gamman/2,
            # dampflag 0 zeroes gammat
            kt = v["KN"] * 2.0 / 7.0 if v["KT"] is None else v["KT"]
            gt = 0.5 * v["GAMMAN"] if v["GAMMAT"] is None else v["GAMMAT"]
            if a[5] == "0":
                gt = 0.0
            if v["XMU"] > 10000.0:
                raise self.err(n, f"pair_style gran/hooke/history XMU: expected <= 10000, got {a[4]!r}")
            self.law_lmp = (v["KN"], kt, v["GAMMAN"], gt, v["XMU"])
            self.law_style = "lammps"
        else:
            raise self.unsupported(n, f"pair_style `{' '.join(w[1:2])}`")

    def c_pair_coeff(self, n, w):
        self.once(n, "pair_coeff")
        self.expect(n, w, ["*", "*"], "pair_coeff")

    def c_timestep(self, n, w):
        self.once(n, "timestep")
        if len(w) != 2:
            raise self.err(n, "timestep: expected one value DT (s)")
        dt = _float(self.err, n, w[1], "timestep DT")
        if dt <= 0:
            raise self.err(n, f"timestep DT: expected > 0 (s), got {w[1]!r}")
        self.dt = (dt, n)

    def c_compute(self, n, w):
        if len(w) < 4:
            raise self.err(n, f"`{' '.join(w)}`: a compute needs ID group style")
        self.group_all(n, w)
        cid, style, args = w[1], w[3], tuple(w[4:])
        if cid in self.computes:
            raise self.err(n, f"compute {cid} defined twice (line {self.computes[cid].line})")
        if style == "pressure":
            self._compute_pressure(n, w, cid, args)
        elif style == "temp":
            if args:
                raise self.err(n, f"`{' '.join(w)}`: the subset has `compute ID all temp` without keywords")
        elif style == "property/atom":
            if not args:
                raise self.err(n, f"compute {cid} property/atom: no attribute given")
            quiet = [a for a in args if a not in DUMP_COLUMNS]
            if quiet:
                self.notes.append(f"line {n}: compute {cid} property/atom {' '.join(quiet)}: printed, not compared")
        elif style == "pair/gran/local":
            self.vote("liggghts", n, "compute pair/gran/local")
            if self.runs:
                raise self.err(
                    n,
                    "compute pair/gran/local after a run: LIGGGHTS stops ('Need to define this compute "
                    "before first run', compute_pair_gran_local.cpp); define it before the first run",
                )
            try:
                pair_gran_local_names(args, 3)
            except ValueError as exc:
                raise self.err(n, f"compute {cid} pair/gran/local: {exc}") from None
        elif style == "pair/local":
            self.vote("lammps", n, "compute pair/local")
            bad = [a for a in args if a not in PAIR_LOCAL_KEYWORDS and not re.fullmatch(r"p([1-9]|10)", a)]
            if not args or bad:
                raise self.err(
                    n,
                    f"compute {cid} pair/local {' '.join(bad)}: supported are {', '.join(PAIR_LOCAL_KEYWORDS)} "
                    "and p1..p10 (gran/hooke/history's single())",
                )
        elif style == "property/local":
            self.vote("lammps", n, "compute property/local")
            bad = [a for a in args if a not in PROPERTY_LOCAL_KEYWORDS]
            if not args or bad:
                raise self.err(
                    n,
                    f"compute {cid} property/local {' '.join(bad)}: supported are "
                    f"{', '.join(PROPERTY_LOCAL_KEYWORDS)} (pairs of the neighbour list)",
                )
        else:
            raise self.unsupported(n, f"compute style `{style}`")
        self.computes[cid] = ComputeSpec(cid, style, args, n)

    def _compute_pressure(self, n, w, cid, args):
        if not args:
            raise self.err(n, f"`{' '.join(w)}`: compute pressure needs a temperature compute ID (or NULL)")
        temp, kw = args[0], args[1:]
        bad = [k for k in kw if k not in ("ke", "pair", "virial")]
        if bad or len(set(kw)) != len(kw):
            raise self.err(
                n,
                f"`{' '.join(w)}`: compute pressure keywords {' '.join(bad or kw)}: the subset has ke, pair "
                "and virial (the pair virial is the whole virial of a granular deck without bonds or "
                "fix virials)",
            )
        ke = not kw or "ke" in kw
        if temp == "NULL":
            self.vote("lammps", n, "compute pressure NULL")
            if ke:
                raise self.err(n, f"`{' '.join(w)}`: a kinetic part needs a temperature compute, not NULL")
        elif temp != "thermo_temp" and (temp not in self.computes or self.computes[temp].style != "temp"):
            raise self.err(
                n,
                f"compute pressure {temp}: no `compute {temp} all temp` defined before this line "
                "(the pressure names its temperature compute)",
            )
        self.pressure[cid] = n

    def c_thermo(self, n, w):
        if len(w) != 2:
            raise self.err(n, "thermo: expected one value N")
        self.thermo_every = _int(self.err, n, w[1], "thermo N", minimum=0)

    def c_thermo_style(self, n, w):
        if len(w) < 3 or w[1] != "custom" or w[2] != "step":
            raise self.err(n, "thermo_style: the subset needs `thermo_style custom step ...` (step first)")
        for kw in w[2:]:
            self._thermo_keyword(n, kw)
        self.thermo_columns = tuple(w[2:])
        self.thermo_line = n

    def _thermo_keyword(self, n, kw):
        m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", kw)
        if m:
            c = self.computes.get(m.group(1))
            if c is None or c.style not in ("pressure", "temp"):
                raise self.err(
                    n,
                    f"thermo keyword {kw!r}: compute {m.group(1)!r} is not a `compute pressure` or "
                    "`compute temp` defined before this line (the global values of the subset)",
                )
            if m.group(3) is not None and int(m.group(3)) not in (1, 2, 3, 4, 5, 6):
                raise self.err(n, f"thermo keyword {kw!r}: compute {c.style} has components 1..6")
        elif kw.startswith("v_"):
            if kw[2:] not in self.variables:
                raise self.err(n, f"thermo keyword {kw!r}: no variable {kw[2:]!r} defined before this line")
            self.notes.append(f"line {n}: thermo column {kw} is printed, not compared")
        elif kw.lower() not in THERMO_KEYWORDS:
            raise self.err(
                n,
                f"thermo keyword {kw!r}: supported are {', '.join(THERMO_KEYWORDS)}, "
                "c_ID[k] of a compute pressure or temp, and v_NAME",
            )
        elif kw.lower() in UNCOMPARED_THERMO:
            self.notes.append(f"line {n}: thermo column {kw} (a timing) is printed, not compared")
        if kw.lower() in LAMMPS_ONLY_THERMO:
            self.lammps_thermo.setdefault(kw.lower(), n)

    def c_thermo_modify(self, n, w):
        k = 1
        while k < len(w):
            key = w[k]
            if key == "format" and k + 2 < len(w) + 0 and w[k + 1] in ("float", "line", "int"):
                if w[k + 1] == "float":
                    self.thermo_float = w[k + 2]
                elif w[k + 1] == "line":
                    self.notes.append(f"line {n}: thermo_modify format line {w[k + 2]!r}")
                    self.thermo_float = self.thermo_float or w[k + 2]
                k += 3
            elif key in ("norm", "flush") and k + 1 < len(w) and w[k + 1] in ("yes", "no"):
                if key == "norm" and w[k + 1] == "yes":
                    raise self.err(n, "thermo_modify norm yes: extensive values would be divided by N; use norm no")
                k += 2
            else:
                raise self.err(
                    n, f"thermo_modify keyword {key!r}: supported are format float|line F, norm no, flush yes|no"
                )

    def c_dump(self, n, w):
        if len(w) < 6:
            raise self.err(n, f"`{' '.join(w)}`: expected `dump ID all custom|local N FILE columns`")
        self.group_all(n, w)
        if w[3] not in ("custom", "local"):
            raise self.unsupported(n, f"dump style `{w[3]}`")
        if w[1] in self.dumps or w[1] in self.undumped:
            raise self.err(n, f"dump {w[1]} defined twice")
        every = _int(self.err, n, w[4], f"dump {w[1]} N", minimum=1)
        cols = tuple(w[6:])
        if not cols:
            raise self.err(n, f"dump {w[1]}: no columns")
        if "*" in w[5] or "%" in w[5] or w[5].endswith((".gz", ".bin")):
            raise self.err(n, f"dump {w[1]} file {w[5]!r}: one plain text file is supported (no *, %, .gz)")
        if any(d.file == w[5] for d in self.dumps.values()):
            raise self.err(n, f"dump {w[1]} file {w[5]!r} is written by another dump of the deck")
        if w[3] == "custom":
            for c in cols:
                if c not in DUMP_COLUMNS and not self._compute_column(c, ("property/atom",)):
                    raise self.err(
                        n,
                        f"dump {w[1]} column {c!r}: supported are {', '.join(DUMP_COLUMNS)} and c_ID[k] of a "
                        "compute property/atom",
                    )
            if "id" not in cols:
                raise self.err(n, f"dump {w[1]}: the column `id` is needed to compare atoms")
        else:
            for c in cols:
                if c != "index" and not self._compute_column(c, ("pair/gran/local", "pair/local", "property/local")):
                    raise self.err(
                        n,
                        f"dump {w[1]} local column {c!r}: supported are index and c_ID[k] of a compute "
                        "pair/gran/local (LIGGGHTS), pair/local or property/local (LAMMPS)",
                    )
        self.dumps[w[1]] = DumpSpec(w[1], every, w[5], cols, line=n, style=w[3], first_run=len(self.runs))

    def _compute_column(self, col, styles) -> bool:
        """``col`` is c_ID or c_ID[k] of a compute of one of ``styles``, k within its values."""
        m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", col)
        c = self.computes.get(m.group(1)) if m else None
        if c is None or c.style not in styles:
            return False
        width = len(pair_gran_local_names(c.args, 3)) if c.style == "pair/gran/local" else len(c.args)
        k = int(m.group(3)) if m.group(3) else None
        return (k is None and width == 1) or (k is not None and 1 <= k <= width)

    def c_undump(self, n, w):
        if len(w) != 2 or w[1] not in self.dumps:
            raise self.err(n, f"undump: no dump {w[1] if len(w) > 1 else ''!r} defined before this line")
        d = self.dumps.pop(w[1])
        self.undumped[w[1]] = dataclasses.replace(d, last_run=len(self.runs) - 1)

    def c_dump_modify(self, n, w):
        if len(w) < 2 or w[1] not in self.dumps:
            raise self.err(n, f"dump_modify: no dump {w[1] if len(w) > 1 else ''!r} defined before this line")
        d = self.dumps[w[1]]
        k = 2
        while k < len(w):
            key = w[k]
            if key == "sort" and k + 1 < len(w) and w[k + 1] == "id":
                d = dataclasses.replace(d, sort_id=True)
                k += 2
            elif key == "format" and k + 1 < len(w):
                if w[k + 1] in ("float", "line", "int") and k + 2 < len(w):
                    d = dataclasses.replace(d, format=f"{w[k + 1]} {w[k + 2]}")
                    k += 3
                else:
                    d = dataclasses.replace(d, format=w[k + 1])
                    k += 2
            else:
                raise self.err(n, f"dump_modify keyword {key!r}: supported are `sort id` and `format ...`")
        self.dumps[w[1]] = d

    def c_variable(self, n, w):
        if len(w) < 4 or w[2] not in ("equal", "index"):
            raise self.err(
                n, f"`{' '.join(w[:3])}`: only `variable NAME equal EXPR` and `variable NAME index V` are supported"
            )
        name, style = w[1], w[2]
        old = self.variables.get(name)
        if style == "index":
            if old is not None and old[3] == "index":
                # Variable::set: an index variable that exists (from -var) keeps its value
                self.notes.append(f"line {n}: variable {name} index ignored: {name} = {old[0]} (already defined)")
                return
            if len(w) != 4:
                raise self.err(n, f"variable {name} index: one value (loops over several values need next/jump)")
            val = w[3]
        else:
            expr = " ".join(w[3:])
            try:
                val = f"{float(expr):.15g}"  # Variable::retrieve prints an equal-style value with %.15g
            except ValueError:
                val = None
        if old is not None:
            if old[3] != style:
                raise self.err(
                    n,
                    f"variable {name} {style}: {name} is an {old[3]}-style variable"
                    + (" (given with --var)" if old[2] == 0 else f" (line {old[2]})")
                    + "; the codes stop ('Cannot redefine variable as a different style')",
                )
            raise self.err(n, f"variable {name} defined twice (line {old[2]})")
        self.variables[name] = (val, " ".join(w[3:]), n, style)

    def c_run(self, n, w):
        if len(w) != 2:
            raise self.err(
                n, f"`{' '.join(w)}`: the subset needs `run N` without keywords (upto, start/stop, pre/post, every)"
            )
        nsteps = _int(self.err, n, w[1], "run N", minimum=0)
        if self.thermo_columns is None:
            raise self.err(
                n,
                "`run` before `thermo_style custom step ...`: the default style prints keywords "
                "LIGGGHTS lacks, and nothing to compare at full precision",
            )
        self.runs.append(RunSpec(nsteps, n, self.step, self.thermo_every, self.thermo_columns))
        self.step += nsteps

    # ---------------------------------------------------------------- finish
    def _engine(self):
        engines = {e for e, _, _ in self.votes}
        if len(engines) > 1:
            lig = next(v for v in self.votes if v[0] == "liggghts")
            lmp = next(v for v in self.votes if v[0] == "lammps")
            raise InputError(
                f"{self.path}: the deck mixes LIGGGHTS syntax ({lig[2]}, line {lig[1]}) and "
                f"LAMMPS syntax ({lmp[2]}, line {lmp[1]})"
            )
        found = engines.pop() if engines else None
        if self.engine_given is not None:
            if found is not None and found != self.engine_given:
                v = next(v for v in self.votes if v[0] == found)
                raise InputError(f"--engine {self.engine_given}: the deck is written for {found} ({v[2]}, line {v[1]})")
            return self.engine_given
        if found is None:
            raise InputError(f"{self.path}: cannot tell LIGGGHTS from LAMMPS syntax (no contact law); give --engine")
        return found

    def _need(self, cond, what):
        if not cond:
            raise InputError(f"{self.path}: {what} is missing; the replay needs it ({_supported_text()})")

    def _check_shear(self, eng, sheared, atoms, data_path):
        """Refuse, naming the line, what the sheared-cell engine cannot express (docs/replay.md)."""
        p, d = self.path, self.deform
        if eng == "liggghts":
            if self.triclinic is not None:  # pragma: no cover - change_box votes lammps
                raise InputError(f"{p}:{self.triclinic}: {LIGGGHTS_TILT}")
            if atoms["tilt"] is not None:
                raise InputError(f"{data_path}: a tilted (triclinic) box in a LIGGGHTS deck: {LIGGGHTS_TILT}")
            if d is not None and d.tilt is not None:
                raise InputError(
                    f"{p}:{d.line}: fix deform xy in a LIGGGHTS deck (needs a triclinic box): {LIGGGHTS_TILT}"
                )
            if d is not None and d.remap == "v":
                raise InputError(
                    f"{p}:{d.line}: fix deform remap v in a LIGGGHTS deck: the Lees-Edwards "
                    f"velocity convention is the sheared cell's: {LIGGGHTS_TILT}"
                )
            return
        if d is None:
            return
        if d.tilt is not None and not sheared:
            raise InputError(
                f"{p}:{d.line}: fix deform xy needs a triclinic box (`change_box all triclinic` "
                "after read_data, or a data file with an `xy xz yz` line); LAMMPS stops too"
            )
        if not sheared:
            if d.remap == "v":
                raise InputError(
                    f"{p}:{d.line}: fix deform remap v on an orthogonal box: the native "
                    "orthogonal engine maps positions (remap x) and ShearEngine (the Lees-Edwards "
                    "convention) needs a triclinic box; use remap x, or change_box all triclinic"
                )
            return
        if any(a is not None for a in d.axes):
            ax = "x" if d.axes[0] is not None else "y"
            raise InputError(
                f"{p}:{d.line}: fix deform {ax} {d.axes[0 if ax == 'x' else 1].style} on a sheared "
                "(triclinic) deck: ShearEngine keeps x fixed and moves y only under a normal-"
                "stress servo (a `variable` style, not in the subset); only `xy` is replayed"
            )
        if d.tilt is None:
            raise InputError(
                f"{p}:{d.line}: fix deform without xy on a sheared deck: nothing for ShearEngine to move"
            )  # pragma: no cover - the parser needs an x, y or xy setting
        if d.remap != "v":
            raise InputError(
                f"{p}:{d.line}: fix deform xy with remap {d.remap}: ShearEngine runs the "
                "Lees-Edwards convention of remap v (positions are not mapped when the tilt "
                "changes); write remap v"
            )

    def finish(self, text, data):
        eng = self._engine()
        p = self.path
        self._need(bool(self.runs), "`run N`")
        self._need(self.read_data is not None, "`read_data FILE`")
        for key in ("units", "dimension", "boundary", "atom_style", "pair_style", "pair_coeff"):
            self._need(key in self.seen, f"`{key}`")
        self._need(self.dt is not None, "`timestep DT`")
        self._need(self.skin is not None, "`neighbor SKIN bin`")
        self._need(
            self.nve is not None, "the integrator `fix ID all nve/sphere`" + (" disc" if eng == "lammps" else "")
        )
        self._need(self.enforce2d is not None, "`fix ID all enforce2d`")
        self._need(
            self.comm_vel is not None,
            "`communicate single vel yes` (LIGGGHTS) or `comm_modify mode single vel yes` (LAMMPS)",
        )
        if self.neigh is None:
            raise InputError(
                f"{p}: `neigh_modify delay 0 every 1 check yes` is missing: the native engine "
                "rebuilds the neighbour list exactly that way, so the deck must say so"
            )
        for key, want in (("delay", "0"), ("every", "1"), ("check", "yes")):
            if self.neigh.get(key) != want:
                got = self.neigh.get(key)
                raise InputError(
                    f"{p}:{self.neigh_line}: neigh_modify {key}: expected {want} (the native "
                    f"engine's rebuild rule), got {got if got is not None else 'the default'}"
                )
        if self.newton_off is None and eng == "lammps":
            raise InputError(
                f"{p}: `newton off` is missing (LAMMPS defaults to newton on; the native engine mirrors newton off)"
            )
        if eng == "lammps" and self.nve[0] != ["disc"]:
            raise InputError(
                f"{p}:{self.nve[1]}: LAMMPS `fix nve/sphere` without `disc` integrates spheres "
                "(I = 2/5 m r^2); a 2D disk deck needs `fix ID all nve/sphere disc`"
            )
        if eng == "lammps" and self.density_disc is None:
            raise InputError(
                f"{p}: `set group all density/disc RHO` is missing: LAMMPS read_data takes the "
                "density column as 3D (m = 4/3 pi r^3 rho) in this build"
            )
        if eng == "liggghts" and self.density_disc is not None:
            raise InputError(f"{p}:{self.density_disc[1]}: `set ... density/disc` is LAMMPS syntax")
        # contact law
        if self.law_style != eng:
            raise InputError(f"{p}:{self.pair_line}: the pair_style is {self.law_style} syntax in a {eng} deck")
        if eng == "liggghts":
            missing = [k for k in _LIG_LAW if k not in self.law_lig]
            if missing:
                raise InputError(
                    f"{p}: fix property/global {', '.join(missing)} missing: hooke/stiffness "
                    f"needs all of {', '.join(_LIG_LAW)}"
                )
            kn, kt, gn, gt, mu = (self.law_lig[k][0] for k in _LIG_LAW)
        else:
            if self.law_lig:
                _, (_, ln) = next(iter(self.law_lig.items()))
                raise InputError(f"{p}:{ln}: fix property/global is LIGGGHTS syntax in a LAMMPS deck")
            kn, kt, gn, gt, mu = self.law_lmp
        if kn <= 0:
            raise InputError(f"{p}:{self.pair_line}: the normal stiffness kn must be > 0, got {kn!r}")
        if self.deform is not None:
            units = self.deform.units or ("box" if eng == "liggghts" else "lattice")
            self.deform = dataclasses.replace(self.deform, units=units)
        if self.sorting:
            self.notes.append(
                "atom sorting is on (atom_modify sort not 0, or the default): the code "
                "reorders atoms, so its summation order differs from the native one; "
                "agreement only to round-off growth"
            )
        if eng == "liggghts" and self.lammps_thermo:
            kw, ln = next(iter(self.lammps_thermo.items()))
            raise InputError(
                f"{p}:{ln}: thermo keyword {kw!r}: LIGGGHTS 3.8.0 has no such keyword (thermo.cpp; it "
                "stops with 'Invalid keyword in thermo_style custom command'): use c_ID of a compute "
                "temp or pressure"
            )
        if self.thermo_float is None or not re.fullmatch(r"%\.1[5-7][eg]", self.thermo_float.split()[0]):
            self.notes.append(
                "thermo floats are not printed with %.17g (thermo_modify format float "
                "%.17g): the stress comparison is limited by the printed digits"
            )
        dumps = tuple(sorted([*self.dumps.values(), *self.undumped.values()], key=lambda d: d.line))
        for d in dumps:
            if d.style == "custom" and not d.sort_id:
                self.notes.append(f"dump {d.id}: rows are matched by id (no dump_modify sort id)")
        # data file
        name, ln = self.read_data
        data_path = Path(data) if data is not None else (Path(name) if Path(name).is_absolute() else p.parent / name)
        atoms = read_data_file(data_path, where=f"{p}:{ln}" if data is None else "--data")
        if eng == "lammps":
            rho = self.density_disc[0]
        else:
            dens = atoms["density"]
            if np.any(dens != dens[0]):
                i = int(np.flatnonzero(dens != dens[0])[0])
                raise InputError(
                    f"{data_path}: atom {int(atoms['ids'][i])} has density {dens[i]!r}, atom "
                    f"{int(atoms['ids'][0])} {dens[0]!r}: the native packing needs one density"
                )
            rho = float(dens[0])
        lo, hi = atoms["lo"], atoms["hi"]
        tilt = float(atoms["tilt"] or 0.0)
        sheared = self.triclinic is not None or atoms["tilt"] is not None
        self._check_shear(eng, sheared, atoms, data_path)
        cell = np.diag(hi - lo)
        if sheared:
            cell = np.array([[hi[0] - lo[0], tilt], [0.0, hi[1] - lo[1]]])
        packing = Packing(
            atoms["x"],
            0.5 * atoms["diameter"],
            cell,
            density=rho,
            metadata={"source": str(data_path), "box_lo": lo.tolist(), "box_hi": hi.tolist()},
        )
        kw = {"kn": kn, "kt": kt, "gamma_n": gn, "gamma_t": gt, "mu": mu, "dt": self.dt[0], "skin": self.skin[0]}
        fields = {f.name for f in dataclasses.fields(DEMSettings)}
        if eng == "lammps":
            if "flavour" in fields:
                kw["flavour"] = "lammps"
            else:
                self.notes.append(
                    "DEMSettings has no flavour='lammps' in this gransim: the native run uses "
                    "the LIGGGHTS arithmetic of the Hooke history law (agreement with LAMMPS "
                    "then only to the law's round-off differences)"
                )
        try:
            settings = DEMSettings(**kw)
        except InputError as exc:
            raise InputError(f"{p}: contact law or step: {exc}") from None
        nsteps = self.step
        local = next((d for d in dumps if d.style == "local"), None)
        if sheared and local is not None:
            raise InputError(
                f"{p}:{local.line}: dump local of contact rows in a sheared (triclinic) deck: the "
                "native rows are evaluated in the orthogonal cell only"
            )
        if sheared and len(self.runs) > 1:
            raise InputError(
                f"{p}:{self.runs[1].line}: a second `run` in a sheared (triclinic) deck: the "
                "sheared-cell replay runs one `run` (ShearEngine.start_run); split the deck"
            )
        shear = _shear_loading(self, p, tilt, lo, hi, settings.dt, nsteps) if sheared else None
        return ReplayDeck(
            engine=eng,
            path=p,
            data_path=data_path,
            data_name=name,
            packing=packing,
            box_lo=lo,
            box_hi=hi,
            ids=atoms["ids"],
            velocities=atoms["v"],
            spins=atoms["w"],
            settings=settings,
            deform=self.deform,
            nsteps=nsteps,
            thermo_every=self.runs[0].thermo_every,
            thermo_columns=self.runs[0].thermo_columns,
            thermo_float_format=self.thermo_float,
            pressure=dict(self.pressure),
            dumps=dumps,
            sorting=self.sorting,
            notes=tuple(self.notes),
            lines=tuple(text.splitlines()),
            tilt=tilt,
            sheared=sheared,
            shear=shear,
            runs=tuple(self.runs),
            computes=dict(self.computes),
            variables=dict(self.cmdline),
        )


def _shear_loading(st, path, tilt, lo, hi, dt, nsteps):
    """The :class:`~gransim.dem.sheared.ShearLoading` of a sheared deck, and its check.

    ShearEngine runs every ``xy`` style of the subset (erate, trate, vel, final, delta) in LAMMPS'
    arithmetic and ``fix deform N`` with any N, so the deck's style, number and N are passed as
    they are. A tilt beyond Lx/2 at the end of the run (LAMMPS would flip the box; ShearEngine
    stops) and a trate on a box without tilt (LAMMPS stops too) are refused naming the line.
    """
    d = st.deform
    if d is None or d.tilt is None:
        return ShearLoading(erate=0.0)
    style, value = d.tilt
    if style == "trate" and tilt == 0.0:
        raise InputError(
            f"{path}:{d.line}: fix deform xy trate on a box without tilt: the tilt grows as "
            "xy0 exp(rate t) (LAMMPS stops: 'Cannot use fix deform trate on a box with zero "
            "tilt'); give the data file a tilt or use xy erate"
        )
    delt = float(nsteps) * dt
    stop = tilt_stop(style, value, tilt, float(hi[1] - lo[1]), delt)
    lx = float(hi[0] - lo[0])
    if abs(stop) > 0.5 * lx:
        raise InputError(
            f"{path}:{d.line}: fix deform xy {style}: the tilt reaches {stop!r} m, beyond Lx/2 = "
            f"{0.5 * lx!r} m, where LAMMPS flips the box; ShearEngine does not flip (shorten "
            "the run or the rate)"
        )
    return ShearLoading(xy=style, value=value, every=d.every)


# ------------------------------------------------------------------------------ data file
_HEADER = re.compile(r"^\s*(\S+)\s+(\S+)\s+(xlo xhi|ylo yhi|zlo zhi)\s*$")


def read_data_file(path, where: str = "read_data") -> dict:
    """Read a ``atom_style sphere`` data file: header (atoms, atom types, xlo xhi, ylo yhi,
    zlo zhi), ``Atoms`` (id type diameter density x y z [ix iy iz]) and optional
    ``Velocities`` (id vx vy vz wx wy wz); a triclinic header line ``XY 0 0 xy xz yz``.

    Returns a dict of ``ids`` (N,) int64, ``diameter``, ``density`` (N,), ``x`` (N, 2), ``v``
    (N, 2), ``w`` (N,) (spin about z), ``lo``, ``hi`` (2,) in file order, ``tilt`` (the xy tilt,
    m, or None without the line). Positions outside an orthogonal box are wrapped once as the
    codes' ``Domain::remap`` does (x < lo: + L; x >= hi: - L); those of a tilted box must lie in it.

    Raises InputError naming the file and the line.
    """
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: cannot read the data file {path} ({exc})") from None

    def bad(n, msg):
        return InputError(f"{path}:{n}: {msg}")

    natoms = ntypes = None
    box = {}
    k = 1  # first line is a title
    sections = {}
    while k < len(lines):
        s = lines[k].split("#")[0].strip()
        n = k + 1
        k += 1
        if not s:
            continue
        m = _HEADER.match(s)
        if m:
            a = _float(lambda _n, msg, n=n: bad(n, msg), n, m.group(1), m.group(3).split()[0])
            b = _float(lambda _n, msg, n=n: bad(n, msg), n, m.group(2), m.group(3).split()[1])
            if not b > a:
                raise bad(n, f"{m.group(3)}: expected lo < hi, got {m.group(1)} {m.group(2)}")
            box[m.group(3)[0]] = (a, b)
            continue
        w = s.split()
        if len(w) == 2 and w[1] == "atoms":
            natoms = _int(lambda _n, msg, n=n: bad(n, msg), n, w[0], "atoms", minimum=2)
            continue
        if len(w) == 3 and w[1:] == ["atom", "types"]:
            ntypes = _int(lambda _n, msg, n=n: bad(n, msg), n, w[0], "atom types", minimum=1)
            if ntypes != 1:
                raise bad(n, f"{ntypes} atom types: the subset has one atom type (one set of coefficients)")
            continue
        if len(w) == 6 and w[3:] == ["xy", "xz", "yz"]:
            e = lambda _n, msg, n=n: bad(n, msg)
            t = [_float(e, n, v, name) for v, name in zip(w[:3], ("xy", "xz", "yz"))]
            if t[1] != 0.0 or t[2] != 0.0:
                raise bad(n, f"xz = {w[1]}, yz = {w[2]}: a 2D triclinic box has only an xy tilt (xz = yz = 0)")
            box["tilt"] = t[0]
            continue
        if w[:1] == ["xy"] or w[-3:] == ["xy", "xz", "yz"]:
            raise bad(n, f"tilt line {s!r}: expected `XY XZ YZ xy xz yz`")
        if w[0] in ("Atoms", "Velocities"):
            if w[0] in sections:
                raise bad(n, f"section {w[0]} given twice")
            if natoms is None:
                raise bad(n, f"section {w[0]} before the `N atoms` header line")
            rows = []
            while k < len(lines) and not lines[k].strip():
                k += 1
            while k < len(lines) and len(rows) < natoms:
                t = lines[k].split("#")[0].strip()
                if t:
                    rows.append((k + 1, t.split()))
                k += 1
            if len(rows) < natoms:
                raise bad(n, f"section {w[0]}: expected {natoms} rows, got {len(rows)}")
            sections[w[0]] = rows
            continue
        raise bad(
            n,
            f"unsupported data file line {s!r} (supported: atoms, atom types, xlo xhi, ylo yhi, "
            "zlo zhi, Atoms, Velocities)",
        )
    if natoms is None:
        raise InputError(f"{path}: no `N atoms` header line")
    for ax in "xyz":
        if ax not in box:
            raise InputError(f"{path}: no `{ax}lo {ax}hi` header line")
    if "Atoms" not in sections:
        raise InputError(f"{path}: no Atoms section")
    ids = np.empty(natoms, np.int64)
    diam = np.empty(natoms)
    dens = np.empty(natoms)
    x = np.empty((natoms, 2))
    for i, (n, w) in enumerate(sections["Atoms"]):
        if len(w) not in (7, 10):
            raise bad(
                n,
                "Atoms row: expected `id type diameter density x y z [ix iy iz]` "
                "(atom_style sphere), "
                f"got {len(w)} fields",
            )
        e = lambda _n, msg, n=n: bad(n, msg)
        ids[i] = _int(e, n, w[0], "atom id", minimum=1)
        _int(e, n, w[1], "atom type", minimum=1)
        if w[1] != "1":
            raise bad(n, f"atom type {w[1]}: the subset has one atom type")
        diam[i] = _float(e, n, w[2], "diameter")
        dens[i] = _float(e, n, w[3], "density")
        if diam[i] <= 0 or dens[i] <= 0:
            raise bad(n, f"atom {w[0]}: diameter and density must be > 0, got {w[2]}, {w[3]}")
        x[i, 0] = _float(e, n, w[4], "x")
        x[i, 1] = _float(e, n, w[5], "y")
        if _float(e, n, w[6], "z") != 0.0:
            raise bad(n, f"atom {w[0]}: z = {w[6]}; a 2D deck needs z = 0")
    if len(set(ids.tolist())) != natoms:
        raise InputError(f"{path}: atom ids are not unique")
    lo = np.array([box["x"][0], box["y"][0]])
    hi = np.array([box["x"][1], box["y"][1]])
    tilt = box.get("tilt")
    if tilt:
        # a tilted box: LAMMPS wraps in lamda coordinates; the replay takes atoms inside the box
        Lx, Ly = hi[0] - lo[0], hi[1] - lo[1]
        ly = (x[:, 1] - lo[1]) / Ly
        lx = (x[:, 0] - lo[0] - tilt * ly) / Lx
        out = (lx < 0) | (lx >= 1) | (ly < 0) | (ly >= 1)
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            raise InputError(
                f"{path}: atom {int(ids[i])} at {x[i].tolist()} lies outside the tilted box; "
                "the replay needs the atoms of a triclinic data file inside the box"
            )
    for d in range(2 if not tilt else 0):
        L = hi[d] - lo[d]
        c = x[:, d]
        c[c < lo[d]] += L
        over = c >= hi[d]
        c[over] -= L
        c[over] = np.maximum(c[over], lo[d])
        out = (c < lo[d]) | (c >= hi[d])
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            raise InputError(
                f"{path}: atom {int(ids[i])} lies more than one box length outside the box ({'xy'[d]} = {x[i, d]!r})"
            )
    v = np.zeros((natoms, 2))
    wz = np.zeros(natoms)
    if "Velocities" in sections:
        index = {int(a): i for i, a in enumerate(ids)}
        for n, w in sections["Velocities"]:
            if len(w) != 7:
                raise bad(n, f"Velocities row: expected `id vx vy vz wx wy wz`, got {len(w)} fields")
            e = lambda _n, msg, n=n: bad(n, msg)
            a = _int(e, n, w[0], "atom id", minimum=1)
            if a not in index:
                raise bad(n, f"Velocities row of atom {a}, which is not in the Atoms section")
            i = index[a]
            v[i] = [_float(e, n, w[1], "vx"), _float(e, n, w[2], "vy")]
            wz[i] = _float(e, n, w[6], "wz")
    return {"ids": ids, "diameter": diam, "density": dens, "x": x, "v": v, "w": wz, "lo": lo, "hi": hi, "tilt": tilt}
