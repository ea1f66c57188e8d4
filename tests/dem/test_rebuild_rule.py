"""The neighbour-rebuild trigger of each code when the box moved more than the skin.

LIGGGHTS 3.8.0 (neighbor.cpp:1400-1401) squares delta = (skin - |d lo| - |d hi|)/2 even when it is
negative; LAMMPS 29Sep2021 (neighbor.cpp:2133-2135) clamps it to 0, so it rebuilds on any motion.
"""

import numpy as np

from gransim.dem import kernels as K


def _case(disp):
    x = np.array([[0.5, 0.5], [1.0, 1.0]])
    xhold = x.copy()
    x[0, 0] += disp
    lo, hi = np.zeros(2), np.array([2.0, 2.0])
    lo_hold, hi_hold = lo.copy(), np.array([2.0 - 0.3, 2.0])  # the box grew by 0.3 since the build
    return x, xhold, lo, hi, lo_hold, hi_hold


def test_box_moved_more_than_the_skin():
    skin = 0.1  # delta = (0.1 - 0.3)/2 = -0.1
    x, xh, lo, hi, loh, hih = _case(0.05)  # a particle moved less than |delta|
    assert K.check_rebuild(x, xh, lo, hi, loh, hih, skin, True) == (True, -1)  # LAMMPS: rebuild
    assert K.check_rebuild(x, xh, lo, hi, loh, hih, skin, False) == (False, -1)  # LIGGGHTS: not
    x, xh, lo, hi, loh, hih = _case(0.15)  # beyond |delta|: both rebuild
    assert K.check_rebuild(x, xh, lo, hi, loh, hih, skin, False) == (True, -1)


def test_inside_the_skin_both_rules_agree():
    skin = 1.0  # delta = (1 - 0.3)/2 = 0.35
    for disp, want in ((0.3, False), (0.4, True)):
        x, xh, lo, hi, loh, hih = _case(disp)
        for clamp in (True, False):
            assert K.check_rebuild(x, xh, lo, hi, loh, hih, skin, clamp) == (want, -1)
