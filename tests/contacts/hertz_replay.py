"""Test-local two-disk integrator for the Hertz laws: the codes' ``nve/sphere`` step order
(docs/dem.md "one step"; fix_nve_sphere.cpp of both codes, native ``gransim.dem.kernels``):
set-up force call without history update, then per step v += dt/2 f/m, x += dt v,
w += dt/2 T/I (I = m r^2/2), force call with the history update, v += dt/2 f/m, w += dt/2 T/I.
Two disks, no periodic image in reach and no list rebuild (reference_runs/decks/hertz.py), so
the pair is (i, j) = (id 1, id 2) with d = x_1 - x_2 throughout. Plain Python floats: the laws
are called through their ``py_func`` so that the replay runs without compiling anything.
"""

from __future__ import annotations

from gransim.contacts import hertz
from gransim.contacts.material import HertzLiggghts, HertzMaterialLammps


def law_call(law: str, case: dict):
    """(pair function, its law parameters) for ``law`` of reference_runs.decks.hertz.LAWS."""
    if law == "liggghts":
        p = HertzLiggghts(case["youngs_modulus"], case["poisson_ratio"], case["restitution"], case["friction"])
        return hertz.hertz_history_liggghts, p.coefficients()
    if law == "gran-hertz-history":
        return hertz.hertz_history_lammps, (case["kn"], case["kt"], case["gamman"], case["gammat"], case["friction"])
    p = HertzMaterialLammps(
        case["youngs_modulus"],
        case["poisson_ratio"],
        case["restitution"],
        case["friction"],
        gammat_ratio=case["gammat_ratio"],
        damping="tsuji",
    )
    return hertz.hertz_mindlin_granular_lammps, p.coefficients()


def replay(law: str, case: dict, masses, jit: bool = False) -> dict:
    """Run ``case`` with ``law``; returns {step: dict(x, y, vx, vy, omegaz, fx, fy, tqz) of
    (2,) lists} for steps 0..nsteps (step 0: the set-up forces). ``masses``: the code's
    masses as the code holds them (read from its dump; the test checks them against pi r^2 rho
    separately)."""
    fn, params = law_call(law, case)
    f = fn if jit else getattr(fn, "py_func", fn)  # NUMBA_DISABLE_JIT=1: already plain Python
    r = list(case["radii"])
    m = list(masses)
    x = [list(p) for p in case["positions"]]
    v = [list(p) for p in case["velocities"]]
    w = list(case["spins"])
    dt = case["dt"]
    s = [0.0, 0.0]
    slide = [False]
    lammps = law != "liggghts"

    def forces(update):
        delx = x[0][0] - x[1][0]
        dely = x[0][1] - x[1][1]
        rsq = delx * delx + dely * dely
        F = [[0.0, 0.0], [0.0, 0.0]]
        T = [0.0, 0.0]
        slide[0] = False
        radsum = r[0] + r[1]
        if rsq < radsum * radsum:
            fx, fy, ti, tj, s0, s1, sliding, _ = f(
                delx,
                dely,
                rsq,
                r[0],
                r[1],
                v[0][0],
                v[0][1],
                v[1][0],
                v[1][1],
                w[0],
                w[1],
                m[0],
                m[1],
                *params,
                dt,
                s[0],
                s[1],
                update,
            )
            s[0], s[1] = s0, s1
            slide[0] = sliding
            F = [[fx, fy], [-fx, -fy]]
            T = [ti, tj]
        elif lammps:  # LAMMPS zeroes the history of a listed pair that does not touch
            s[0] = s[1] = 0.0
        return F, T

    def frame(F, T):
        return {
            "x": [x[0][0], x[1][0]],
            "y": [x[0][1], x[1][1]],
            "vx": [v[0][0], v[1][0]],
            "vy": [v[0][1], v[1][1]],
            "omegaz": list(w),
            "fx": [F[0][0], F[1][0]],
            "fy": [F[0][1], F[1][1]],
            "tqz": list(T),
            "s": list(s),
            "sliding": slide[0],
        }

    F, T = forces(False)
    out = {0: frame(F, T)}
    dtf = 0.5 * dt
    dtfrot = dtf / 0.5
    for step in range(1, int(case["nsteps"]) + 1):
        for i in range(2):
            dtfm = dtf / m[i]
            v[i][0] += dtfm * F[i][0]
            v[i][1] += dtfm * F[i][1]
            x[i][0] += dt * v[i][0]
            x[i][1] += dt * v[i][1]
            w[i] += dtfrot / (r[i] * r[i] * m[i]) * T[i]
        F, T = forces(True)
        for i in range(2):
            dtfm = dtf / m[i]
            v[i][0] += dtfm * F[i][0]
            v[i][1] += dtfm * F[i][1]
            w[i] += dtfrot / (r[i] * r[i] * m[i]) * T[i]
        out[step] = frame(F, T)
    return out
