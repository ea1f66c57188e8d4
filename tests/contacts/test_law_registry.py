"""The contact laws of gransim.contacts as plug-ins of the DEM engine: every
law built by name (gransim.contacts.laws.make_law) runs the stored two-disk impact of its code
through DEMEngine (its integrator, neighbour list and history hand-over, not a test-local loop)
and reproduces every dumped number of every step of LIGGGHTS 3.8.0 / LAMMPS 29 Sep 2021 exactly
(reference_runs/stored/hertz-*, rolling-*: README.md there for the provenance); bad names and
parameters are refused with a message naming them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gransim.contacts import hertz, rolling
from gransim.contacts.laws import law_code, law_names, law_spec, make_law
from gransim.dem import DEMEngine, DEMSettings, Loading
from gransim.errors import InputError
from gransim.geometry import Packing
from reference_runs.decks.hertz import impact_case
from reference_runs.decks.rolling import rolling_case

ROOT = Path(__file__).resolve().parents[2]
STORED = ROOT / "reference_runs" / "stored"


def _hertz(name):
    c = impact_case()
    if name == "hertz-liggghts":
        p = {
            "youngs_modulus": c["youngs_modulus"],
            "poisson_ratio": c["poisson_ratio"],
            "restitution": c["restitution"],
            "friction": c["friction"],
        }
        return c, p, STORED / "hertz-liggghts"
    if name == "hertz-lammps":
        p = {"kn": c["kn"], "kt": c["kt"], "gamma_n": c["gamman"], "gamma_t": c["gammat"], "mu": c["friction"]}
        return c, p, STORED / "hertz-lammps" / "gran-hertz-history"
    p = {
        "youngs_modulus": c["youngs_modulus"],
        "poisson_ratio": c["poisson_ratio"],
        "damp": c["restitution"],
        "friction": c["friction"],
        "gammat_ratio": c["gammat_ratio"],
        "damping": "tsuji",
    }
    return c, p, STORED / "hertz-lammps" / "granular"


def _rolling(name):
    c = rolling_case()
    model = name.split("-")[1]
    if model == "sds":
        p = {
            "kn": c["kn"],
            "damp": c["gamman"],
            "damping": "mass_velocity",
            "kt": c["kt"],
            "xgammat": c["gammat"] / c["gamman"],
            "mu": c["friction"],
            "kroll": c["kroll"],
            "gammaroll": c["gammaroll"],
            "muroll": c["rolling_friction"],
        }
        return c, p, STORED / "rolling-lammps" / "sds"
    p = {
        "kn": c["kn"],
        "kt": c["kt"],
        "gamma_n": c["gamman"],
        "gamma_t": c["gammat"],
        "mu": c["friction"],
        "mu_r": c["rolling_friction"],
    }
    if model == "epsd":
        p["eta_r"] = c["rolling_viscous"]
    return c, p, STORED / "rolling-liggghts" / model


#: law name -> (case, make_law parameters, stored job directory) of its two-disk run
CASES = {
    n: (_hertz if n.startswith("hertz") else _rolling)(n)
    for n in law_names()
    if n not in ("hooke-liggghts", "hooke-lammps")
}


def read_dump(path) -> dict:
    """{step: {column: (N,) array}} of a ``dump custom`` file sorted by id."""
    out, lines, k = {}, Path(path).read_text().splitlines(), 0
    while k < len(lines):
        if lines[k].startswith("ITEM: TIMESTEP"):
            step = int(lines[k + 1])
            n = int(lines[k + 3])
            cols = lines[k + 8].split()[2:]
            rows = np.array([[float(v) for v in ln.split()] for ln in lines[k + 9 : k + 9 + n]])
            out[step] = {c: rows[:, i] for i, c in enumerate(cols)}
            k += 9 + n
        else:
            k += 1
    return out


def _engine(name):
    case, params, job = CASES[name]
    law = make_law(name, **params)
    pk = Packing(
        positions=np.array(case["positions"]),
        radii=np.array(case["radii"]),
        cell=np.diag(case["box"]),
        density=case["density"],
    )
    s = DEMSettings(dt=case["dt"], skin=case["skin"], flavour=law_code(name))
    eng = DEMEngine(
        pk, s, velocities=np.array(case["velocities"]), spins=np.array(case["spins"]), law=law, check_dt=False
    )
    return eng, case, job


def _frame(eng):
    return {
        "x": eng.x[:, 0],
        "y": eng.x[:, 1],
        "vx": eng.v[:, 0],
        "vy": eng.v[:, 1],
        "omegaz": eng.w,
        "fx": eng.f[:, 0],
        "fy": eng.f[:, 1],
        "tqz": eng.t,
    }


@pytest.mark.parametrize("name", list(CASES))
def test_engine_plugin_equals_stored_two_disk_run(name):
    """DEMEngine with the law of ``name`` equals the stored run of its code at every step, every
    column (x, y, vx, vy, omegaz, fx, fy, tqz): difference 0. The set-up is the deck's: the same
    periodic 0.1 m box from the origin, positions, velocities, spins and masses pi r^2 rho (checked
    against the dump), the same skin and the code's rebuild rule (law_code -> flavour). The run has
    contact, sticking and (Hertz, epsd2/epsd/sds) sliding or a capped rolling torque, so a law that
    differs in any branch it takes differs here."""
    eng, case, job = _engine(name)
    d = read_dump(job / "dump.atoms")
    assert sorted(d) == list(range(case["nsteps"] + 1))
    assert np.array_equal(eng.m, d[0]["mass"]), "masses differ from the code's"
    touching = 0
    for step in range(case["nsteps"] + 1):
        if step:
            eng.advance(Loading(), 1)
        fr = _frame(eng)
        for k, v in fr.items():
            assert np.array_equal(v, d[step][k]), (name, step, k, v - d[step][k])
        touching += d[step]["fx"][0] != 0.0
    assert touching > 100
    # the rolling laws carry their rolling history through the engine's list (width of the law)
    assert eng.nb.hist.shape[1] == law_spec(eng.law).width


def test_names_classes_and_widths():
    """Each name maps to its module's class, the widths and flips of rolling.HISTORY_WIDTH/FLIP,
    and the code that the name says (the LAMMPS laws zero a separated pair's history)."""
    cls = {
        "hertz-liggghts": hertz.HertzHistoryLiggghts,
        "hertz-lammps": hertz.HertzHistoryLammps,
        "hertz-granular-lammps": hertz.HertzGranularLammps,
        "hooke-epsd2-liggghts": rolling.HookeEpsd2Liggghts,
        "hooke-epsd-liggghts": rolling.HookeEpsdLiggghts,
        "hooke-cdt-liggghts": rolling.HookeCdtLiggghts,
        "hooke-sds-lammps": rolling.HookeSdsLammps,
    }
    for name, (_, params, _) in CASES.items():
        law = make_law(name, **params)
        assert type(law) is cls[name]
        spec = law_spec(law)
        model = name.split("-")[1]
        if model in rolling.HISTORY_WIDTH:
            assert spec.width == rolling.HISTORY_WIDTH[model] and spec.flip == rolling.HISTORY_FLIP[model]
        else:
            assert spec.width == 2 and spec.flip == (-1.0, -1.0)
        assert law_code(name) == name.rsplit("-", 1)[1]
        assert (spec.apart is not None) == (law_code(name) == "lammps")
        assert all(isinstance(v, float) for v in law)  # one numba type per class


def test_separated_pair_history_zeroed_only_in_lammps():
    """After the two disks part (stored run ends separated), a LAMMPS law has zeroed the pair's
    history (pair_granular.cpp:283-288, pair_gran_hertz_history.cpp:126-132) and a LIGGGHTS law
    keeps its last spring (pair_gran_base.h:414: surfacesClose unreachable)."""
    for name in ("hertz-liggghts", "hertz-lammps", "hertz-granular-lammps"):
        eng, case, _ = _engine(name)
        eng.advance(Loading(), case["nsteps"])
        assert eng.nb.a.size == 1  # the pair is still listed (skin 2 mm)
        kept = np.abs(eng.nb.hist).max()
        assert (kept == 0.0) == (law_code(name) == "lammps"), (name, kept)


def test_bad_names_and_parameters():
    with pytest.raises(InputError, match="expected one of hooke-liggghts"):
        make_law("hertz")
    with pytest.raises(InputError, match="hertz-lammps: expected parameters kn, kt.*missing gamma_n"):
        make_law("hertz-lammps", kn=1.0, kt=1.0)
    with pytest.raises(InputError, match="unknown youngs"):
        make_law("hooke-cdt-liggghts", kn=1.0, kt=1.0, gamma_n=0, gamma_t=0, mu=0.1, mu_r=0.1, youngs=3)
    with pytest.raises(InputError, match="coefficientRestitution"):
        make_law("hertz-liggghts", youngs_modulus=1e8, poisson_ratio=0.3, restitution=1.5, friction=0.3)
    with pytest.raises(InputError, match="mu_r"):
        make_law("hooke-epsd2-liggghts", kn=1.0, kt=1.0, gamma_n=0, gamma_t=0, mu=0.1, mu_r=-1)
    with pytest.raises(InputError, match="damping: expected one of velocity"):
        make_law("hooke-sds-lammps", **{**CASES["hooke-sds-lammps"][1], "damping": "tsujii"})
    with pytest.raises(InputError, match="kroll: expected a stiffness > 0"):
        make_law("hooke-sds-lammps", **{**CASES["hooke-sds-lammps"][1], "kroll": 0.0})


def test_energies_of_registered_and_radius_dependent_laws():
    """sds energy = kn d^2/2 + kt|xi|^2/2 + kroll|psi|^2/2 (its forces are -grad of it below the
    caps); hertz_energy's normal part has d/d delta = 4/3 Y* sqrt(R*) delta^1.5 (central
    difference, rel 1e-8); epsd_energy's rolling part is M^2/(2 kt R*^2) for epsd2."""
    law = make_law("hooke-sds-lammps", **CASES["hooke-sds-lammps"][1])
    ov, h = np.array([1e-6, 2e-6]), np.array([[1e-7, 0, 2e-7, 0], [0, -3e-7, 0, 1e-7]])
    want = 0.5 * 1000 * 5e-12 + 0.5 * 800 * 1e-14 * 10 + 0.5 * 800 * 1e-14 * 5
    assert law_spec(law).energy(law, ov, h) == pytest.approx(want, rel=1e-14)
    hl = make_law("hertz-liggghts", **CASES["hertz-liggghts"][1])
    R, d, eps = np.array([4.4e-4]), 3e-6, 1e-10
    r2 = 2 * R  # two disks of radius 2 R*: R* = R
    up = hertz.hertz_energy(hl, np.array([d + eps]), np.zeros((1, 2)), r2, r2)
    dn = hertz.hertz_energy(hl, np.array([d - eps]), np.zeros((1, 2)), r2, r2)
    assert (up - dn) / (2 * eps) == pytest.approx(4 / 3 * hl.yeff * math.sqrt(R[0]) * d**1.5, rel=1e-8)
    e2 = make_law("hooke-epsd2-liggghts", **CASES["hooke-epsd2-liggghts"][1])
    got = rolling.epsd_energy(e2, np.zeros(1), np.array([[0.0, 0.0, 2e-6]]), r2, r2)
    assert got == pytest.approx(0.5 * 4e-12 / (800 * R[0] ** 2), rel=1e-14)
