"""Regenerate the stored reference outputs in ``reference_runs/stored/`` (needs LIGGGHTS).

    python -m reference_runs.store            # rewrites reference_runs/stored/taylor-*

The stored outputs let tests compare against LIGGGHTS where the binary is absent. Each case
directory holds the job files exactly as run (deck, data files, states.json, log.lammps,
contact dumps, manifest.json), the packing (packing.h5) and a README.md of provenance.
"""

from __future__ import annotations

import datetime as _dt
import shutil
from pathlib import Path

from gransim.io import liggghts_version, save_packing

from .demo_packings import perturbed_lattice

STORED = Path(__file__).resolve().parent / "stored"
TAYLOR_CASE = "taylor-lattice-6x6"
#: parameters of the stored Taylor case
TAYLOR_PARAMS = {"nx": 6, "ny": 6, "seed": 7, "kn": 2.8e7, "n_steps": 50, "stride": 10, "max_strain": 0.1}
#: a study RVE (gransim.generation standard packing rve-70-1), thermo only (no data files kept)
RVE_CASE = "taylor-rve-70-1"


def stored_taylor_packing():
    """The packing of the stored Taylor case (deterministic; also saved as packing.h5)."""
    p = TAYLOR_PARAMS
    return perturbed_lattice(p["nx"], p["ny"], seed=p["seed"])


_README = """\
# Stored LIGGGHTS reference output: `{case}`

Taylor (affine) RVE states of a {n}-disk periodic packing (orthogonal cell {lx:.6g} m x {ly:.6g} m;
{source}; stored in `packing.h5`) along the four study paths of 000_6d950a6f5c65e7b0.txt: compression-11/22 (F11, F22
= 1 -> 0.9) and shear-12/21 (F12, F21 = 0 -> 0.1), states k = 0, 10, ..., 50 of 50 steps, by the
periodic-box route (compression only) and the explicit-image route (all paths).

- LIGGGHTS: {version} (`/usr/bin/liggghts`, Debian package `liggghts`); banner: `{banner}`
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


def regenerate_taylor(dest: Path | None = None, packing=None, name: str = TAYLOR_CASE, contacts: bool = True,
                      keep_data: bool = True, packing_source: str | None = None,
                      timeout: float | None = 600.0) -> Path:
    """Run a stored Taylor case and copy the job (without stdout/stderr) into ``dest``.

    Defaults: the lattice case. ``keep_data=False`` drops the per-state data files (they are
    regenerated bit for bit by the deck generator from ``packing.h5``; the manifest keeps
    their hashes).
    """
    from .taylor import run_taylor

    dest = Path(dest) if dest else STORED / name
    p = TAYLOR_PARAMS
    if packing is None:
        packing = stored_taylor_packing()
    tmp = dest.parent / (dest.name + ".job")
    shutil.rmtree(tmp, ignore_errors=True)
    run = run_taylor(packing, p["kn"], tmp, name=name, n_steps=p["n_steps"], stride=p["stride"],
                     max_strain=p["max_strain"], contacts=contacts, progress=False,
                     cleanup_inputs=not keep_data, timeout=timeout)
    for junk in ("stdout.txt", "stderr.txt"):
        (tmp / junk).unlink(missing_ok=True)
    if not keep_data:
        shutil.rmtree(tmp / "states", ignore_errors=True)
    save_packing(tmp / "packing.h5", packing, parameters={**dict(packing.metadata), **p},
                 seed=packing.metadata.get("seed", p["seed"]))
    m = run.manifest
    banner = (tmp / "log.lammps").read_text().splitlines()[0]
    cmd = " ".join(Path(c).name if i == 0 else c for i, c in enumerate(m["command"]))
    source = packing_source or ("`reference_runs.demo_packings.perturbed_lattice(6, 6, seed=7)`, a "
                                "perturbed triangular lattice")
    (tmp / "README.md").write_text(_README.format(
        case=name, n=packing.n, lx=packing.cell[0, 0], ly=packing.cell[1, 1], source=source,
        data_note="" if keep_data else " (not kept: regenerated bit for bit from `packing.h5` by the "
                                       "deck generator; their SHA-256 are in the manifest)",
        contacts_note=", `contacts/<path>/<route>_<k>.dump` (`compute pair/gran/local id pos force delta`, "
                      "`%.17g`)" if contacts else "",
        version=liggghts_version(), banner=banner, kn=p["kn"], command=cmd,
        date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), elapsed=m["elapsed_s"]))
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    return dest


def regenerate_taylor_rve(dest: Path | None = None, packing_file=None, timeout: float | None = 600.0) -> Path:
    """The RVE case: the standard packing rve-70-1 of gransim.generation, thermo only."""
    from gransim.io import load_packing

    if packing_file is None:
        packing_file = STORED / RVE_CASE / "packing.h5"
    packing = load_packing(packing_file)
    src = ("the study RVE `rve-70-1` of `gransim.generation.standard_packings` (quartz-sand, 70 disks, "
           "seed 1)")
    return regenerate_taylor(dest or STORED / RVE_CASE, packing, name=RVE_CASE, contacts=False,
                             keep_data=False, packing_source=src, timeout=timeout)


if __name__ == "__main__":  # pragma: no cover
    print(regenerate_taylor())
    print(regenerate_taylor_rve())
