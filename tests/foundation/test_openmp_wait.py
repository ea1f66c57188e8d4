"""The OpenMP wait policy gransim sets at import (gransim/_numba.py): a short spin, then sleep.

Checked in fresh interpreters, since libgomp reads its environment once, when numba first loads
its OpenMP layer; and with libgomp itself: a parallel kernel runs under each setting."""

import os
import subprocess
import sys

import pytest

_PROBE = """
import os
import gransim._numba as nb
if {passive}:
    nb.wait_passively()
print(os.environ.get("OMP_WAIT_POLICY"), os.environ.get("GOMP_SPINCOUNT"))
"""


def _probe(passive=False, **env):
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    out = subprocess.run(
        [sys.executable, "-c", _PROBE.format(passive=passive)],
        capture_output=True,
        text=True,
        env={**base, **env},
        check=True,
    )
    return tuple(None if v == "None" else v for v in out.stdout.split())


def test_a_short_spin_unless_the_user_chose():
    from gransim._numba import SPIN_COUNT

    assert int(SPIN_COUNT) > 0
    assert _probe() == (None, SPIN_COUNT)  # nothing chosen: gransim's short spin
    assert _probe(OMP_WAIT_POLICY="ACTIVE") == ("ACTIVE", None)  # the user's policy, untouched
    assert _probe(GOMP_SPINCOUNT="7") == (None, "7")  # the user's spin count, untouched
    # the slope's passive waiting: the spin count gransim set would take precedence, so it goes
    assert _probe(passive=True) == ("PASSIVE", None)
    assert _probe(passive=True, GOMP_SPINCOUNT="7") == ("PASSIVE", "7")


_KERNEL = """
import numpy as np
import gransim._numba as nb
import numba

@nb.pjit(cache=False)
def f(a):
    s = 0.0
    for i in nb.prange(a.shape[0]):
        s += a[i]
    return s

nb.set_num_threads(2)
print(f(np.ones(100000)), numba.threading_layer())
"""


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two cores")
def test_openmp_accepts_the_spin_count():
    # a parallel kernel runs on two threads with gransim's setting (libgomp warns on a bad value)
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    base["NUMBA_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", _KERNEL], capture_output=True, text=True, env=base, check=True)
    assert out.stdout.split() == ["100000.0", "omp"]
    assert "libgomp" not in out.stderr
