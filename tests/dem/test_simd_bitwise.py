"""The bitwise engine's SIMD force loop for the Hooke laws (gransim.dem.kernels._serial_block_loop).

The bitwise engine must keep LIGGGHTS' and LAMMPS' bits (docs/dem.md), so its vectorised loop is
held to equality, not to round-off: against the generic scalar loop (``_serial_loop``, the loop of
every other law and of the sheared cell), and its branch-free laws against the scalar laws
``hooke_history`` / ``hooke_history_lammps`` entry by entry. The stored-run cases
(tests/validation: biaxial-short, laws-short) check the engine against the codes themselves.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest

from gransim import Packing
from gransim.contacts.hooke import (
    hooke_history,
    hooke_history_lammps,
    hooke_select_lammps,
    hooke_select_liggghts,
)
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem import kernels as K

FLAVOURS = ("liggghts", "lammps")
FIXED = Loading(x=AxisControl("fixed"), y=AxisControl("fixed"))


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint8) if a.dtype != bool else a


def _assembly(seed=3, n_side=9):
    """A jittered, compressed periodic lattice (overlaps ~1e-2 d, pairs across both boundaries)."""
    rng = np.random.default_rng(seed)
    d = 1e-3
    L = n_side * d * 0.985
    g = (np.arange(n_side) + 0.5) * (L / n_side)
    x = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2) + rng.normal(0.0, 0.01 * d, (n_side**2, 2))
    r = 0.5 * d * rng.uniform(0.97, 1.03, n_side**2)
    return Packing(positions=x % L, radii=r, cell=np.diag([L, L]), density=2650.0)


def _engine(flavour, mu=0.5, kt=8e4, gamma_t=100.0, seed=3):
    p = _assembly(seed)
    rng = np.random.default_rng(seed + 1)
    s = DEMSettings(
        kn=1e5, kt=kt, gamma_n=200.0, gamma_t=gamma_t, mu=mu, dt=1e-6, skin=2e-5, flavour=flavour, mode="serial"
    )
    v = rng.normal(0.0, 0.05, (p.n, 2))
    w = rng.normal(0.0, 50.0, p.n)
    return DEMEngine(p, s, velocities=v, spins=w, threads=1), s


def _copy(t):
    return type(t)(*[a.copy() if isinstance(a, np.ndarray) else a for a in t])


def _both_loops(e, s, update, hist=None):
    nb = e.nb if hist is None else e.nb._replace(hist=hist)
    L = e.box_lengths
    p1, nb1, p2, nb2 = _copy(e.p), _copy(nb), _copy(e.p), _copy(nb)
    v1, v2 = np.zeros(4), np.zeros(4)
    r1 = K.forces(p1, nb1, e.law, L[0], L[1], s.dt, update, v1, True)
    r2 = K.forces_in(p2, nb2, e.law, K.OrthoImage(L[0], L[1]), s.dt, update, v2, True)
    return (p1, nb1, v1, r1), (p2, nb2, v2, r2)


def _assert_same(one, two):
    (p1, nb1, v1, r1), (p2, nb2, v2, r2) = one, two
    for name, a, b in (
        ("force", p1.f, p2.f),
        ("torque", p1.t, p2.t),
        ("spring", nb1.hist, nb2.hist),
        ("virial", v1, v2),
        ("cap flag", nb1.slide, nb2.slide),
        ("entry force", nb1.ef, nb2.ef),
    ):
        assert np.array_equal(_bits(a), _bits(b)), f"{name} differs from the scalar loop"
    assert r1 == r2


@pytest.mark.parametrize("flavour", FLAVOURS)
@pytest.mark.parametrize("update", [True, False])
def test_simd_loop_equals_the_scalar_loop_bit_for_bit(flavour, update):
    e, s = _engine(flavour)
    e.advance(FIXED, 150)  # springs built up, some contacts sliding, some pairs apart
    one, two = _both_loops(e, s, update)
    _assert_same(one, two)
    nb1 = one[1]
    touching = one[3][0]
    assert touching > 50 and 0 < nb1.slide.sum() < touching, "the case must hold sliding and sticking contacts"
    assert np.any(~nb1.both), "the case must hold pairs across the periodic boundary"


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_springs_of_pairs_apart_kept_or_zeroed_as_the_scalar_loop(flavour):
    # every list entry carries a spring, touching or not: LIGGGHTS keeps the springs of pairs
    # apart, LAMMPS zeroes them; both loops must agree on every entry
    e, s = _engine(flavour)
    e.advance(FIXED, 20)
    rng = np.random.default_rng(7)
    hist = rng.normal(0.0, 1e-6, e.nb.hist.shape)
    hist[::7] = 0.0  # zero springs (the cap's |xi| = 0 case when mu = 0)
    one, two = _both_loops(e, s, True, hist=hist)
    _assert_same(one, two)
    apart = ~np.isin(np.arange(hist.shape[0]), np.flatnonzero(np.any(one[1].ef != 0.0, axis=1)))
    assert apart.sum() > 10
    if flavour == "lammps":
        assert np.all(one[1].hist[apart] == 0.0)
    else:
        assert np.array_equal(one[1].hist[apart], hist[apart])


@pytest.mark.parametrize("flavour", FLAVOURS)
@pytest.mark.parametrize("mu,kt,gamma_t", [(0.0, 8e4, 100.0), (0.5, 0.0, 0.0)])
def test_simd_loop_equals_the_scalar_loop_without_friction_or_spring(flavour, mu, kt, gamma_t):
    # mu = 0: every loaded spring is capped to zero (signed zeros must match); kt = 0: no cap
    # (with gamma_t > 0 LAMMPS' cap divides by kt: nan in LAMMPS' arithmetic, in both loops)
    e, s = _engine(flavour, mu=mu, kt=kt, gamma_t=gamma_t)
    e.advance(FIXED, 60)
    _assert_same(*_both_loops(e, s, True))


def _random_pairs(rng, n):
    """Random pair states around contact: about half touching, some exactly at zero overlap."""
    ri = rng.uniform(0.4e-3, 0.6e-3, n)
    rj = rng.uniform(0.4e-3, 0.6e-3, n)
    dist = (ri + rj) * rng.uniform(0.97, 1.03, n)
    dist[::11] = ri[::11] + rj[::11]
    ang = rng.uniform(0.0, 2.0 * math.pi, n)
    delx, dely = dist * np.cos(ang), dist * np.sin(ang)
    v = rng.normal(0.0, 0.1, (n, 4))
    w = rng.normal(0.0, 100.0, (n, 2))
    m = rng.uniform(1e-6, 3e-6, (n, 2))
    sp = rng.normal(0.0, 3e-6, (n, 2))
    sp[::5] = 0.0
    return ri, rj, delx, dely, v, w, m, sp


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_branch_free_law_equals_the_scalar_law_entry_by_entry(flavour):
    scalar, select = (
        (hooke_history, hooke_select_liggghts) if flavour == "liggghts" else (hooke_history_lammps, hooke_select_lammps)
    )
    rng = np.random.default_rng(11)
    n = 400
    ri, rj, delx, dely, v, w, m, sp = _random_pairs(rng, n)
    seen = {"touch": 0, "slide": 0, "stick": 0}
    for law in ((1e5, 8e4, 200.0, 100.0, 0.5), (1e5, 8e4, 200.0, 100.0, 0.0), (1e5, 0.0, 0.0, 0.0, 0.3)):
        for update in (True, False):
            for k in range(n):
                rsq = delx[k] * delx[k] + dely[k] * dely[k]
                pair = (delx[k], dely[k], rsq, ri[k], rj[k], *v[k], *w[k], *m[k])
                args = (*pair, *law, 1e-6, sp[k, 0], sp[k, 1], update)
                t, fx, fy, ti, tj, s0, s1, sl, dn = select(*args)
                rad = ri[k] + rj[k]
                assert t == (1.0 if rsq < rad * rad else 0.0)
                assert np.float64(dn).tobytes() == np.float64(rad - math.sqrt(rsq)).tobytes()
                if t == 0.0:
                    expect = (sp[k, 0], sp[k, 1]) if flavour == "liggghts" else (0.0, 0.0)
                    assert np.array([s0, s1]).tobytes() == np.array(expect).tobytes()
                    continue
                ref = scalar(*args)
                got = (fx, fy, ti, tj, s0, s1)
                assert np.array(got).tobytes() == np.array(ref[:6]).tobytes(), (k, law, update, got, ref)
                assert (sl == 1.0) == ref[6]
                seen["touch"] += 1
                seen["slide" if ref[6] else "stick"] += 1
    assert min(seen.values()) > 100, seen


def test_simd_loop_is_compiled_to_simd_code():
    # the speed of the loop rests on LLVM vectorising the law (docs/performance.md); numba gives
    # up silently when the body changes shape (a bool array read, a 2D spring in the law loop, a
    # division inside a select's arm), so the compiled kernel is checked for packed square roots,
    # divisions and gathers. Compiled afresh (inspection is off for cached code).
    import numba

    from gransim._numba import JIT_OPTIONS

    flags = open("/proc/cpuinfo").read() if os.path.exists("/proc/cpuinfo") else ""
    if " avx2" not in flags:
        pytest.skip("no AVX2 on this CPU: the gathers need it")
    e, s = _engine("liggghts")
    k = numba.njit(**{**JIT_OPTIONS, "cache": False, "parallel": True})(K._serial_block_loop.py_func)
    p, nb, L = e.p, e.nb, e.box_lengths
    k(p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.a, nb.b, nb.sx, nb.sy, nb.both.view(np.uint8), nb.hist,
      nb.slide.view(np.uint8), nb.ef, e.law, L[0], L[1], s.dt, True, np.zeros(4), True, np.zeros(2))  # fmt: skip
    asm = k.inspect_asm(k.signatures[0])
    assert re.search(r"\bvsqrtpd\b", asm), "the pair law is not vectorised (no packed square root)"
    assert re.search(r"\bvdivpd\b", asm)
    assert re.search(r"\bvgather[dq]pd\b", asm), "the partners' loads are not gathers"


_SPIN_CHECK = r"""
import os, sys
import numpy as np
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem.lattice import lattice_packing

def cpu(tid):
    with open(f"/proc/self/task/{tid}/stat") as fh:
        f = fh.read().rsplit(")", 1)[1].split()
    return int(f[11]) + int(f[12])  # utime + stime, clock ticks

s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5, mode="serial")
e = DEMEngine(lattice_packing(30, 30), s)
fixed = Loading(x=AxisControl("fixed"), y=AxisControl("fixed"))
e.advance(fixed, 200)  # kernels loaded, OpenMP runtime started
main = os.getpid()
before = {t: cpu(t) for t in os.listdir("/proc/self/task")}
for _ in range(200):  # until the main thread has used about a second of CPU (100 ticks)
    e.advance(fixed, 2000)
    if cpu(main) - before[str(main)] >= 100:
        break
after = {t: cpu(t) for t in os.listdir("/proc/self/task")}
mine = after[str(main)] - before[str(main)]
others = sum(after[t] - before.get(t, 0) for t in after if t != str(main))
print(mine, others)
"""


def test_the_serial_engine_keeps_to_one_core(tmp_path):
    # the SIMD loop is a one-iteration parallel loop: on more than one numba thread, libgomp's
    # default wait policy lets the idle thread spin beside every step, a second core burnt by a
    # serial run (found in a validation run beside the codes' jobs). Checked in a fresh
    # interpreter with libgomp's defaults (no OMP_WAIT_POLICY), on 2 numba threads.
    import subprocess
    import sys

    if not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2:
        pytest.skip("needs /proc and two cores")
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    env["NUMBA_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", _SPIN_CHECK], capture_output=True, text=True, env=env, check=True)
    mine, others = (int(v) for v in out.stdout.split()[-2:])
    assert mine >= 100, f"the run was too short to judge ({mine} ticks)"
    assert others < 0.2 * mine, f"other threads used {others} clock ticks beside the main thread's {mine}"


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_the_hooke_laws_take_the_simd_loop_and_the_others_the_generic_one(flavour):
    # the equality tests above compare kernels.forces with the generic loop: they would also pass if
    # the dispatch fell back to the generic loop for Hooke, so the compiled code of forces is read
    import numba

    from gransim._numba import JIT_OPTIONS
    from gransim.contacts.laws import law_spec, make_law

    e, s = _engine(flavour)
    L = e.box_lengths
    other = make_law("hertz-liggghts", youngs_modulus=5e8, poisson_ratio=0.3, restitution=0.5, friction=0.5)
    for law, simd in ((e.law, True), (other, False)):
        k = numba.njit(**{**JIT_OPTIONS, "cache": False})(K.forces.py_func)
        nb = e.nb if simd else e.nb._replace(hist=np.zeros((e.nb.a.shape[0], law_spec(other).width)))
        k(_copy(e.p), _copy(nb), law, L[0], L[1], s.dt, True, np.zeros(4), True)
        ir = k.inspect_llvm(k.signatures[0])
        assert ("_serial_block_loop" in ir) == simd, f"{type(law).__name__}: SIMD loop {'missing' if simd else 'used'}"
