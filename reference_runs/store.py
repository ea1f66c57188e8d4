"""Regenerate the stored reference outputs in ``reference_runs/stored/`` (needs the code).

    python -m reference_runs.store                   # LIGGGHTS: rewrites reference_runs/stored/taylor-*
    python -m reference_runs.store --engine lammps   # LAMMPS: rewrites reference_runs/stored/taylor-*-lammps
    python -m reference_runs.store --case relaxation # both codes: reference_runs/stored/relaxation-lattice-8x8
    python -m reference_runs.store --case relaxation-rve  # both codes: reference_runs/stored/relaxation-rve-70-1

The stored outputs let tests compare against LIGGGHTS where the binary is absent. Each case
directory holds the job files exactly as run (deck, data files, states.json, log.lammps,
contact dumps, manifest.json), the packing (packing.h5) and a README.md of provenance.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import shutil
import sys
from pathlib import Path

from gransim.errors import GransimError
from gransim.io import load_packing, save_packing
from gransim.paper import KN_2D

from .demo_packings import perturbed_lattice
from .engines import get_engine
from .taylor import run_taylor

STORED = Path(__file__).resolve().parent / "stored"
TAYLOR_CASE = "taylor-lattice-6x6"
#: parameters of the stored Taylor case (kn: the paper's 2D contact stiffness, N/m, gransim.paper.KN_2D)
TAYLOR_PARAMS = {"nx": 6, "ny": 6, "seed": 7, "kn": KN_2D, "n_steps": 50, "stride": 10, "max_strain": 0.1}
#: a study RVE (gransim.generation standard packing rve-70-1), thermo only (no data files kept)
RVE_CASE = "taylor-rve-70-1"


def taylor_case(base: str, engine: str = "liggghts") -> str:
    """Name of a stored Taylor case for an engine: ``base`` for LIGGGHTS, ``base-lammps`` for LAMMPS."""
    e = get_engine(engine)
    return base if e.name == "liggghts" else f"{base}-{e.name}"


def stored_taylor_packing():
    """The packing of the stored Taylor case (deterministic; also saved as packing.h5)."""
    p = TAYLOR_PARAMS
    return perturbed_lattice(p["nx"], p["ny"], seed=p["seed"])


_README = """\
# Stored LIGGGHTS reference output: `{case}`

Taylor (affine) RVE states of a {n}-disk periodic packing (orthogonal cell {lx:.6g} m x {ly:.6g} m;
{source}; stored in `packing.h5`) along the four study paths of Meier, Steinmann & Kuhl, "Towards
completeness: a multiscale approach of confined particulate systems" (Figs 4-5): compression-11/22
(F11, F22 = 1 -> 0.9) and shear-12/21 (F12, F21 = 0 -> 0.1), states k = 0, 10, ..., 50 of 50 steps,
by the periodic-box route (compression only) and the explicit-image route (all paths).

- LIGGGHTS: {version}, Debian package `liggghts`: {package}; banner: `{banner}`
- Contact: `pair_style gran model hooke/stiffness tangential no_history`, kn = E_n = {kn:g} N/m,
  kt = 0, gamman = gammat = 0, `run 0` per state (no motion).
- Deck: `in.liggghts` (written by `reference_runs.decks.taylor.taylor_job`); per-state data files
  in `states/`{data_note}, written by gransim at `%.17g` with x = F X; states and F in `states.json`.
- Command (in this directory): `{command}`
- Date: {date}; job time {elapsed} s; manifest: `manifest.json` (status ok, SHA-256 of every input).
- Outputs: `log.lammps` (one thermo row per state, `%.17g`: `c_p[1,2,4]` = virial pressure,
  compression positive; `c_sc[1..3]` = sum of stress/atom over the central particles = sigma det F
  V_ref, tension positive){contacts_note}.
- Regenerate: `python -m reference_runs.store` (needs LIGGGHTS; the RVE case needs its packing file).
- Used by: `tests/reference_runs/test_ref_stored_taylor.py` (parsers; stress vs the numpy Taylor
  stress to 1e-10 relative; contact forces vs numpy).
"""

_README_LAMMPS = """\
# Stored LAMMPS reference output: `{case}`

Taylor (affine) RVE states of a {n}-disk periodic packing (orthogonal cell {lx:.6g} m x {ly:.6g} m;
{source}; stored in `packing.h5`) along the four study paths of Meier, Steinmann & Kuhl, "Towards
completeness: a multiscale approach of confined particulate systems" (Figs 4-5): compression-11/22
(F11, F22 = 1 -> 0.9) and shear-12/21 (F12, F21 = 0 -> 0.1), states k = 0, 10, ..., 50 of 50 steps, by
the periodic route on **all four paths** (compression in an orthogonal box, simple shear in a true
periodic triclinic box = the sheared cell; shear-21 with x and y swapped, `frame` in `states.json`)
and the explicit-image route (all paths).

- LAMMPS: {version}, Debian package `lammps`: {package}; banner: `{banner}`
- Contact: `pair_style gran/hooke {kn:.17g} 0 0 0 0 0` (kn = E_n = {kn:g} N/m, kt = gamman = gammat = mu = 0),
  `comm_modify mode single vel yes`, `set group all density/disc`, `run 0` per state (no motion).
- Deck: `in.lammps` (written by `reference_runs.decks.taylor.taylor_job(..., engine="lammps")`);
  per-state data files in `states/`{data_note}, written by gransim at `%.17g` with x = F X;
  states, F and frames in `states.json`.
- Command (in this directory): `{command}`
- Date: {date}; job time {elapsed} s; manifest: `manifest.json` (status ok, engine lammps, SHA-256 of
  every input).
- Outputs: `log.lammps` (one thermo row per state, `%.17g`: `c_p[1,2,4]` = virial pressure,
  compression positive; `c_sc[1..3]` = sum of stress/atom over the central particles = sigma det F
  V_ref, tension positive; both in the engine frame){contacts_note}.
- Regenerate: `python -m reference_runs.store --engine lammps` (needs `lmp`).
- Used by: `tests/reference_runs/test_ref_stored_taylor_lammps.py` (stress vs the numpy Taylor
  stress to 1e-10 relative, contact forces vs numpy; live when `lmp` is installed).
"""


def regenerate_taylor(
    dest: Path | None = None,
    packing=None,
    name: str | None = None,
    contacts: bool = True,
    keep_data: bool = True,
    packing_source: str | None = None,
    timeout: float | None = 600.0,
    engine: str = "liggghts",
) -> Path:
    """Run a stored Taylor case and copy the job (without stdout/stderr) into ``dest``.

    Defaults: the lattice case (``taylor-lattice-6x6``, LAMMPS: ``taylor-lattice-6x6-lammps``).
    ``keep_data=False`` drops the per-state data files (they are regenerated bit for bit by the
    deck generator from ``packing.h5``; the manifest keeps their hashes). ``engine``:
    ``"liggghts"`` or ``"lammps"``.
    """
    eng = get_engine(engine)
    name = name or taylor_case(TAYLOR_CASE, eng.name)
    dest = Path(dest) if dest else STORED / name
    p = TAYLOR_PARAMS
    if packing is None:
        packing = stored_taylor_packing()
    tmp = dest.parent / (dest.name + ".job")
    shutil.rmtree(tmp, ignore_errors=True)
    run = run_taylor(
        packing,
        p["kn"],
        tmp,
        name=name,
        n_steps=p["n_steps"],
        stride=p["stride"],
        max_strain=p["max_strain"],
        contacts=contacts,
        progress=False,
        cleanup_inputs=not keep_data,
        timeout=timeout,
        engine=eng.name,
    )
    for junk in ("stdout.txt", "stderr.txt", ".lock"):  # .lock: the runner's job lock, released by now
        (tmp / junk).unlink(missing_ok=True)
    if not keep_data:
        shutil.rmtree(tmp / "states", ignore_errors=True)
    save_packing(
        tmp / "packing.h5",
        packing,
        parameters={**dict(packing.metadata), **p},
        seed=packing.metadata.get("seed", p["seed"]),
    )
    m = run.manifest
    banner = (tmp / "log.lammps").read_text().splitlines()[0]
    cmd = " ".join(Path(c).name if i == 0 else c for i, c in enumerate(m["command"]))
    source = packing_source or (
        "`reference_runs.demo_packings.perturbed_lattice(6, 6, seed=7)`, a perturbed triangular lattice"
    )
    (tmp / "README.md").write_text(
        (_README_LAMMPS if eng.name == "lammps" else _README).format(
            case=name,
            package=m.get("engine_package"),
            n=packing.n,
            lx=packing.cell[0, 0],
            ly=packing.cell[1, 1],
            source=source,
            data_note=""
            if keep_data
            else " (not kept: regenerated bit for bit from `packing.h5` by the "
            "deck generator; their SHA-256 are in the manifest)",
            contacts_note=", `contacts/<path>/<route>_<k>.dump` (`compute pair/gran/local id pos force delta`, `%.17g`)"
            if contacts
            else "",
            version=eng.version(),
            banner=banner,
            kn=p["kn"],
            command=cmd,
            date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            elapsed=m["elapsed_s"],
        )
    )
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    return dest


def regenerate_taylor_rve(
    dest: Path | None = None, packing_file=None, timeout: float | None = 600.0, engine: str = "liggghts"
) -> Path:
    """The RVE case: the standard packing rve-70-1 of gransim.generation, thermo only (its packing
    is read from the stored LIGGGHTS case)."""
    if packing_file is None:
        packing_file = STORED / RVE_CASE / "packing.h5"
    packing = load_packing(packing_file)
    src = "the study RVE `rve-70-1` of `gransim.generation.standard_packings` (quartz-sand, 70 disks, seed 1)"
    name = taylor_case(RVE_CASE, engine)
    return regenerate_taylor(
        dest or STORED / name,
        packing,
        name=name,
        contacts=False,
        keep_data=False,
        packing_source=src,
        timeout=timeout,
        engine=engine,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m reference_runs.store", description="Regenerate the stored Taylor reference outputs."
    )
    ap.add_argument("--engine", default="liggghts", help="liggghts (default) or lammps")
    ap.add_argument(
        "--case",
        default="taylor",
        choices=("taylor", "relaxation", "relaxation-rve"),
        help="taylor (default: the Taylor cases of --engine), relaxation (the relaxation case's lattice RVE, "
        "both codes) or relaxation-rve (its standard random RVE rve-70-1, both codes)",
    )
    args = ap.parse_args(argv)

    try:
        if args.case in ("relaxation", "relaxation-rve"):
            # lazy: reference_runs.decks.relaxation imports this module (STORED)
            from .decks.relaxation import RVE_NAME, regenerate

            print(regenerate(key="lattice" if args.case == "relaxation" else RVE_NAME))
            return 0
        get_engine(args.engine).find()  # before anything is written
        print(regenerate_taylor(engine=args.engine))
        print(regenerate_taylor_rve(engine=args.engine))
    except GransimError as exc:
        print(f"python -m reference_runs.store: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
