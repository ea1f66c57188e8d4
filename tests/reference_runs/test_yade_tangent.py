"""The material part of gransim's Taylor tangent against YADE's ``getStressAndTangent`` tangent.

gransim (gransim.rve.taylor): A_iJkL = dP_iJ/dF_kL = 1/V sum [a n_i n_k + b delta_ik] L_J L_L with,
for the linear law, a = kn (r_i + r_j)/d = kn + kn eps/d and b = -kn eps/d. YADE (docs/yade.md,
Kruyt and Rothenburg): D = 1/v sum kn sym(n (x) l) sym(n (x) l) in the current configuration
(v = det hSize, the 3D volume; Voigt xx, yy, zz, yz, xz, xy, tensor shear components; ks = 0 here).
So with K_iJkL = A_iJkL - 1/V sum (kn eps/d)(n_i n_k - delta_ik) L_J L_L = 1/V sum kn n_i n_k L_J L_L
(the contacts' eps, d, n, L from the independent numpy Taylor stress), the push-forward
k_ijkl = F_jJ F_lL K_iJkL / det F = 1/(det F V) sum kn n_i l_j n_k l_l, symmetrised in (i, j) and
(k, l), must be z D (YADE sums the upper triangle of D only and leaves the lower one zero;
docs/yade.md). Tolerance 1e-12 of max |z D|: the correction is ~1e-2 of A, and A, the
correction and the push-forward each round at a few eps times sums of ~200 terms (measured worst
2.0e-15 on the 48-, 64- and 120-disk demo packings; without the eps/d correction the two differ by
5%).
"""

import shutil

import numpy as np
import pytest

from gransim.paper import KN_2D
from gransim.rve.taylor import material_for
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.taylor_numpy import taylor_stress_numpy
from reference_runs.yade.taylor import run_yade_taylor

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
VOIGT_2D = ((0, 0), (1, 1), (0, 1))  # YADE's Voigt rows 0, 1, 5
ROWS = (0, 1, 5)
TANGENT_RTOL = 1e-12


def _pushed_material_part(packing, F, A):
    ref = taylor_stress_numpy(packing, F, KN_2D)
    V = abs(np.linalg.det(packing.cell))
    d = np.linalg.norm(ref.branch, axis=1)
    n = ref.branch / d[:, None]
    L = np.linalg.solve(F, ref.branch.T).T
    w = KN_2D * ref.overlap / d
    nn_minus_I = n[:, :, None] * n[:, None, :] - np.eye(2)[None]
    G = np.einsum("c,cik,cJ,cL->iJkL", w, nn_minus_I, L, L) / V
    K = A - G
    return np.einsum("jJ,lL,iJkL->ijkl", F, F, K) / np.linalg.det(F)


def test_yade_tangent_is_the_pushed_forward_material_part_of_gransims(tmp_path):
    packing = perturbed_lattice(8, 8, seed=3)
    run = run_yade_taylor(packing, KN_2D, tmp_path / "job", n_steps=4)
    mat = material_for(packing, KN_2D)
    for t, F in enumerate(run.F):
        where = f"state {t} ({run.states[t]['path']}, k = {run.states[t]['k']})"
        D = run.tangent[t]  # z times YADE's 6 x 6 tangent (N/m)
        others = [a for a in range(6) if a not in ROWS]
        assert not D[others].any() and not D[:, others].any(), where  # no z components for disks
        k = _pushed_material_part(packing, F, mat(F).tangent)
        want = np.array(
            [
                [0.25 * (k[i, j, p, q] + k[j, i, p, q] + k[i, j, q, p] + k[j, i, q, p]) for (p, q) in VOIGT_2D]
                for (i, j) in VOIGT_2D
            ]
        )
        got = D[np.ix_(ROWS, ROWS)]
        # YADE fills the upper triangle only (its ``symmetry`` argument is ignored): the lower is 0
        assert not got[np.tril_indices(3, -1)].any(), where
        upper = np.triu_indices(3)
        assert np.abs(got[upper] - want[upper]).max() <= TANGENT_RTOL * np.abs(got).max(), where
        assert np.allclose(want, want.T, rtol=1e-14, atol=0), where
