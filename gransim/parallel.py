"""One executor for the Gauss points of the FE2 slope, the RVE studies and sweeps: in process or Dask.

``make_executor()`` (in process, the default), ``make_executor(workers=N)`` (a ``dask.distributed``
LocalCluster of N worker processes, one thread each, no dashboard, its HTTP routes on a free local port) or
``make_executor(scheduler="tcp://host:port")`` (an existing cluster). Every executor offers

* ``map(fn, items)``: stateless tasks, results in the order of ``items`` (``gransim rve-study``,
  sweeps);
* ``material(material, n_gauss)``: the material evaluated per Newton iteration at the G Gauss
  points. In process this is the material itself. On a cluster it is a
  :class:`DistributedMaterial`: the Gauss points are cut into contiguous blocks, one per worker,
  and each block lives in a ``distributed`` Actor that owns its part of the material and its
  Gauss-point history (the relaxed RVE's fluctuations never leave the worker). Per iteration only
  F goes in and the material response (P, A, and the small per-point sigma, W, contact count)
  comes back; ``commit`` / ``revert`` are forwarded to every block.

Bitwise reproducibility. The response at a Gauss point depends only on its own F and its own
committed history: the Taylor kernel sums the active contacts of a candidate set in the set's
order, and :class:`gransim.rve.TaylorMaterial` sorts every set by (i, j, image) whatever F it was
built at, so any valid candidate set gives the same bits; the relaxed RVE warm-starts each point
from its own trial or committed state. So the result is the same, bit for bit, for any number of
workers and any block cut (tests/fem/test_parallel.py checks in process against a 2-worker
LocalCluster).

A lost worker. The driver keeps the F of every evaluation since the first one (G x 4 floats
each, only for a material with history): per commit the evaluations of the committed attempt, and
those since the last commit or revert. When a block's worker is lost (the Actor's calls fail), the
block is rebuilt on a live worker from its pristine copy and the history is replayed (per commit:
evaluate at each of its F, commit; then the pending evaluations): the relaxed state depends only
on the previous committed state and the F evaluated since (each evaluation warm-starts from the
previous trial; from the committed state, the default, only on the committed F, and then only
that is replayed), so the replay restores it exactly; then the interrupted call is repeated. The
checkpoint of a slope run (:mod:`gransim.fem.checkpoint`) restores the history the same way.
"""

from __future__ import annotations

import itertools
import logging
import os
import time

import numpy as np

from .errors import GransimError, InputError

#: seconds to wait for a worker to come back after a loss before giving up
RECOVERY_TIMEOUT = 300.0
#: most recoveries of one call before the error is raised
MAX_RECOVERIES = 3


class ExecutorError(GransimError):
    """The cluster cannot run the work (no worker came back after a loss, scheduler gone)."""


def split_material(material, index: np.ndarray):
    """The part of ``material`` that evaluates the Gauss points ``index`` (K,) int.

    A material with one RVE index per Gauss point (``rve_index`` and ``material``, e.g.
    :class:`gransim.fem.materials.AssignedRVEs`) gets the slice of its index; any other batched
    material evaluates any number of points and is returned as it is (it is copied to its worker).
    """
    ri = getattr(material, "rve_index", None)
    inner = getattr(material, "material", None)
    if ri is not None and inner is not None:
        return type(material)(inner, np.asarray(ri)[index])
    return material


def _history(material, action: str, *args):
    fn = getattr(material, action, None)
    return fn(*args) if callable(fn) else None


class GaussBlock:
    """A block of Gauss points on a worker (a ``distributed`` Actor): its material and its history."""

    def __init__(self, material):
        self.material = material

    def evaluate(self, F):
        """(piola, tangent, cauchy, energy, n_contacts) of the block's F (K, 2, 2)."""
        b = self.material.evaluate(F)
        return (
            np.asarray(b.piola),
            np.asarray(b.tangent),
            np.asarray(b.cauchy),
            np.asarray(b.energy),
            np.asarray(b.n_contacts),
        )

    def commit(self) -> None:
        """Commit the block's trial history."""
        _history(self.material, "commit")

    def revert(self) -> None:
        """Drop the block's trial history."""
        _history(self.material, "revert")

    def committed_fluctuation(self, g: int):
        """Committed fluctuation of local Gauss point g (None for a history-free material)."""
        return _history(self.material, "committed_fluctuation", int(g))

    def pid(self) -> int:
        """The worker's process id (tests use it to kill the worker)."""
        return os.getpid()


class BatchResult:
    """The response assembled from the blocks (fields as :class:`gransim.fem.materials.MaterialResult`)."""

    __slots__ = ("cauchy", "energy", "n_contacts", "piola", "tangent")

    def __init__(self, piola, tangent, cauchy, energy, n_contacts):
        self.piola, self.tangent, self.cauchy, self.energy, self.n_contacts = (
            piola,
            tangent,
            cauchy,
            energy,
            n_contacts,
        )


class DistributedMaterial:
    """A batched material whose Gauss points live in Actors on a Dask cluster (module docstring).

    Parameters
    ----------
    material : the batched material (``evaluate(F)``, optional ``commit`` / ``revert``)
    executor : :class:`DaskExecutor`
    n_gauss : int, the number G of Gauss points every ``evaluate`` receives
    n_blocks : int, default the number of workers
    """

    def __init__(self, material, executor: DaskExecutor, n_gauss: int, n_blocks: int | None = None):
        self.template = material
        self.executor = executor
        self.n_gauss = int(n_gauss)
        nb = max(1, min(int(n_blocks or executor.n_workers), self.n_gauss))
        edges = np.linspace(0, self.n_gauss, nb + 1).round().astype(int)
        self.index = [np.arange(a, b) for a, b in itertools.pairwise(edges)]
        self.starts = edges[:-1]
        self._blocks = [split_material(material, ix) for ix in self.index]
        inner = getattr(material, "material", material)
        self.has_history = callable(getattr(inner, "commit", None))
        # a material started from its committed state (the relaxed RVE's default) depends on the
        # committed F alone: its replay skips the other evaluations
        self._replay_every = getattr(inner, "warm_start", "trial") != "committed"
        # per commit the F (G, 2, 2) of every evaluation of its attempt; the evaluations since the
        # last commit or revert (materials with history; the replay of a recovery)
        self._log: list[list[np.ndarray]] = []
        self._pending: list[np.ndarray] = []
        self.recoveries = 0
        workers = executor.workers()
        self._actors = [self._spawn(i, workers[i % len(workers)]) for i in range(nb)]

    # -- the material protocol ----------------------------------------------------------------
    @property
    def packings(self):
        """The RVEs' reference packings (of the template)."""
        return self.template.packings

    @property
    def normal_stiffness(self):
        """kn of the RVE contact law (of the template)."""
        return self.template.normal_stiffness

    @property
    def rve_index(self):
        """RVE index per Gauss point, or None."""
        return getattr(self.template, "rve_index", None)

    def evaluate(self, F) -> BatchResult:
        """The response at all G Gauss points, each block on its worker."""
        F = np.ascontiguousarray(F, dtype=float)
        if F.shape != (self.n_gauss, 2, 2):
            raise InputError(f"F: expected shape ({self.n_gauss}, 2, 2) (the distributed Gauss points), got {F.shape}")
        parts = self._call_all("evaluate", [F[ix] for ix in self.index])
        if self.has_history:
            self._pending.append(F.copy())
        return BatchResult(*(np.concatenate([p[k] for p in parts]) for k in range(5)))

    def commit(self) -> None:
        """Commit every block's trial history (and log the committed F for a recovery)."""
        if self.has_history and not self._pending:
            raise InputError("commit: no trial state (call evaluate first, or it was reverted)")
        self._call_all("commit", [() for _ in self.index], star=True)
        if self.has_history:
            self._log.append(self._pending)
        self._pending = []

    def revert(self) -> None:
        """Drop every block's trial history."""
        self._pending = []
        self._call_all("revert", [() for _ in self.index], star=True)

    def committed_fluctuation(self, g: int):
        """The committed fluctuation of Gauss point g from its worker (None for Taylor)."""
        g = int(g)
        i = int(np.searchsorted(self.starts, g, side="right") - 1)
        return self._call(i, "committed_fluctuation", (g - int(self.starts[i]),))

    def close(self) -> None:
        """Release the Actors."""
        self._actors = []

    # -- machinery ----------------------------------------------------------------------------
    def _spawn(self, i: int, worker: str | None = None):
        kw = {"workers": [worker]} if worker else {}
        fut = self.executor.client.submit(GaussBlock, self._blocks[i], actor=True, pure=False, **kw)
        return fut.result()

    def _call_all(self, method: str, args: list, star: bool = False):
        futs = [getattr(a, method)(*(x if star else (x,))) for a, x in zip(self._actors, args)]
        out = []
        for i, (f, x) in enumerate(zip(futs, args)):
            try:
                out.append(f.result())
            except Exception as exc:
                if not self._lost(i, exc):
                    raise
                out.append(self._recover_and_call(i, method, x if star else (x,)))
        return out

    def _call(self, i: int, method: str, args: tuple):
        try:
            return getattr(self._actors[i], method)(*args).result()
        except Exception as exc:
            if not self._lost(i, exc):
                raise
            return self._recover_and_call(i, method, args)

    def _lost(self, i: int, exc: Exception) -> bool:
        """True when block i's worker is gone (the Actor's calls fail), not a material error."""
        if isinstance(exc, GransimError):
            return False
        try:
            from distributed.comm.core import CommClosedError  # noqa: PLC0415 - start-up: distributed (~1 s)
        except ImportError:  # pragma: no cover
            CommClosedError = OSError
        if isinstance(exc, (OSError, CommClosedError)) or "Actor was lost" in str(exc):
            return True
        addr = getattr(self._actors[i], "_address", None)
        return addr is not None and addr not in self.executor.workers()

    def _recover_and_call(self, i: int, method: str, args: tuple):
        for attempt in range(MAX_RECOVERIES):
            self.executor.wait_for_workers(1, RECOVERY_TIMEOUT)
            try:
                self._actors[i] = self._spawn(i)
                self.recoveries += 1
                ix = self.index[i]
                a = self._actors[i]
                for seq in self._log:  # replay the committed history (module docstring)
                    for Fc in seq if self._replay_every else seq[-1:]:
                        a.evaluate(Fc[ix]).result()
                    a.commit().result()
                for Fc in self._pending if self._replay_every else []:  # the current attempt's trial
                    a.evaluate(Fc[ix]).result()
                return getattr(a, method)(*args).result()
            except Exception as exc:
                if attempt == MAX_RECOVERIES - 1 or not self._lost(i, exc):
                    raise
        raise ExecutorError(f"Gauss-point block {i}: no worker could take it over")  # pragma: no cover


class InProcess:
    """The default executor: everything in this process."""

    kind = "in-process"
    n_workers = 1

    def map(self, fn, items) -> list:
        """``[fn(x) for x in items]``."""
        return [fn(x) for x in items]

    def material(self, material, n_gauss: int | None = None):
        """The material itself (evaluated here)."""
        return material

    def describe(self) -> str:
        """One line for reports."""
        return "in process"

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class DaskExecutor:
    """A ``dask.distributed`` client: a LocalCluster of ``workers`` processes or ``scheduler``'s cluster."""

    kind = "dask"

    def __init__(self, workers: int | None = None, scheduler: str | None = None, timeout: float = 30.0):
        from distributed import Client, LocalCluster  # noqa: PLC0415 - start-up: distributed (~1 s)

        self.cluster = None
        if scheduler is not None:
            try:
                self.client = Client(scheduler, timeout=timeout)
            except (OSError, TimeoutError) as exc:
                raise InputError(f"--scheduler: cannot reach a Dask scheduler at {scheduler!r} ({exc})") from None
        else:
            # the scheduler's HTTP server (health and metrics routes; no dashboard without bokeh)
            # listens even with dashboard_address=None, on 8787 unless told: a free local port
            # instead, so that another Dask cluster on this machine neither clashes nor makes a warning
            self.cluster = LocalCluster(
                n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0"
            )
            self.client = Client(self.cluster)
            self.client.wait_for_workers(int(workers), timeout=timeout)
        self.scheduler = scheduler

    def workers(self) -> list[str]:
        """Addresses of the live workers, sorted."""
        return sorted(self.client.scheduler_info()["workers"])

    @property
    def n_workers(self) -> int:
        """Number of live workers."""
        return len(self.workers())

    def wait_for_workers(self, n: int, timeout: float) -> None:
        """Block until ``n`` workers are up (a lost LocalCluster worker is restarted by its nanny)."""
        t0 = time.monotonic()
        while self.n_workers < n:
            if time.monotonic() - t0 > timeout:
                raise ExecutorError(f"no Dask worker available after {timeout:.0f} s")
            time.sleep(0.1)

    def map(self, fn, items) -> list:
        """``fn`` on every item on the cluster; results in the order of ``items``."""
        items = list(items)
        return self.client.gather(self.client.map(fn, items, pure=False))

    def material(self, material, n_gauss: int):
        """A :class:`DistributedMaterial` of ``material`` at ``n_gauss`` Gauss points."""
        return DistributedMaterial(material, self, n_gauss)

    def describe(self) -> str:
        """One line for reports."""
        where = self.scheduler or "a LocalCluster"
        return f"Dask, {self.n_workers} workers on {where}"

    def close(self) -> None:
        """Close the client and (when this executor started it) the LocalCluster.

        The cluster's own processes are silenced first (the ``distributed`` loggers of the workers
        and of this process to CRITICAL): the work is done or checkpointed, and ``distributed``
        (2026.8) logs races of its own shutdown as errors with a traceback on the inherited stderr,
        e.g. a worker's heartbeat in flight while its connection pool closes ("Failed to
        communicate with scheduler during heartbeat", worker.py ``heartbeat``). The levels of this
        process are put back afterwards. An error of the close itself still raises. An existing
        cluster (``--scheduler``) is left as it is."""
        if self.cluster is None:
            self.client.close()
            return
        try:
            self.client.run(_silence_distributed, on_error="ignore")
        except Exception:  # noqa: BLE001 - a worker already gone is closed below all the same
            pass
        levels = _silence_distributed()
        try:
            self.client.close()
            self.cluster.close()
        finally:
            for name, level in levels.items():
                logging.getLogger(name).setLevel(level)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _silence_distributed() -> dict:
    """Set every ``distributed`` logger of this process to CRITICAL (see :meth:`DaskExecutor.close`):
    the package's and each of its modules' (its logging configuration gives some their own level).
    Returns their levels before ({name: level})."""
    names = {"distributed", *(n for n in logging.root.manager.loggerDict if n.startswith("distributed."))}
    levels = {name: logging.getLogger(name).level for name in names}
    for name in names:
        logging.getLogger(name).setLevel(logging.CRITICAL)
    return levels


def make_executor(workers=None, scheduler: str | None = None):
    """The executor of the options: none (in process), ``--workers N`` or ``--scheduler ADDRESS``."""
    if workers is not None and scheduler is not None:
        raise InputError(
            "--workers and --scheduler: give one of them (a LocalCluster of N workers, or an "
            "existing cluster's scheduler address)"
        )
    if scheduler is not None:
        if not isinstance(scheduler, str) or "://" not in scheduler and ":" not in scheduler:
            raise InputError(f"--scheduler: expected a scheduler address such as tcp://host:8786, got {scheduler!r}")
        return DaskExecutor(scheduler=scheduler)
    if workers is None:
        return InProcess()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise InputError(f"--workers: expected an integer >= 1 (Dask worker processes), got {workers!r}")
    return DaskExecutor(workers=int(workers))


def add_options(parser) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` on a command's parser."""
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="evaluate on a dask.distributed LocalCluster of N worker processes (one thread each); default: in process",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="evaluate on an existing Dask cluster (e.g. tcp://host:8786)",
    )


__all__ = [
    "DaskExecutor",
    "DistributedMaterial",
    "ExecutorError",
    "GaussBlock",
    "InProcess",
    "add_options",
    "make_executor",
    "split_material",
]
