"""Tiny decks (3 disks far apart, no contacts) that print the box at %.17g every step under one
fix deform, in LIGGGHTS or LAMMPS syntax (tests/replay/test_replay_deform.py)."""

from __future__ import annotations

from pathlib import Path

TINY_DATA = """tiny deform deck: 3 disks far apart, box origin away from zero

3 atoms
1 atom types

-0.0123 0.0377 xlo xhi
0.0051 0.0462 ylo yhi
-0.001 0.001 zlo zhi

Atoms

1 1 0.002 2500 0.001 0.010 0
2 1 0.0024 2500 0.02 0.03 0
3 1 0.0018 2500 -0.005 0.04 0
"""

#: name -> (fix deform arguments after N, N, run length)
CASES = {
    "erate-trate": ("x erate -0.7 y trate 1.3", 1, 40),
    "vel-final": ("x vel 0.01 y final 0.0049 0.0465", 3, 40),
    "delta-scale": ("x delta 1e-4 -3e-4 y scale 0.97", 2, 41),
    "trate-erate": ("x trate -2.1 y erate 0.4", 4, 37),
}

_LAW = {
    "liggghts": [
        "communicate single vel yes",
        "read_data data.tiny",
        "fix k1 all property/global kn peratomtypepair 1 1e5",
        "fix k2 all property/global kt peratomtypepair 1 7e4",
        "fix k3 all property/global gamman peratomtypepair 1 50",
        "fix k4 all property/global gammat peratomtypepair 1 25",
        "fix k5 all property/global coefficientFriction peratomtypepair 1 0.5",
        "pair_style gran model hooke/stiffness tangential history",
    ],
    "lammps": [
        "comm_modify mode single vel yes",
        "read_data data.tiny",
        "set group all density/disc 2500",
        "pair_style gran/hooke/history 1e5 7e4 50 25 0.5 1",
    ],
}


def deck_text(engine: str, case: str) -> str:
    args, every, n = CASES[case]
    temp = "thermo_temp" if engine == "liggghts" else "NULL"
    nve = "nve/sphere" if engine == "liggghts" else "nve/sphere disc"
    lines = [
        "units si",
        "dimension 2",
        "boundary p p p",
        "atom_style sphere",
        "atom_modify map array sort 0 0.0",
        "newton off",
        *_LAW[engine][:1],
        _LAW[engine][1],
        *_LAW[engine][2:],
        "pair_coeff * *",
        "neighbor 1e-4 bin",
        "neigh_modify delay 0 every 1 check yes",
        "timestep 1e-5",
        f"fix 1 all {nve}",
        "fix 2 all enforce2d",
        f"fix 3 all deform {every} {args} remap x",
        f"compute p all pressure {temp} virial",
        "thermo_style custom step lx xlo xhi ly ylo yhi c_p[1]",
        "thermo_modify format float %.17g norm no",
        "thermo 1",
        f"run {n}",
    ]
    return "\n".join(lines) + "\n"


def write(tmp, engine: str, case: str) -> Path:
    tmp = Path(tmp)
    (tmp / "data.tiny").write_text(TINY_DATA)
    deck = tmp / f"in.{engine}-{case}"
    deck.write_text(deck_text(engine, case))
    return deck


# -- shared by the replay tests ---------------------------------------------------------------
import shutil  # noqa: E402

HERE = Path(__file__).parent
DATA = HERE / "data"
BINARIES = {"liggghts": "liggghts", "lammps": "lmp"}


def need_binary(engine: str) -> None:
    import pytest

    if shutil.which(BINARIES[engine]) is None:
        pytest.skip(f"{BINARIES[engine]} binary not installed")


# -- tiny sheared decks (tests/replay/test_replay_tilt.py) -------------------------------------
TINY_TRICLINIC_DATA = """tiny sheared deck: 3 disks far apart, tilted box with its origin away from zero

3 atoms
1 atom types

-0.0123 0.0377 xlo xhi
0.0051 0.0462 ylo yhi
-0.001 0.001 zlo zhi
0.003 0 0 xy xz yz

Atoms

1 1 0.002 2500 0.001 0.010 0
2 1 0.0024 2500 0.02 0.03 0
3 1 0.0018 2500 0.005 0.04 0
"""

#: name -> (fix deform xy arguments, N, run length): every xy style, N = 1 and N > 1
TILT_CASES = {
    "erate-3": ("xy erate 2.1", 3, 40),
    "trate-1": ("xy trate 13.0", 1, 40),
    "trate-4": ("xy trate -7.5", 4, 41),
    "vel-2": ("xy vel 0.9", 2, 40),
    "final-5": ("xy final -0.004", 5, 40),
    "delta-1": ("xy delta 0.0021", 1, 37),
}


def tilt_deck_text(case: str) -> str:
    args, every, n = TILT_CASES[case]
    lines = [
        "units si",
        "dimension 2",
        "boundary p p p",
        "atom_style sphere",
        "atom_modify map array sort 0 0.0",
        "newton off",
        "comm_modify mode single vel yes",
        "read_data data.tri",
        "set group all density/disc 2500",
        "pair_style gran/hooke/history 1e5 7e4 50 25 0.5 1",
        "pair_coeff * *",
        "neighbor 1e-4 bin",
        "neigh_modify delay 0 every 1 check yes",
        "timestep 1e-5",
        "fix 1 all nve/sphere disc",
        "fix 2 all enforce2d",
        f"fix 3 all deform {every} {args} remap v",
        "compute p all pressure NULL virial",
        "thermo_style custom step lx ly xy xlo xhi ylo yhi c_p[1]",
        "thermo_modify format float %.17g norm no",
        "thermo 1",
        f"run {n}",
    ]
    return "\n".join(lines) + "\n"


def write_tilt(tmp, case: str) -> Path:
    tmp = Path(tmp)
    (tmp / "data.tri").write_text(TINY_TRICLINIC_DATA)
    deck = tmp / f"in.lammps-xy-{case}"
    deck.write_text(tilt_deck_text(case))
    return deck
