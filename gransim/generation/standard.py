"""The standard assemblies of the papers: the 15 RVEs of Meier et al. and Kuhn's 1002-disk assembly.

The catalogue (:data:`STANDARD_PACKINGS`) names each assembly by its request to one of the two
protocols, :func:`gransim.generation.make_packing` (frictionless FIRE) or
:func:`gransim.generation.compact_packing` (frictional DEM compaction), and
:func:`standard_packings` generates them into HDF5 files, reusing a file whose request and
generator version match. The 16 files ship with the package (``gransim/generation/data/standard/``,
made by ``gransim packings --force`` at :data:`GENERATOR_VERSION`, provenance inside each file):
a missing file is copied from there instead of regenerated, which saves about a minute of a fresh
``make run``. That the shipped files are what the generator makes is checked, not assumed:
``tests/generation/test_pack.py`` and the ``packings`` validation case regenerate some of them and
compare bit for bit (the full suite regenerates all 16).

The RVEs are made by the original random-start method of :func:`make_packing` (``method="random"``,
:data:`STANDARD_METHOD`): the stored reference runs of ``reference_runs/stored/`` (e.g.
``taylor-rve-70-1``) and the cached ``results/packings`` files are those packings, bit for bit.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from ..errors import InputError, ResultFileError
from ..geometry import Packing
from ..io import atomic_path, read_provenance, save_packing
from ..progress import progress
from .compaction import compact_packing
from .pack import DEFAULT_MEAN_OVERLAP, make_packing

#: bump when the algorithm changes results, so that :func:`standard_packings` regenerates files
#: (2: decompression ladder, rms preparatory stages, cell-list order, chunked sums;
#: 3: the Kuhn compaction is one servo phase, as one LIGGGHTS run)
GENERATOR_VERSION = 3

#: target mean overlap of the standard RVEs (relative to d_mean): the dense state of the slope problem
RVE_MEAN_OVERLAP = DEFAULT_MEAN_OVERLAP
#: the make_packing method of the standard RVEs (the one the stored references were made with)
STANDARD_METHOD = "random"
#: The Kuhn assembly (Kuhn, "Deformation measures for granular materials", section 4: void ratio 0.189,
#: effective coordination 3.75, mean indentation
#: below 0.02 % of D50) is made by frictional DEM compaction (:func:`gransim.generation.compact_packing`):
#: a frictionless jammed packing of this grading is denser (e = 0.177-0.184 over seeds 1-8) and
#: better connected than Kuhn's. The preparation friction 0.05 gives e = 0.190, 0.189, 0.195, 0.196
#: for seeds 1-4 (docs/generation.md); the seed is 1. Compaction stress 1e-4 kn: mean overlap 0.9e-4 D50.
KUHN_SEED = 1
KUHN_FRICTION = 0.05
KUHN_PRESSURE = 1e-4

#: where the shipped copies of the standard assemblies live (``<name>.h5``)
SHIPPED_DIR = Path(__file__).resolve().parent / "data" / "standard"


def _standard_requests() -> dict:
    req = {}
    for n in (70, 350, 700):
        for seed in range(1, 6):
            req[f"rve-{n}-{seed}"] = {
                "distribution": "quartz-sand",
                "n": n,
                "seed": seed,
                "mean_overlap": RVE_MEAN_OVERLAP,
            }
    req["kuhn-1002"] = {
        "protocol": "compaction",
        "distribution": "kuhn-1002",
        "n": 1002,
        "seed": KUHN_SEED,
        "friction": KUHN_FRICTION,
        "pressure": KUHN_PRESSURE,
    }
    return req


#: the 16 standard assemblies: name -> request. RVEs of Meier et al. section 4 (5 each of 70, 350,
#: 700 disks of quartz-sand, seeds 1-5; :func:`make_packing` arguments) and Kuhn's 1002-disk
#: assembly (seed 1; ``protocol: compaction`` = :func:`gransim.generation.compact_packing` arguments).
STANDARD_PACKINGS = _standard_requests()


def build_standard(name: str) -> Packing:
    """Generate one standard assembly of :data:`STANDARD_PACKINGS` (no file written)."""
    if name not in STANDARD_PACKINGS:
        raise InputError(f"unknown standard packing {name!r}; choose from: {', '.join(STANDARD_PACKINGS)}")
    req = dict(STANDARD_PACKINGS[name])
    if req.pop("protocol", "fire") == "compaction":
        return compact_packing(**req)
    return make_packing(**req, method=STANDARD_METHOD)


def _request(name: str) -> dict:
    """The provenance ``parameters`` a file of standard assembly ``name`` must carry."""
    return {"name": name, "generator_version": GENERATOR_VERSION, **STANDARD_PACKINGS[name]}


def _matches(path: Path, params: dict) -> bool:
    try:
        return read_provenance(path).get("parameters") == params
    except ResultFileError:
        return False  # unreadable or foreign


def shipped_packing(name: str) -> Path | None:
    """The shipped copy of standard assembly ``name`` if it is there and made by this generator version."""
    if name not in STANDARD_PACKINGS:
        raise InputError(f"unknown standard packing {name!r}; choose from: {', '.join(STANDARD_PACKINGS)}")
    path = SHIPPED_DIR / f"{name}.h5"
    return path if path.is_file() and _matches(path, _request(name)) else None


def standard_packings(out_dir="results/packings", names=None, force: bool = False, shipped: bool = True) -> dict:
    """Provide the standard assemblies as ``out_dir/<name>.h5`` (HDF5, :func:`gransim.io.save_packing`).

    A file that exists with the same request parameters (and generator version) is kept, so a
    rerun is cheap. A missing (or outdated) file is copied from the shipped copy
    (:data:`SHIPPED_DIR`, when ``shipped`` and its version matches) or else generated; ``force``
    always regenerates. ``names`` restricts the set (default: all 16 of :data:`STANDARD_PACKINGS`).
    Returns {name: Path} in the order of :data:`STANDARD_PACKINGS`.
    """
    out_dir = Path(out_dir)
    names = list(STANDARD_PACKINGS) if names is None else list(names)
    for name in names:
        if name not in STANDARD_PACKINGS:
            raise InputError(f"unknown standard packing {name!r}; choose from: {', '.join(STANDARD_PACKINGS)}")
        if (out_dir / f"{name}.h5").is_dir():
            raise InputError(f"{out_dir / f'{name}.h5'} is a directory; the packing {name!r} is written there")
    out = {}
    bar = progress(names, total=len(names), desc="packings")
    for name in bar:
        req = STANDARD_PACKINGS[name]
        params = _request(name)
        path = out_dir / f"{name}.h5"
        if not force:
            if path.exists() and _matches(path, params):
                out[name] = path
                continue
            src = shipped_packing(name) if shipped else None
            if src is not None and src.resolve() != path.resolve():
                with atomic_path(path, suffix=".h5") as tmp:  # a crash leaves no half-copied file
                    shutil.copyfile(src, tmp)
                out[name] = path
                continue
        packing = build_standard(name)
        save_packing(path, packing, parameters=params, seed=req["seed"])
        out[name] = path
    return out
