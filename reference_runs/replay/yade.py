"""Replay a YADE script of the supported shape: in YADE and natively in YADE's arithmetic, compared
frame by frame, bit for bit.

The supported shape is the script :mod:`reference_runs.yade.dem` runs
(:data:`reference_runs.yade.dem_script.DEM_SCRIPT` with its ``input.json``) and a user's script of
the same form (docs/replay.md, "YADE scripts"). The script is read with :mod:`ast`, never executed
in this interpreter: its top-level statements, in order, are

* imports: ``import json``, ``import math``, ``from yade import utils`` (no others);
* parameters anywhere between the statements below: ``NAME = EXPR`` (or a tuple of names), EXPR
  made of literals, names assigned before, ``job["key"]`` subscripts, ``+ - * / **``, ``float``,
  ``int``, ``len``, ``list``, ``tuple``, ``abs``, ``math.pi`` and ``math.atan|tan|sqrt|...``, list
  comprehensions; ``with open("FILE") as fh: NAME = json.load(fh)`` (a JSON file next to the
  script: the packing, the law, the run; the job gets a copy). They are evaluated here in Python's
  own float arithmetic, as YADE's interpreter evaluates them;
* ``O.periodic = True``; ``O.cell.hSize = Matrix3(Lx, 0, 0, 0, Ly, 0, 0, 0, z)`` (an orthogonal
  cell);
* ``mat = O.materials.append(FrictMat(young=.., poisson=.., frictionAngle=PHI, density=..))``;
* the body loop ``for (x, y), r, (vx, vy), w in zip(POSITIONS, RADII, VELOCITIES, SPINS):`` (or
  ``for (x, y), r in zip(POSITIONS, RADII):`` without initial velocities) whose body is the
  template's: ``m = RHO * math.pi * r * r``, ``b = utils.sphere((x, y, 0.0), r, material=mat)``,
  ``blockedDOFs = "zXY"``, mass ``m``, inertia ``(0.5 * m * r * r,) * 3``, ``vel``, ``angVel``,
  ``O.bodies.append(b)`` (the 2D mass and inertia the native arithmetic computes);
* ``out = open("FILE", "w")`` and the recorder and loading hook ``g``, ``put``, ``axis_rate``,
  ``control`` exactly as gransim writes them (the output format of
  :mod:`reference_runs.yade.dem_script`; the loading is the ``load`` dict: each diagonal axis
  ``fixed``, ``rate`` (``c``) or ``servo`` (``k``, ``target``), ``xy_erate``);
* ``O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]), InteractionLoop(
  [Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=False)], [Ip2_FrictMat_FrictMat_FrictPhys(
  kn=MatchMaker(algo="val", val=KN), ks=MatchMaker(algo="val", val=KS))],
  [Law2_ScGeom_FrictPhys_CundallStrack()]), PyRunner(command="control()", iterPeriod=1,
  initRun=True), NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, 0.0))]``;
* ``O.dt = DT``, the header ``put``, ``for _ in range(n_steps + 1): O.step()``, ``put("END",
  n_steps)``, ``out.close()``.

Anything else is refused with an :class:`~gransim.errors.InputError` naming the line: another
law, damping != 0, clumps, threads, engines in another order or with other arguments, another
recorder, any other statement. What the native arithmetic cannot take is refused the same way (a
sheared start cell, centres outside the cell, a shear with an x loading, a rate or a servo gain
that no native parameter reproduces to the bit).

:func:`replay_yade` runs the script in YADE through :func:`reference_runs.yade.job.run_yade_job`
(quiet module, own process group, timeout, private TMPDIR, nothing listening; the output's
completeness is the job's evidence) or reads a finished job directory, runs it natively with
:func:`gransim.dem.yade_arithmetic.yade_run`, and compares every thermo row and every frame bit
for bit (tolerance 0). A missing step, frame, particle or contact is a failure named
``incomplete``.
"""

from __future__ import annotations

import ast
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gransim.dem.settings import AxisControl, DEMSettings, Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_h5
from reference_runs.errors import ReferenceRunError
from reference_runs.yade.dem import YadeDemOutput, read_yade_dem
from reference_runs.yade.dem_script import DEM_SCRIPT
from reference_runs.yade.job import run_yade_job

from .compare import Check, ReplayResult, write_text_reports

ENGINE = "yade"
#: the scripts' law, the one the native yade arithmetic has
LAW = "Law2_ScGeom_FrictPhys_CundallStrack"
_ENGINES = ("ForceResetter", "InsertionSortCollider", "InteractionLoop", "PyRunner", "NewtonIntegrator")
_IMPORTS = {"import json", "import math", "from yade import utils"}
#: names a parameter statement may not rebind (YADE's, the modules', the recorder's, the builtins used)
_RESERVED = {
    "O", "math", "json", "utils", "out", "mat", "g", "put", "axis_rate", "control", "Matrix3", "Vector3",
    "float", "int", "len", "list", "tuple", "abs", "zip", "range", "open", "repr", "str", "print",
}  # fmt: skip
_MATH = {"atan": math.atan, "tan": math.tan, "sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "exp": math.exp}
_CALLS = {"float": float, "int": int, "len": len, "list": list, "tuple": tuple, "abs": abs}
_MAX_ITEMS = 10_000_000
#: files of a YADE job directory (reference_runs.yade.job): neither an input nor the output may take their names
_JOB_FILES = {"yade_job.py", "gransim_yade_quiet.py", "manifest.json", "stdout.txt", "stderr.txt", ".lock"}


def _plain(name) -> bool:
    """A plain file name (no directory) that is not one of the job's own files."""
    return isinstance(name, str) and Path(name).name == name and name not in ("", ".", "..") and name not in _JOB_FILES


def _template():
    tree = ast.parse(DEM_SCRIPT)
    defs = {s.name: s for s in tree.body if isinstance(s, ast.FunctionDef)}
    loop = next(s for s in tree.body if isinstance(s, ast.For) and isinstance(s.iter, ast.Call))
    tail = [s for s in tree.body if s.lineno > next(s.lineno for s in tree.body if _is_set(s, "O.dt"))]
    return defs, loop, tail


def _dump(node) -> str:
    return ast.dump(node, annotate_fields=False)


def _src(node) -> str:
    return ast.unparse(node)


def _first_diff(mine, tmpl):
    """The first statement of ``mine`` (a compound statement) that differs from ``tmpl``'s."""
    a, b = getattr(mine, "body", []), getattr(tmpl, "body", [])
    for x, y in zip(a, b):
        if _dump(x) != _dump(y):
            return _first_diff(x, y) if type(x) is type(y) and hasattr(x, "body") else x
    return a[len(b)] if len(a) > len(b) else mine


def _is_set(stmt, target: str) -> bool:
    return isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and _src(stmt.targets[0]) == target


@dataclass(frozen=True, eq=False)
class YadeScript:
    """A YADE script read into the native run's inputs.

    Attributes
    ----------
    path : the script. text : its text. packing : the disks as YADE gets them (positions (N, 2) m,
    radii (N,) m, cell (2, 2) m, density kg/m^2). settings : kn, kt (N/m), mu (tan(mu) as YADE's
    FrictPhys has it), dt (s); undamped. loading : :class:`Loading` or :class:`ShearLoading`.
    nsteps, thermo_every, dump_every : the run and its output periods. velocities (N, 2) m/s,
    spins (N,) rad/s : initial. z : YADE's cell z size (m). files : {name: path} the JSON files the
    script reads. output : the output file's name. lines : the script's lines. notes : remarks.
    """

    path: Path
    text: str
    packing: Packing
    settings: DEMSettings
    loading: object
    nsteps: int
    thermo_every: int
    dump_every: int
    velocities: np.ndarray
    spins: np.ndarray
    z: float
    files: dict
    output: str
    lines: list
    notes: list = field(default_factory=list)
    engine: str = ENGINE

    @property
    def expect(self) -> dict:
        """The counts the output's header must carry."""
        return {
            "n_particles": self.packing.n,
            "n_steps": self.nsteps,
            "thermo_every": self.thermo_every,
            "dump_every": self.dump_every,
        }


class _Reader:
    """One pass over the script's top-level statements (module doc)."""

    SLOTS = ("periodic", "hsize", "material", "bodies", "output", "g", "put", "axis_rate", "control")
    SLOTS += ("engines", "dt", "header", "steps", "end", "close")

    def __init__(self, path: Path, text: str):
        self.path, self.text = path, text
        self.env: dict = {}
        self.lines_of: dict = {}  # name -> line of its last assignment
        self.imports: set = set()
        self.files: dict = {}
        self.got: dict = {}  # slot -> value
        self.where: dict = {}  # slot -> line
        self.defs, self.loop, self.tail = _template()

    # ------------------------------------------------------------------ messages
    def bad(self, node, msg) -> InputError:
        line = getattr(node, "lineno", 0)
        text = self.text.splitlines()[line - 1].strip() if 0 < line <= len(self.text.splitlines()) else ""
        return InputError(f"{self.path}: line {line}: {text!r}: {msg}")

    # ------------------------------------------------------------------ expressions
    def ev(self, node):
        """The value of an expression of the parameter subset (module doc), in Python's arithmetic."""
        e = self.ev
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool, type(None))):
            return node.value
        if isinstance(node, ast.Name):
            if node.id not in self.env:
                raise self.bad(
                    node, f"{node.id!r} is not a parameter assigned above (module reference_runs.replay.yade)"
                )
            return self.env[node.id]
        if isinstance(node, ast.Attribute) and _src(node) == "math.pi":
            self.need("import math", node)
            return math.pi
        if isinstance(node, (ast.List, ast.Tuple)):
            items = [e(x) for x in node.elts]
            return items if isinstance(node, ast.List) else tuple(items)
        if isinstance(node, ast.Dict) and None not in node.keys:
            return {e(k): e(v) for k, v in zip(node.keys, node.values)}
        if isinstance(node, ast.Subscript):
            base, key = e(node.value), e(node.slice)
            try:
                return base[key]
            except (KeyError, IndexError, TypeError) as exc:
                raise self.bad(node, f"{_src(node)}: {type(exc).__name__} {exc}") from None
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = e(node.operand)
            return -v if isinstance(node.op, ast.USub) else +v
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)):
            a, b = e(node.left), e(node.right)
            if isinstance(node.op, ast.Mult) and isinstance(a, (list, tuple)) and isinstance(b, int):
                if len(a) * b > _MAX_ITEMS:
                    raise self.bad(node, "a sequence of more than 1e7 items")
            if isinstance(node.op, ast.Pow) and isinstance(b, (int, float)) and abs(b) > 1024:
                raise self.bad(node, "an exponent beyond 1024")
            try:
                return {
                    ast.Add: lambda: a + b,
                    ast.Sub: lambda: a - b,
                    ast.Mult: lambda: a * b,
                    ast.Div: lambda: a / b,
                    ast.Pow: lambda: a**b,
                }[type(node.op)]()
            except (TypeError, ZeroDivisionError, OverflowError) as exc:
                raise self.bad(node, f"{_src(node)}: {exc}") from None
        if isinstance(node, ast.Call) and not node.keywords:
            f = node.func
            fn = None
            if isinstance(f, ast.Name) and f.id in _CALLS:
                fn = _CALLS[f.id]
            elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "math":
                fn = _MATH.get(f.attr)
                self.need("import math", node)
            if fn is not None:
                try:
                    return fn(*[e(a) for a in node.args])
                except (TypeError, ValueError, OverflowError) as exc:
                    raise self.bad(node, f"{_src(node)}: {exc}") from None
        if isinstance(node, ast.ListComp) and len(node.generators) == 1:
            gen = node.generators[0]
            if not gen.ifs and not gen.is_async:
                seq = e(gen.iter)
                out = []
                saved = dict(self.env)
                try:
                    for item in seq:
                        self.bind(gen.target, item, node)
                        out.append(e(node.elt))
                finally:
                    self.env = saved
                return out
        raise self.bad(node, f"{_src(node)!r} is not a literal parameter expression of the supported shape")

    def bind(self, target, value, node):
        if isinstance(target, ast.Name):
            if target.id in _RESERVED:
                raise self.bad(node, f"{target.id!r} is YADE's, a module's or the recorder's name: not a parameter")
            self.env[target.id] = value
            self.lines_of[target.id] = node.lineno
            return
        if isinstance(target, (ast.Tuple, ast.List)):
            try:
                items = list(value)
            except TypeError:
                raise self.bad(node, f"cannot unpack {type(value).__name__}") from None
            if len(items) != len(target.elts):
                raise self.bad(node, f"{len(items)} values for {len(target.elts)} names")
            for t, v in zip(target.elts, items):
                self.bind(t, v, node)
            return
        raise self.bad(node, f"assignment to {_src(target)}: not a parameter of the supported shape")

    def need(self, imp, node):
        if imp not in self.imports:
            raise self.bad(node, f"uses a module the script does not import ({imp!r} missing above)")

    def number(self, node, what, positive=False, zero=True) -> float:
        v = self.ev(node)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.bad(node, f"{what}: expected a finite number, got {v!r}")
        if positive and not (v > 0 or (zero and v == 0)):
            raise self.bad(node, f"{what}: expected a number {'>= 0' if zero else '> 0'}, got {v!r}")
        return float(v)

    # ------------------------------------------------------------------ statements
    def slot(self, name, stmt, value=True):
        i = self.SLOTS.index(name)
        done = [s for s in self.SLOTS if s in self.got]
        if name in self.got:
            raise self.bad(stmt, f"a second {name!r} statement (the first is at line {self.where[name]})")
        later = [s for s in done if self.SLOTS.index(s) > i]
        if later:
            raise self.bad(
                stmt,
                f"out of order: the supported shape has {name!r} before {later[0]!r} (line {self.where[later[0]]})",
            )
        self.got[name], self.where[name] = value, stmt.lineno

    def read(self):
        try:
            tree = ast.parse(self.text, filename=str(self.path))
        except SyntaxError as exc:
            raise InputError(f"{self.path}: line {exc.lineno}: not valid Python: {exc.msg}") from None
        for k, stmt in enumerate(tree.body):
            self.statement(stmt, docstring=k == 0)
        missing = [s for s in self.SLOTS if s not in self.got]
        if missing:
            raise InputError(
                f"{self.path}: the script has no {missing[0]!r} statement of the supported shape "
                "(docs/replay.md, 'YADE scripts')"
            )
        return self

    def statement(self, s, docstring=False):  # noqa: C901, PLR0912 - one branch per statement of the shape
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant) and isinstance(s.value.value, str):
            return  # a docstring or a bare string
        if isinstance(s, (ast.Import, ast.ImportFrom)):
            src = _src(s)
            if src not in _IMPORTS:
                raise self.bad(s, f"an import outside the supported shape (only {', '.join(sorted(_IMPORTS))})")
            self.imports.add(src)
            return
        if _is_set(s, "O.periodic"):
            if not (isinstance(s.value, ast.Constant) and s.value.value is True):
                raise self.bad(s, "the supported shape is a periodic scene (O.periodic = True)")
            return self.slot("periodic", s)
        if _is_set(s, "O.cell.hSize"):
            return self.hsize(s)
        if _is_set(s, "mat"):
            return self.material(s)
        if isinstance(s, ast.For) and isinstance(s.iter, ast.Call) and _src(s.iter.func) == "zip":
            return self.bodies(s)
        if _is_set(s, "out"):
            v = s.value
            if not (_src(v.func) == "open" if isinstance(v, ast.Call) else False) or len(v.args) != 2:
                raise self.bad(s, 'the output is opened as out = open("FILE", "w")')
            name, mode = self.ev(v.args[0]), self.ev(v.args[1])
            if mode != "w" or not _plain(name) or name in self.files:
                raise self.bad(
                    s,
                    'the output is opened as out = open("FILE", "w") with a plain file name, not an input file or '
                    f"one of the job's own files ({', '.join(sorted(_JOB_FILES))})",
                )
            return self.slot("output", s, name)
        if isinstance(s, ast.FunctionDef):
            return self.function(s)
        if _is_set(s, "O.engines"):
            return self.engines(s)
        if _is_set(s, "O.dt"):
            return self.slot("dt", s, self.number(s.value, "O.dt", positive=True, zero=False))
        param = isinstance(s, ast.With) or (
            isinstance(s, ast.Assign) and len(s.targets) == 1 and not _src(s.targets[0]).startswith("O.")
        )
        if param and "header" in self.got:
            raise self.bad(s, "a parameter after the run has started (the supported shape sets them before O.engines)")
        if isinstance(s, ast.With):
            return self.json_file(s)
        if param:
            return self.bind(s.targets[0], self.ev(s.value), s)
        for name, tmpl in zip(("header", "steps", "end", "close"), self.tail):
            if _dump(s) == _dump(tmpl):
                return self.slot(name, s)
        raise self.bad(s, self.why(s))

    def why(self, s) -> str:
        src = _src(s)
        low = src.lower()
        if "clump" in low:
            return "clumps are not in the supported shape (the native yade arithmetic has spheres only)"
        if "thread" in low or "omp_" in low:
            return "several threads are not in the supported shape (the job runs yade -j1, one thread)"
        if "O.engines" in src:
            return "the engine list is set once, as a whole, in the supported shape (O.engines = [...])"
        if "O.bodies" in src:
            return "bodies are appended only by the body loop of the supported shape"
        return "a statement outside the supported shape of a YADE script (docs/replay.md, 'YADE scripts')"

    def json_file(self, s):
        items = s.items
        ok = (
            len(items) == 1
            and isinstance(items[0].context_expr, ast.Call)
            and _src(items[0].context_expr.func) == "open"
            and len(items[0].context_expr.args) == 1
            and not items[0].context_expr.keywords
            and isinstance(items[0].optional_vars, ast.Name)
            and len(s.body) == 1
            and isinstance(s.body[0], ast.Assign)
            and len(s.body[0].targets) == 1
            and _src(s.body[0].value) == f"json.load({items[0].optional_vars.id})"
        )
        if not ok:
            raise self.bad(
                s,
                'a with-statement of the supported shape reads one JSON file: with open("FILE") as fh: '
                "NAME = json.load(fh)",
            )
        self.need("import json", s)
        name = self.ev(items[0].context_expr.args[0])
        if not _plain(name):
            raise self.bad(
                s,
                "the JSON file must be a plain file name next to the script (the job runs in its own directory), "
                f"not one of the job's own files ({', '.join(sorted(_JOB_FILES))})",
            )
        p = self.path.parent / name
        try:
            data = json.loads(p.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise self.bad(s, f"cannot read the JSON file {str(p)!r}: {exc}") from None
        self.files[name] = p
        self.bind(s.body[0].targets[0], data, s.body[0])

    def hsize(self, s):
        v = s.value
        if not (isinstance(v, ast.Call) and _src(v.func) == "Matrix3" and len(v.args) == 9 and not v.keywords):
            raise self.bad(s, "the cell is set as O.cell.hSize = Matrix3(9 numbers)")
        h = [self.number(a, "O.cell.hSize") for a in v.args]
        if any(h[i] != 0.0 for i in (1, 2, 3, 5, 6, 7)):
            raise self.bad(
                s,
                "the supported shape starts from an orthogonal cell, Matrix3(Lx, 0, 0, 0, Ly, 0, 0, 0, z) "
                "(the native yade arithmetic starts untilted; shear comes from xy_erate)",
            )
        if not (h[0] > 0 and h[4] > 0 and h[8] > 0):
            raise self.bad(s, "the cell's sides must be > 0")
        self.slot("hsize", s, (h[0], h[4], h[8]))

    def material(self, s):
        v = s.value
        ok = isinstance(v, ast.Call) and _src(v.func) == "O.materials.append" and len(v.args) == 1
        fm = v.args[0] if ok else None
        if not (ok and isinstance(fm, ast.Call) and _src(fm.func) == "FrictMat" and not fm.args):
            raise self.bad(
                s, f"the material is mat = O.materials.append(FrictMat(...)) (FrictMat: the law {LAW} needs FrictPhys)"
            )
        kw = {k.arg: k.value for k in fm.keywords}
        extra = set(kw) - {"young", "poisson", "frictionAngle", "density", "label"}
        if extra or "frictionAngle" not in kw:
            raise self.bad(
                s,
                "FrictMat takes young, poisson, frictionAngle, density (kn and ks come from MatchMaker; "
                f"masses are set by hand), got {sorted(kw)}",
            )
        for k in ("young", "poisson", "density"):
            if k in kw:
                self.number(kw[k], f"FrictMat {k}")
        phi = self.number(kw["frictionAngle"], "frictionAngle", positive=True)
        self.slot("material", s, phi)

    def bodies(self, s):
        tmpl = self.loop
        full = _dump(s.target) == _dump(tmpl.target)
        short = _src(s.target) == "((x, y), r)"
        if not (full or short) or s.orelse or s.iter.keywords or len(s.iter.args) != (4 if full else 2):
            raise self.bad(
                s,
                "the body loop of the supported shape is for (x, y), r, (vx, vy), w in zip(POSITIONS, "
                "RADII, VELOCITIES, SPINS): (or for (x, y), r in zip(POSITIONS, RADII):)",
            )
        want = [t for t in tmpl.body if full or not (_src(t).startswith(("b.state.vel", "b.state.angVel")))]
        if len(s.body) != len(want):
            bad = s.body[min(len(s.body), len(want)) - 1] if s.body else s
            raise self.bad(
                bad,
                f"the body loop has {len(s.body)} statements, the supported shape {len(want)}: "
                + "; ".join(_src(t) for t in want),
            )
        rho = None
        for mine, t in zip(s.body, want):
            if _src(t).startswith("m = rho"):
                # m = RHO * math.pi * r * r: ((RHO * math.pi) * r) * r, the native arithmetic's order
                e = mine.value if isinstance(mine, ast.Assign) and _src(mine.targets[0]) == "m" else None
                ok = all(
                    isinstance(x, ast.BinOp)
                    for x in (
                        e,
                        getattr(e, "left", None),
                        getattr(e, "left", e).left if isinstance(getattr(e, "left", None), ast.BinOp) else None,
                    )
                )
                ok = ok and _src(e) == f"{_src(e.left.left.left)} * math.pi * r * r"
                if not ok:
                    raise self.bad(
                        mine,
                        "the 2D mass is m = RHO * math.pi * r * r in the supported shape (the native "
                        "arithmetic's order of the products)",
                    )
                self.need("import math", mine)
                rho = self.number(e.left.left.left, "density RHO", positive=True, zero=False)
                continue
            if _dump(mine) != _dump(t):
                raise self.bad(mine, f"the body loop of the supported shape has {_src(t)!r} here")
        self.need("from yade import utils", s)
        if "material" not in self.got:
            raise self.bad(s, "the body loop uses mat before the material statement")
        cols = [self.ev(a) for a in s.iter.args]
        try:
            arrs = [np.asarray(c, dtype=float) for c in cols]
        except (TypeError, ValueError) as exc:
            raise self.bad(s, f"the loop's lists are not numbers: {exc}") from None
        n = arrs[1].shape[0] if arrs[1].ndim == 1 else -1
        shapes = [(n, 2), (n,), (n, 2), (n,)][: len(arrs)]
        if n < 2 or any(a.shape != sh for a, sh in zip(arrs, shapes)):
            raise self.bad(
                s,
                f"zip of {[a.shape for a in arrs]}: expected positions (N, 2), radii (N,)"
                + (", velocities (N, 2), spins (N,)" if full else "")
                + ", N >= 2",
            )
        if not all(np.all(np.isfinite(a)) for a in arrs) or np.any(arrs[1] <= 0):
            raise self.bad(s, "the loop's numbers must be finite and the radii > 0")
        vel = arrs[2] if full else np.zeros((n, 2))
        spin = arrs[3] if full else np.zeros(n)
        self.slot("bodies", s, (arrs[0], arrs[1], vel, spin, rho))

    def function(self, s):
        t = self.defs.get(s.name)
        if t is None:
            raise self.bad(
                s,
                f"def {s.name}: the supported shape defines only {', '.join(self.defs)} (the recorder "
                "and loading hook gransim writes)",
            )
        if _dump(s) != _dump(t):
            raise self.bad(
                _first_diff(s, t),
                f"def {s.name} differs from the recorder gransim writes (reference_runs/yade/"
                "dem_script.py): the supported shape keeps it unchanged",
            )
        self.slot(s.name, s)

    def engines(self, s):
        v = s.value
        if not isinstance(v, ast.List):
            raise self.bad(s, "O.engines is a literal list of the supported shape")
        for e in v.elts:
            if not isinstance(e, ast.Call):
                raise self.bad(e, f"{_src(e)}: the supported shape lists engine instances, Engine(...)")
        names = [_src(e.func) for e in v.elts]
        for e, name in zip(v.elts, names):
            if name not in _ENGINES:
                msg = f"engine {name} is not in the supported shape ({', '.join(_ENGINES)})"
                raise self.bad(e, msg)
        if tuple(names) != _ENGINES:
            k = next((i for i, (a, b) in enumerate(zip(names, _ENGINES)) if a != b), min(len(names), len(_ENGINES)))
            node = v.elts[k] if k < len(v.elts) else s
            raise self.bad(
                node,
                f"engines in another order or number: {', '.join(names)}; the supported shape runs "
                f"{', '.join(_ENGINES)} (YADE's iteration order, which the native arithmetic follows)",
            )
        tv = next(t for t in ast.parse(DEM_SCRIPT).body if _is_set(t, "O.engines")).value
        fr, isc, loop, runner, newton = v.elts
        for mine, t in ((fr, tv.elts[0]), (isc, tv.elts[1]), (runner, tv.elts[3])):
            if _dump(mine) != _dump(t):
                raise self.bad(
                    mine,
                    f"the supported shape has {_src(t)} here (the native arithmetic's collider "
                    "defaults and the recorder called every step)",
                )
        ig, ip, law = (loop.args + [None, None, None])[:3]
        if len(loop.args) != 3 or loop.keywords:
            raise self.bad(loop, "InteractionLoop takes three lists: geometry, physics, law")
        for mine, t in ((ig, tv.elts[2].args[0]),):
            if _dump(mine) != _dump(t):
                raise self.bad(mine, f"the supported shape has {_src(t)} (the relative velocity at the contact point)")
        if _dump(law) != _dump(tv.elts[2].args[2]):
            got = ", ".join(_src(e.func) if isinstance(e, ast.Call) else _src(e) for e in getattr(law, "elts", [law]))
            raise self.bad(
                law, f"another law ({got}): the supported shape runs [{LAW}()], the native yade arithmetic's"
            )
        ok = isinstance(ip, ast.List) and len(ip.elts) == 1 and isinstance(ip.elts[0], ast.Call)
        c = ip.elts[0] if ok else None
        ok = ok and _src(c.func) == "Ip2_FrictMat_FrictMat_FrictPhys" and not c.args
        kw = {k.arg: k.value for k in c.keywords} if ok else {}
        ok = ok and set(kw) == {"kn", "ks"}
        vals = {}
        for k in ("kn", "ks"):
            m = kw.get(k)
            if not (ok and isinstance(m, ast.Call) and _src(m.func) == "MatchMaker" and not m.args):
                ok = False
                break
            mk = {a.arg: a.value for a in m.keywords}
            if set(mk) != {"algo", "val"} or self.ev(mk["algo"]) != "val":
                ok = False
                break
            vals[k] = self.number(mk["val"], f"{k} MatchMaker val", positive=True, zero=k == "ks")
        if not ok:
            raise self.bad(
                ip,
                "the physics is [Ip2_FrictMat_FrictMat_FrictPhys(kn=MatchMaker(algo='val', val=KN), "
                "ks=MatchMaker(algo='val', val=KS))] (constant stiffnesses)",
            )
        nk = {k.arg: k.value for k in newton.keywords}
        if newton.args or set(nk) - {"damping", "gravity"}:
            raise self.bad(newton, "NewtonIntegrator takes damping=0 and gravity=(0, 0, 0) in the supported shape")
        damping = self.number(nk["damping"], "damping") if "damping" in nk else 0.2
        if damping != 0.0:
            raise self.bad(
                newton,
                f"damping {damping!r}"
                + (" (YADE's default, NewtonIntegrator.hpp:72)" if "damping" not in nk else "")
                + ": Cundall's non-viscous damping is not in the native yade arithmetic; the supported "
                "shape has NewtonIntegrator(damping=0)",
            )
        if "gravity" in nk:
            gv = self.ev(nk["gravity"])
            if not (isinstance(gv, (list, tuple)) and len(gv) == 3 and all(x == 0 for x in gv)):
                raise self.bad(newton, f"gravity {gv!r}: the supported shape has none")
        self.slot("engines", s, vals)

    # ------------------------------------------------------------------ the run
    def script(self) -> YadeScript:  # noqa: PLR0912 - each global the recorder reads is checked
        env, g = self.env, self.got
        lx, ly, z = g["hsize"]
        pos, radii, vel, spin, rho = g["bodies"]
        dt = g["dt"]
        line = self.lines_of

        def glob(name, kind):
            if name not in env:
                raise InputError(f"{self.path}: the recorder reads {name!r}, which the script never assigns")
            v = env[name]
            if kind is int and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
                raise InputError(f"{self.path}: line {line[name]}: {name} = {v!r}: expected an integer >= 1")
            if kind is float and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
                raise InputError(f"{self.path}: line {line[name]}: {name} = {v!r}: expected a number")
            return v

        nsteps, te, de = glob("n_steps", int), glob("thermo_every", int), glob("dump_every", int)
        if glob("n", int) != len(radii):
            raise InputError(
                f"{self.path}: line {line['n']}: n = {env['n']!r}, the loop appends {len(radii)} bodies "
                "(the recorder writes n as the frame's particle count)"
            )
        if float(glob("dt", float)) != dt:
            raise InputError(
                f"{self.path}: line {line['dt']}: dt = {env['dt']!r} differs from O.dt = {dt!r} (line "
                f"{self.where['dt']}); the loading hook divides by dt"
            )
        if float(glob("z", float)) != z:
            raise InputError(
                f"{self.path}: line {line['z']}: z = {env['z']!r} differs from the cell's z {z!r} "
                f"(line {self.where['hsize']}); the recorder scales the stress by z"
            )
        L0 = glob("L0", None)
        if not (isinstance(L0, (list, tuple)) and len(L0) == 2 and float(L0[0]) == lx and float(L0[1]) == ly):
            raise InputError(
                f"{self.path}: line {line['L0']}: L0 = {L0!r}: the supported shape has L0 = the cell's "
                f"sides ({lx!r}, {ly!r}) (the shear rate is xy_erate L0[1] / Ly)"
            )
        if np.any(pos < 0) or np.any(pos[:, 0] >= lx) or np.any(pos[:, 1] >= ly):
            raise InputError(
                f"{self.path}: line {self.where['bodies']}: centres outside the cell [0, Lx) x [0, Ly): "
                "the supported shape starts from centres wrapped into the cell"
            )
        kn, ks = g["engines"]["kn"], g["engines"]["ks"]
        phi = g["material"]
        mu = _friction(phi)
        if mu is None:
            raise InputError(
                f"{self.path}: line {self.where['material']}: frictionAngle {phi!r}: no mu has "
                "tan(atan(mu)) == tan(frictionAngle) (the native arithmetic's friction tangent)"
            )
        try:
            settings = DEMSettings(kn=kn, kt=ks, mu=mu, dt=dt)
        except InputError as exc:
            raise InputError(f"{self.path}: line {self.where['engines']}: {exc}") from None
        loading = self.loading(glob("load", None), lx, ly, dt)
        packing = Packing(pos, radii, np.diag([lx, ly]), density=rho)
        lines = self.text.splitlines()
        notes = [f"input files read by the script: {', '.join(sorted(self.files)) or 'none'}"]
        return YadeScript(
            self.path,
            self.text,
            packing,
            settings,
            loading,
            nsteps,
            te,
            de,
            vel,
            spin,
            z,
            dict(self.files),
            g["output"],
            lines,
            notes,
        )

    def loading(self, load, lx, ly, dt):
        where = f"{self.path}: line {self.lines_of['load']}"
        if not (isinstance(load, dict) and set(load) == {"xx", "yy", "xy_erate"}):
            raise InputError(f"{where}: load: expected a dict with keys xx, yy, xy_erate, got {load!r}")

        def axis(name, ctl, L):
            keys = {"fixed": {"mode"}, "rate": {"mode", "c"}, "servo": {"mode", "k", "target"}}
            mode = ctl.get("mode") if isinstance(ctl, dict) else None
            if mode not in keys or set(ctl) != keys[mode]:
                raise InputError(
                    f"{where}: load[{name!r}] = {ctl!r}: expected mode fixed, rate (c) or servo (k, target)"
                )
            if mode == "fixed":
                return AxisControl("fixed")
            if mode == "rate":
                c = float(ctl["c"])
                r = _solve(lambda r: r * L * dt, c, c / (L * dt))  # gransim.dem.yade_arithmetic: c = rate L0 dt
                if r is None:
                    raise InputError(
                        f"{where}: load[{name!r}] c = {c!r}: no engineering rate r has r L0 dt == c "
                        f"exactly (L0 = {L!r}, dt = {dt!r}); write c as rate * L0 * dt"
                    )
                return AxisControl("rate", rate=r)
            k = float(ctl["k"])
            gain = _solve(lambda gn: dt * gn, k, k / dt)  # k = dt gain
            if gain is None or not gain > 0:
                raise InputError(
                    f"{where}: load[{name!r}] k = {k!r}: expected dt gain with a gain > 0 that gives k "
                    "exactly (write k as dt * gain)"
                )
            return AxisControl("servo", target=float(ctl["target"]), gain=gain)

        x, y = axis("xx", load["xx"], lx), axis("yy", load["yy"], ly)
        erate = load["xy_erate"]
        if isinstance(erate, bool) or not isinstance(erate, (int, float)) or not math.isfinite(erate):
            raise InputError(f"{where}: load['xy_erate'] = {erate!r}: expected a number")
        if not erate:
            return Loading(x=x, y=y)
        if x.mode != "fixed" or y.mode == "rate":
            raise InputError(
                f"{where}: load: xy_erate {erate!r} with xx {x.mode} and yy {y.mode}: the native yade "
                "arithmetic shears with x fixed and y fixed or under the servo"
            )
        return ShearLoading(erate=float(erate), y=y.mode, target=y.target, gain=y.gain)


def _solve(f, want: float, guess: float, reach: int = 64):
    """A float p with f(p) == want bit for bit, searched from ``guess`` outwards, one ulp at a time
    (None when no float within ``reach`` ulps gives it)."""
    if not math.isfinite(guess):
        return None
    up = down = guess
    for _ in range(reach):
        if f(up) == want:
            return up
        if f(down) == want:
            return down
        up, down = math.nextafter(up, math.inf), math.nextafter(down, -math.inf)
    return None


def _friction(phi: float):
    """mu with tan(atan(mu)) == tan(phi): YADE's FrictPhys holds tan(frictionAngle) (FrictPhys.cpp:39-41),
    the native arithmetic tan(atan(mu)) (gransim.contacts.yade_cundall_strack.friction_tangent)."""
    near = [math.tan(phi)]
    for _ in range(8):
        near = [math.nextafter(near[0], -math.inf), *near, math.nextafter(near[-1], math.inf)]
    for ok in (lambda m: math.atan(m) == phi, lambda m: math.tan(math.atan(m)) == math.tan(phi)):
        hits = [m for m in near if ok(m)]
        if hits:  # the shortest decimal: mu = 0.5 for frictionAngle = atan(0.5)
            return min(hits, key=lambda m: (len(repr(m)), abs(m - near[8])))
    return _solve(lambda m: math.tan(math.atan(m)), math.tan(phi), math.tan(phi))


def read_script(path) -> YadeScript:
    """Read a YADE script of the supported shape (module doc) without executing it; InputError
    naming the line for anything outside it."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"SCRIPT: cannot read {str(p)!r}: {exc}") from None
    return _Reader(p, text).read().script()


# ----------------------------------------------------------------------------- running and comparing
def run_yade(script: YadeScript, job_dir: Path, timeout):
    """Run the script unchanged in YADE in ``job_dir``: (output path, version). Raises
    ReferenceRunError when the job fails or its output is incomplete (the job's evidence)."""
    files = {name: p.read_bytes() for name, p in script.files.items()}

    def check(d):
        try:
            read_yade_dem(Path(d) / script.output, script.expect)
        except ReferenceRunError as exc:
            return [str(exc)]
        return []

    res = run_yade_job(job_dir, script.text, files, timeout=timeout, outputs=[script.output], force=True, check=check)
    return Path(job_dir) / script.output, str(res.manifest.get("engine_version") or "unknown")


def _differ(a, b) -> tuple:
    """(number of entries that differ, largest |a - b|) of two equally shaped arrays; NaN never equal."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return max(a.size, b.size, 1), math.nan
    ne = ~(a == b)
    d = np.abs(a - b)
    return int(ne.sum()), float(np.max(d)) if d.size else 0.0


def _bitwise(quantity, n_diff, worst, where, n_values) -> Check:
    return Check(
        quantity,
        "values that differ from native (bit for bit)",
        n_diff,
        0,
        n_diff == 0,
        f"{n_values} values compared; largest |yade - native| {worst:.3g}" + (f" at step {where}" if n_diff else ""),
    )


def compare_output(script: YadeScript, out: YadeDemOutput, run) -> list:
    """Checks of every thermo row and frame of YADE's output against the native run (tolerance 0)."""
    checks = []
    steps = out.step
    checks.append(Check("thermo steps", "rows present", 0, 0, True, f"{len(steps)} rows, steps 0..{out.n_steps}"))
    for what, mine, theirs in (
        ("thermo cell", run.cell[steps], out.cell),
        ("thermo stress", run.stress[steps], out.stress),
        ("thermo velGrad", run.vel_grad[steps], out.vel_grad),
        ("thermo contacts", run.n_contacts[steps], out.n_contacts),
    ):
        nd, worst = _differ(mine, theirs)
        bad = np.flatnonzero(np.any((np.asarray(mine) != np.asarray(theirs)).reshape(len(steps), -1), axis=1))
        checks.append(_bitwise(what, nd, worst, int(steps[bad[0]]) if bad.size else None, np.asarray(theirs).size))
    frames = sorted(out.frames)
    checks.append(Check("frames", "frames present", 0, 0, True, f"{len(frames)} frames: steps {frames[:3]}..."))
    acc = {
        q: [0, 0.0, None, 0]
        for q in (
            "positions",
            "velocities",
            "spins",
            "forces",
            "torques",
            "mass",
            "radius",
            "contact cellDist",
            "contact normal force",
            "contact shear force",
            "contact penetration",
        )
    }
    missing, stray, order = [], [], []
    n_pairs = 0

    def add(q, mine, theirs, step):
        nd, worst = _differ(mine, theirs)
        a = acc[q]
        a[0] += nd
        a[1] = max(a[1], worst) if math.isfinite(worst) else math.nan
        a[2] = step if (nd and a[2] is None) else a[2]
        a[3] += np.asarray(theirs).size

    for s in frames:
        fr = out.frames[s]
        add("positions", run.positions[s], fr.positions, s)
        add("velocities", run.velocities[s], fr.velocities, s)
        add("spins", run.spins[s], fr.spins, s)
        add("forces", run.forces[s], fr.forces, s)
        add("torques", run.torques[s], fr.torques, s)
        add("mass", run.mass, fr.mass, s)
        add("radius", script.packing.radii, fr.radius, s)
        ids, cd, fn, fs, pen = run.contacts[s]
        mine = {(int(a), int(b)): k for k, (a, b) in enumerate(ids)}
        theirs = {(int(a), int(b)): k for k, (a, b) in enumerate(fr.ids)}
        lost = [p for p in mine if p not in theirs]
        extra = [p for p in theirs if p not in mine]
        if lost:
            missing.append(f"step {s}: {len(lost)} of {len(mine)} native contacts have no YADE row, e.g. {lost[0]}")
        if extra:
            stray.append(f"step {s}: {len(extra)} YADE contacts the native run does not have, e.g. {extra[0]}")
        if not lost and not extra and not np.array_equal(ids, fr.ids):
            order.append(f"step {s}")
        common = [p for p in theirs if p in mine]
        n_pairs += len(common)
        km = np.array([mine[p] for p in common], np.int64)
        kt = np.array([theirs[p] for p in common], np.int64)
        add("contact cellDist", cd[km], fr.cell_dist[kt], s)
        add("contact normal force", fn[km], fr.normal_force[kt], s)
        add("contact shear force", fs[km], fr.shear_force[kt], s)
        add("contact penetration", pen[km], fr.penetration[kt], s)
    checks.append(
        Check(
            "frame contacts",
            "incomplete: native contacts without a YADE row" if missing else "every native contact has its YADE row",
            len(missing),
            0,
            not missing,
            "; ".join(missing[:3]) or f"{n_pairs} contact rows matched by (id1, id2)",
        )
    )
    checks.append(
        Check("frame contacts without a native contact", "YADE rows", len(stray), 0, not stray, "; ".join(stray[:3]))
    )
    checks.append(
        Check(
            "frame contacts, YADE's container order",
            "frames in another order",
            len(order),
            0,
            not order,
            "; ".join(order[:3]) or "the interactions in YADE's order in every frame",
        )
    )
    for q, (nd, worst, where, size) in acc.items():
        checks.append(_bitwise(f"frame {q}", nd, worst, where, size))
    return checks


def read_reference(script: YadeScript, ref_dir: Path):
    """A finished YADE job directory: its output (the name the script writes) and the version its
    manifest records."""
    ref_dir = Path(ref_dir)
    if not ref_dir.is_dir():
        raise InputError(f"--reference: {ref_dir} is not a directory")
    version = "unknown (stored job)"
    try:
        version = json.loads((ref_dir / "manifest.json").read_text()).get("engine_version") or version
    except (OSError, ValueError):
        pass
    return ref_dir / script.output, f"{version} (stored job)"


def replay_yade(path, outdir=None, timeout=None, reference=None, echo=None) -> ReplayResult:
    """Read the script (InputError naming the line for anything outside the shape), run it in YADE
    (or read ``reference``), run it natively with :func:`gransim.dem.yade_arithmetic.yade_run`,
    compare bit for bit and write ``OUTDIR/report.md``, ``report.html``, ``replay.h5``.

    Returns a :class:`~reference_runs.replay.compare.ReplayResult` (``passed``: every value equal
    and the evidence complete). Raises ReferenceRunError when the YADE job fails (its output
    incomplete included)."""
    from gransim.dem.yade_arithmetic import yade_run  # noqa: PLC0415 - numba kernels, on demand

    say = echo or (lambda msg: None)
    script = read_script(path)
    out = Path(outdir) if outdir is not None else Path("results/replay") / Path(path).name
    if out.exists() and not out.is_dir():
        raise InputError(f"-o: {out} exists and is not a directory")
    if timeout is not None and not timeout > 0:
        raise InputError(f"--timeout: expected seconds > 0, got {timeout!r}")
    out.mkdir(parents=True, exist_ok=True)
    if reference is not None:
        output, version = read_reference(script, Path(reference))
        say(f"reading the YADE job in {reference}")
    else:
        say(f"running the script in YADE (job directory {out / 'job'})")
        output, version = run_yade(script, out / "job", timeout)
    say(f"running the script natively in YADE's arithmetic ({script.packing.n} disks, {script.nsteps} steps)")
    run = None
    try:
        run = yade_run(
            script.packing, script.settings, script.loading, script.nsteps, script.velocities, script.spins, script.z
        )
    except RuntimeError as exc:
        checks = [Check("native run", "stopped", 1, 0, False, str(exc))]
    else:
        try:
            data = read_yade_dem(output, script.expect)
        except ReferenceRunError as exc:
            checks = [
                Check(
                    "yade output",
                    "incomplete: steps, frames, particles or contacts missing",
                    1,
                    0,
                    False,
                    f"{exc}; no value is judged on incomplete evidence",
                )
            ]
        else:
            checks = compare_output(script, data, run)
    res = ReplayResult(script, checks, out, version, list(script.notes))
    write_report(res, run)
    return res


def write_report(res: ReplayResult, run) -> None:
    """``report.md``, ``report.html`` and ``replay.h5`` in ``res.outdir`` (each atomically)."""
    s = res.deck
    verdict = "PASS" if res.passed else "FAIL"
    ld = s.loading
    head = [
        f"# gransim replay: {s.path.name} ({verdict})",
        "",
        f"- YADE script `{s.path}` (the supported shape: docs/replay.md, 'YADE scripts'), output `{s.output}`",
        f"- code: {res.code_version}",
        f"- {s.packing.n} disks, cell {float(s.packing.cell[0, 0])!r} x {float(s.packing.cell[1, 1])!r} m (z {s.z!r}),"
        f" {s.nsteps} steps of {s.settings.dt!r} s, thermo every {s.thermo_every}, frames every {s.dump_every}",
        f"- law {LAW}: kn {s.settings.kn!r}, ks {s.settings.kt!r} N/m, mu {s.settings.mu!r}; NewtonIntegrator "
        "damping 0",
        f"- loading: {ld}",
        "- native run: gransim.dem.yade_arithmetic.yade_run (YADE 2023.02a's arithmetic); tolerance 0 (bit for bit); "
        "missing evidence fails",
        "",
    ]
    write_text_reports(res, s.path.name, head, verdict)
    params = {
        "script": str(s.path),
        "engine": ENGINE,
        "settings": s.settings.to_dict(),
        "nsteps": s.nsteps,
        "code_version": res.code_version,
    }
    with atomic_h5(res.outdir / "replay.h5", kind="replay", parameters=params) as f:
        f.attrs["passed"] = res.passed
        f.attrs["deck_text"] = s.text
        f.attrs["notes"] = json.dumps(res.notes)
        if run is not None:
            g = f.create_group("native")
            g.create_dataset("step", data=run.step)
            g.create_dataset("cell", data=run.cell)
            g["cell"].attrs["units"] = "m (YADE's hSize, lattice vectors as columns)"
            g.create_dataset("stress", data=run.stress)
            g["stress"].attrs["convention"] = "tension positive, z getStress() (N/m in 2D), not symmetrised"
        c = f.create_group("checks")
        c.create_dataset("quantity", data=np.array([k.quantity for k in res.checks], dtype="S"))
        c.create_dataset("metric", data=np.array([k.metric for k in res.checks], dtype="S"))
        c.create_dataset("value", data=np.array([float(k.value) for k in res.checks]))
        c.create_dataset("tolerance", data=np.array([float(k.tolerance) for k in res.checks]))
        c.create_dataset("passed", data=np.array([k.passed for k in res.checks], bool))


__all__ = ["YadeScript", "compare_output", "read_script", "replay_yade", "run_yade"]
