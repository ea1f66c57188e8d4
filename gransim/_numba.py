"""All numba settings of gransim, in one place.

Every kernel in the package is compiled through :func:`njit` (serial) or
:func:`pjit` (``parallel=True``, for loops written with :data:`prange`).

* ``cache=True``: compiled machine code is kept on disk (``NUMBA_CACHE_DIR``),
  so only the first run after a change pays the compile time.
* One cache for every way gransim is run (``make``, ``.venv/bin/gransim``, ``python -c "import
  gransim"``, Dask workers): when ``NUMBA_CACHE_DIR`` is not set, ``import gransim`` sets it,
  before gransim imports numba, to ``sys.prefix/numba-cache`` inside a writable virtual
  environment (the checkout's ``.venv/numba-cache``, which ``make`` exports too), else to
  ``$XDG_CACHE_HOME/gransim/numba`` (default ``~/.cache/gransim/numba``); child processes inherit
  it. A value the user set, even an empty one (numba's own default: ``__pycache__`` beside the
  sources), is kept. When numba was imported before gransim, numba has already read its
  environment: gransim then also sets ``numba.config.CACHE_DIR``, which every kernel decorated
  afterwards (all of gransim's) uses; the user's own kernels decorated before ``import gransim``
  keep numba's default. ``make`` fills the cache for every command (``gransim warmup``,
  docs/startup.md).
* ``fastmath=False``: floating point follows IEEE order exactly. The DEM engine
  is compared with LIGGGHTS and LAMMPS bit for bit, which re-association would break.
* ``error_model="numpy"``: division by zero gives inf/nan instead of raising
  inside a kernel; the Python boundary checks results.

* Idle OpenMP threads spin briefly, then sleep: ``import gransim`` sets ``GOMP_SPINCOUNT`` to
  :data:`SPIN_COUNT` (~10 us by libgomp's estimate of 1e5 spins per ms) unless the user set
  ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT``. libgomp's default (300,000 spins, ~3 ms) burns the
  time slice a descheduled partner needs when another process holds a core: 2 threads then ran
  the fast DEM path at 0.57x of one thread (1e5 disks). Sleeping at once (``PASSIVE``) costs a
  wake-up (~40 us on this VM) for each of a DEM step's three parallel regions. Measured at 1e5
  disks, 2 threads / 1 thread, quiet and with one core held by a spinning process: PASSIVE 1.69-1.71x
  and 0.91-0.94x; 1000 spins 1.78-1.83x and 0.93-0.94x; 3000 spins 1.83x and 0.86x
  (docs/performance.md).
* Threading layer: OpenMP first, then TBB, then numba's workqueue (``NUMBA_THREADING_LAYER``
  overrides). Launching a ``prange`` loop costs ~4x less time with OpenMP than with TBB (18 against
  82 us measured here), which is what a threaded DEM step of a small assembly pays many times.
  The layer does not change results: the threaded kernels sum in a fixed order.

* Unpacked arrays. Kernels take small namedtuples of arrays (``gransim.dem.kernels.Particles``,
  ``Neighbours``, ``Box``, ...) and a law object, except where numba makes the arrays arguments
  of their own. Two limitations of numba (0.68) do, both in ``parallel=True`` kernels:

  - vectorisation: numba marks the array *arguments* of a parallel loop body ``noalias`` only
    when it finds no alias among them; an array taken out of a namedtuple, an array passed through
    an ``inline="always"`` function, or a bool array that is read counts as a possible alias, and
    LLVM then keeps the loop scalar (no packed square roots, no gathers; read in the compiled
    code by tests/dem/test_simd_bitwise.py, test_threaded_bitwise.py and test_fast.py). The bool
    arrays go in as uint8 views, the history in two contiguous block buffers (a stride-2 pair of
    loads is not vectorised either);
  - a wrong result: with the arrays taken out of the namedtuples inside the threaded
    entry-by-entry force loop, numba returned torques on the second particle 1e-5 N m off the
    serial loop and the interpreted kernel (measured; presumably its parfor pass fusing the loop's
    ``prange`` regions); as arguments the result is right.

  So the force loops ``kernels._serial_block_loop``, ``_threaded_block_loop``,
  ``_threaded_scalar_loop`` and the fast path's ``fast_kernels.forces_v``, ``integrate_v`` take
  unpacked arrays, and a thin wrapper beside each (``kernels._serial_blocks``, ...) unpacks the
  tuples at the call.

Set ``NUMBA_DISABLE_JIT=1`` to run the kernels as plain Python (coverage,
debugging); the test suite is expected to pass in that mode too (slowly).
"""

from __future__ import annotations

import contextlib
import os

import numba
from numba.core import caching

from ._validate import as_int

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

#: libgomp's spin count before an idle thread sleeps, set at import unless the user chose a policy
SPIN_COUNT = "1000"
#: True when gransim set GOMP_SPINCOUNT (libgomp reads it when numba first loads its OpenMP layer,
#: at the first parallel kernel: importing numba does not)
_SPIN_SET = "OMP_WAIT_POLICY" not in os.environ and "GOMP_SPINCOUNT" not in os.environ
if _SPIN_SET:
    os.environ["GOMP_SPINCOUNT"] = SPIN_COUNT

JIT_OPTIONS = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}

prange = numba.prange


def njit(*args, **kwargs):
    """Serial ``numba.njit`` with the package-wide options (usable bare or with arguments)."""
    opts = {**JIT_OPTIONS, **kwargs}
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


def pjit(*args, **kwargs):
    """``numba.njit(parallel=True)`` with the package-wide options."""
    opts = {**JIT_OPTIONS, "parallel": True, **kwargs}
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


@contextlib.contextmanager
def disk_cache_off(off: bool = True):
    """Compilations inside the block are not written to numba's disk cache (``off`` False: no-op).

    For kernels specialised on a type that another process may not be able to import (a contact
    law defined in a test module or a script, ``register_law(..., cache=False)``): numba's cache
    index of a kernel lists every signature compiled into it and is unpickled as a whole by each
    process that loads the kernel, so one such type in it would make every other process fail
    (ModuleNotFoundError in ``numba/core/caching.py`` ``_load_index``; measured). Loading what
    is cached still works inside the block.
    """
    if not off:
        yield
        return

    orig = caching.Cache.save_overload
    caching.Cache.save_overload = lambda self, sig, data: None
    try:
        yield
    finally:
        caching.Cache.save_overload = orig


def wait_passively() -> None:
    """Let idle OpenMP threads sleep instead of spinning (``OMP_WAIT_POLICY=PASSIVE``, unless the
    user set a policy), for commands whose parallel kernels are few and long (``gransim slope``).

    libgomp's default lets a thread that waits (for the next parallel region, or at a region's
    end for a partner that the OS has not scheduled yet) spin for up to ~300,000 iterations. On a
    loaded machine that burns CPU that other work, including this process's own serial code, needs:
    ``find_neighbours`` on 700 disks took 41 ms of CPU and 94 ms wall at load 12 with spinning,
    0.65 ms and 0.8 ms sleeping; the whole ``gransim slope --protocol paper`` 7.6-8.3 s of CPU
    against 5.5-5.8 s (interleaved, load 12-14). A sleeping thread costs a futex wake-up (tens of
    microseconds) per parallel region, nothing against a slope kernel call of 10 ms or more. The
    DEM launches many short regions per step and keeps libgomp's default.

    Takes effect only before the OpenMP runtime starts (numba starts it at the first parallel
    kernel or ``numba.set_num_threads``); child processes (Dask workers) inherit it. Results do not
    depend on it (every state is summed by one thread in a fixed order).
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    if _SPIN_SET and os.environ.get("GOMP_SPINCOUNT") == SPIN_COUNT:
        del os.environ["GOMP_SPINCOUNT"]  # the spin count would take precedence over the policy


def set_num_threads(n: int | None) -> None:
    """Set the number of numba threads (``None`` leaves the default: all cores)."""
    if n is not None:
        numba.set_num_threads(int(n))


@contextlib.contextmanager
def num_threads(n: int | None):
    """Run the enclosed kernels on ``n`` numba threads and restore the previous count afterwards
    (``None``: leave it). Numba's count is per calling thread and sticky; this keeps one
    object's choice from leaking into the next computation."""
    if n is None:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(int(n))
    try:
        yield
    finally:
        numba.set_num_threads(old)


@contextlib.contextmanager
def dynamic_chunks(size: int = 1):
    """numba's parallel loops inside the block hand out their iterations dynamically in chunks of
    ``size`` (numba >= 0.57 ``set_parallel_chunksize``; 0 restores static scheduling). Loops run
    so are written over tasks of many particles (a thread descheduled by another process then
    holds back one task, not a fixed share of the loop)."""
    old = numba.get_parallel_chunksize()
    numba.set_parallel_chunksize(int(size))
    try:
        yield
    finally:
        numba.set_parallel_chunksize(old)


def check_threads(n, name: str = "threads") -> int | None:
    """``None`` or an integer in [1, NUMBA_NUM_THREADS]; :class:`InputError` otherwise."""
    if n is None:
        return None

    return as_int(n, name, 1, numba.config.NUMBA_NUM_THREADS, " (NUMBA_NUM_THREADS)")
