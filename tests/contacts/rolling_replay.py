"""Test-local two-disk integrator for the rolling-resistance laws, in the codes' ``nve/sphere``
step order (as tests/contacts/hertz_replay.py: set-up force call without history update, then per
step v += dt/2 f/m, x += dt v, w += dt/2 T/I with I = m r^2/2, force call with the update,
v += dt/2 f/m, w += dt/2 T/I). Two disks, no periodic image in reach, no list rebuild
(reference_runs/decks/rolling.py): the pair is (id 1, id 2), d = x_1 - x_2. Plain Python floats
(the laws' ``py_func``), so nothing is compiled.

``fixed_centres=True`` holds both centres (and velocities) fixed and integrates the spins only:
the set-up of the rolling-decay benchmark (test_rolling.py).
"""

from __future__ import annotations

from gransim.contacts import rolling

FUNCS = {
    "epsd2": rolling.hooke_epsd2_liggghts,
    "epsd": rolling.hooke_epsd_liggghts,
    "cdt": rolling.hooke_cdt_liggghts,
    "sds": rolling.hooke_sds_granular_lammps,
}


def law_params(law: str, case: dict) -> tuple:
    """The law parameters of ``law`` for a case dict of reference_runs.decks.rolling."""
    c = case
    hooke = (c["kn"], c["kt"], c["gamman"], c["gammat"], c["friction"])
    if law == "epsd2" or law == "cdt":
        return hooke + (c["rolling_friction"],)
    if law == "epsd":
        return hooke + (c["rolling_friction"], c["rolling_viscous"])
    return (
        c["kn"],
        c["gamman"],
        rolling.DAMPING_MASS_VELOCITY,
        c["kt"],
        c["gammat"] / c["gamman"],
        c["friction"],
        c["kroll"],
        c["gammaroll"],
        c["rolling_friction"],
    )


def replay(
    law: str, case: dict, masses, jit: bool = False, fixed_centres: bool = False, params: tuple | None = None
) -> dict:
    """Run ``case`` with ``law``; {step: frame} for steps 0..nsteps (step 0: set-up forces); a
    frame holds x, y, vx, vy, omegaz, fx, fy, tqz ((2,) lists), the history ``h``, the flags
    ``sliding``, ``rolling``, the normal force ``fn`` and the rolling torque on i ``tr``."""
    fn = FUNCS[law]
    f = fn if jit else getattr(fn, "py_func", fn)
    params = law_params(law, case) if params is None else params
    width = rolling.HISTORY_WIDTH[law]
    r = list(case["radii"])
    m = list(masses)
    x = [list(p) for p in case["positions"]]
    v = [list(p) for p in case["velocities"]]
    w = list(case["spins"])
    dt = case["dt"]
    h = [0.0] * width
    info = {"sliding": False, "rolling": False, "fn": 0.0, "tr": 0.0}
    lammps = law == "sds"

    def forces(update):
        delx = x[0][0] - x[1][0]
        dely = x[0][1] - x[1][1]
        rsq = delx * delx + dely * dely
        F = [[0.0, 0.0], [0.0, 0.0]]
        T = [0.0, 0.0]
        info.update(sliding=False, rolling=False, fn=0.0, tr=0.0)
        radsum = r[0] + r[1]
        if rsq < radsum * radsum:
            out = f(
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
                *h,
                update,
            )
            h[:] = out[4 : 4 + width]
            info.update(sliding=out[4 + width], rolling=out[5 + width], fn=out[6 + width], tr=out[7 + width])
            F = [[out[0], out[1]], [-out[0], -out[1]]]
            T = [out[2], out[3]]
        elif lammps:  # LAMMPS zeroes the history of a listed pair that does not touch
            h[:] = [0.0] * width
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
            "h": list(h),
            **info,
        }

    F, T = forces(False)
    out = {0: frame(F, T)}
    dtf = 0.5 * dt
    dtfrot = dtf / 0.5
    for step in range(1, int(case["nsteps"]) + 1):
        for i in range(2):
            if not fixed_centres:
                dtfm = dtf / m[i]
                v[i][0] += dtfm * F[i][0]
                v[i][1] += dtfm * F[i][1]
                x[i][0] += dt * v[i][0]
                x[i][1] += dt * v[i][1]
            w[i] += dtfrot / (r[i] * r[i] * m[i]) * T[i]
        F, T = forces(True)
        for i in range(2):
            if not fixed_centres:
                dtfm = dtf / m[i]
                v[i][0] += dtfm * F[i][0]
                v[i][1] += dtfm * F[i][1]
            w[i] += dtfrot / (r[i] * r[i] * m[i]) * T[i]
        out[step] = frame(F, T)
    return out
