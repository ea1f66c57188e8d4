"""Gauss points that hold state: the material-point interface of the FEM x DEM macro problem.

A *point law* describes one Gauss point's material (a DEM RVE, or a continuum stand-in) through

* ``initial_state(g) -> state``: the state of Gauss point g (flat index ``e * G + g``) before the
  first load step, built where the point lives (on its Dask worker: a DEM state never travels);
* ``response(state) -> (stress (2, 2), tangent (2, 2, 2, 2))``: the Cauchy stress (Pa, tension
  positive) and tangent of a state as it stands (the predictor of the next step);
* ``update(f, state) -> (stress, tangent, new_state)``: the response after the load-step increment
  f = dx / dx_n (2, 2), the deformation gradient of the step relative to the last converged
  configuration x_n (f - 1 = grad_n du is Guo & Zhao's strain increment "D = grad(u)", applied to
  their RVE as a constant velocity gradient), with ``tangent[i, j, k, l] = d stress_ij / d f_kl``.
  ``update`` must not modify ``state``: it returns a new one;
* optionally ``observables(state) -> dict[str, float]`` (void ratio, rotation...) for the outputs;
* optionally ``commit_response(state, stress, tangent) -> (stress, tangent)``: the committed
  response of a state just committed (the next step's predictor), given the last iterate's
  (default: that one; :class:`gransim.fem.perturbation.PerturbationTangent` gives the tangent of
  the committed state itself).

Newton iterates start from the last converged state and never pollute it: each iterate calls
``update(f, committed_state)``; the new states are kept as the *trial* and become the committed
states only when the load step converges (:meth:`GaussPoints.commit`); a rejected iterate or
step drops them (:meth:`GaussPoints.revert`). The committed states' numpy arrays are made
read-only, so a law that writes into its input state fails at once instead of corrupting it.

Where the points live. :class:`GaussPoints` keeps them in this process; :class:`DaskGaussPoints`
cuts them into contiguous chunks, one ``distributed`` Actor per chunk (a :class:`GaussChunk` on a
worker: the law, the committed and the trial states). Per Newton iterate only f goes out and the
stress and tangent come back (32 bytes out, 160 bytes back per point); states stay on the workers
between iterations and steps and travel only when asked for (a checkpoint, :meth:`states`).
Both run the same :class:`GaussChunk` code per point, so the results are the same bits for any
number of chunks and workers, provided the law's result at a point depends on its own f and state
only (tests/fem/test_material_points.py checks it).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import time

import numpy as np

from ..errors import GransimError, InputError


class MaterialPointError(GransimError):
    """A point law failed at a Gauss point (an RVE that lost a particle, diverged...); names it."""

    def __init__(self, point: int, message: str):
        super().__init__(f"Gauss point {point}: {message}")
        self.point = int(point)
        self.reason = message

    def __reduce__(self):  # raised on a Dask worker, re-raised here: pickled with its own arguments
        return (type(self), (self.point, self.reason))


def freeze(state):
    """Make the numpy arrays inside ``state`` read-only (dataclasses, tuples, lists and dicts are
    searched); returns ``state``."""
    if isinstance(state, np.ndarray):
        state.flags.writeable = False
    elif dataclasses.is_dataclass(state) and not isinstance(state, type):
        for fld in dataclasses.fields(state):
            freeze(getattr(state, fld.name))
    elif isinstance(state, (tuple, list)):
        for s in state:
            freeze(s)
    elif isinstance(state, dict):
        for s in state.values():
            freeze(s)
    return state


def is_frozen(state) -> bool:
    """Whether every numpy array inside ``state`` is read-only (searched as :func:`freeze` does):
    a committed state, whose derived quantities a law may keep while it lives."""
    if isinstance(state, np.ndarray):
        return not state.flags.writeable
    if dataclasses.is_dataclass(state) and not isinstance(state, type):
        return all(is_frozen(getattr(state, fld.name)) for fld in dataclasses.fields(state))
    if isinstance(state, (tuple, list)):
        return all(is_frozen(s) for s in state)
    if isinstance(state, dict):
        return all(is_frozen(s) for s in state.values())
    return True


def _check_f(f, n: int) -> np.ndarray:
    f = np.ascontiguousarray(f, dtype=float)
    if f.shape != (n, 2, 2):
        raise InputError(f"f: expected the step's deformation gradients ({n}, 2, 2), got {f.shape}")
    return f


class GaussChunk:
    """A contiguous chunk of Gauss points ``indices`` (K,) with its law and states.

    Built on the process that keeps it (a Dask worker for :class:`DaskGaussPoints`): the initial
    states come from ``law.initial_state(g)`` there, unless ``states`` (K committed states, e.g.
    from a checkpoint) are given; their stress and tangent from ``law.response``, unless
    ``response`` (stress (K, 2, 2), tangent (K, 2, 2, 2, 2): the committed response of a
    checkpoint, which a resumed run's predictor needs to repeat the uninterrupted run's bits) is.
    """

    def __init__(self, law, indices, states=None, response=None):
        self.law = law
        self.indices = np.asarray(indices, dtype=np.int64)
        if states is None:
            states = [self._call(g, law.initial_state, int(g)) for g in self.indices]
        if len(states) != self.indices.size:
            raise InputError(
                f"states: expected {self.indices.size} (one per Gauss point of the chunk), got {len(states)}"
            )
        self.committed = [freeze(s) for s in states]
        self.trial = None
        self._trial_response = None
        self.law_s = 0.0  # seconds in law.update (the RVE calls), wall and CPU, and their number: timing()
        self.law_cpu_s = 0.0
        self.law_calls = 0
        if response is None:
            resp = [self._call(g, law.response, s) for g, s in zip(self.indices, self.committed)]
            response = ([r[0] for r in resp], [r[1] for r in resp])
        self.stress = np.array(response[0], dtype=float).reshape(-1, 2, 2)
        self.tangent = np.array(response[1], dtype=float).reshape(-1, 2, 2, 2, 2)

    @staticmethod
    def _call(g, fn, *args):
        try:
            return fn(*args)
        except MaterialPointError:
            raise
        except Exception as exc:  # the law's own error, named by the point where it happened
            raise MaterialPointError(int(g), f"{type(exc).__name__}: {exc}") from None

    def evaluate(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(stress (K, 2, 2), tangent (K, 2, 2, 2, 2)) after the increments f (K, 2, 2), each from
        its point's committed state; the new states are kept as the trial (replacing an older one)."""
        f = _check_f(f, self.indices.size)
        t0, c0 = time.perf_counter(), time.process_time()
        out = [self._call(g, self.law.update, f[k], self.committed[k]) for k, g in enumerate(self.indices)]
        self.law_s += time.perf_counter() - t0
        self.law_cpu_s += time.process_time() - c0
        self.law_calls += len(out)
        self.trial = [o[2] for o in out]
        stress = np.array([o[0] for o in out], dtype=float).reshape(-1, 2, 2)
        tangent = np.array([o[1] for o in out], dtype=float).reshape(-1, 2, 2, 2, 2)
        self._trial_response = (stress, tangent)
        return stress, tangent

    def commit(self) -> None:
        """The trial states become the committed ones (the load step converged)."""
        if self.trial is None:
            raise InputError("commit: no trial state (evaluate first; a reverted trial cannot be committed)")
        self.committed = [freeze(s) for s in self.trial]
        self.stress, self.tangent = self._trial_response
        self.trial = self._trial_response = None
        hook = getattr(self.law, "commit_response", None)
        if callable(hook):  # RVE calls too (the perturbation tangent): timed with the updates
            t0, c0 = time.perf_counter(), time.process_time()
            out = [
                self._call(g, hook, s, self.stress[k], self.tangent[k])
                for k, (g, s) in enumerate(zip(self.indices, self.committed))
            ]
            self.law_s += time.perf_counter() - t0
            self.law_cpu_s += time.process_time() - c0
            self.stress = np.array([o[0] for o in out], dtype=float).reshape(-1, 2, 2)
            self.tangent = np.array([o[1] for o in out], dtype=float).reshape(-1, 2, 2, 2, 2)

    def revert(self) -> None:
        """Drop the trial states (a rejected iterate or step): the committed ones are untouched."""
        self.trial = self._trial_response = None

    def committed_response(self) -> tuple[np.ndarray, np.ndarray]:
        """Stress and tangent of the committed states."""
        return self.stress, self.tangent

    def states(self) -> list:
        """The committed states (they travel: for checkpoints and tests)."""
        return list(self.committed)

    def observables(self) -> dict:
        """{name: (K,) float} from ``law.observables`` of the committed states ({} without it)."""
        fn = getattr(self.law, "observables", None)
        if not callable(fn):
            return {}
        rows = [self._call(g, fn, s) for g, s in zip(self.indices, self.committed)]
        return {k: np.array([r[k] for r in rows], dtype=float) for k in (rows[0] if rows else {})}

    def pid(self) -> int:
        """The process id of the chunk's process (tests)."""
        return os.getpid()

    def timing(self) -> dict:
        """{"law_s": seconds spent in ``law.update`` (and ``law.commit_response``) since the chunk
        was made (on its process),
        "law_cpu_s": the process's CPU seconds in them (on a shared machine, what the calls would
        take alone), "law_calls": their number, "pid"}: the DEM share of a run (bench/femxdem.py)."""
        return {"law_s": self.law_s, "law_cpu_s": self.law_cpu_s, "law_calls": self.law_calls, "pid": os.getpid()}


def _concat(parts, k):
    return np.concatenate([p[k] for p in parts])


class GaussPoints:
    """All Gauss points of a mesh in this process (one :class:`GaussChunk`).

    The driver-side protocol shared with :class:`DaskGaussPoints`: ``evaluate(f)``, ``commit()``,
    ``revert()``, ``committed_response()``, ``states()``, ``observables()``, ``timing()``, ``close()``.
    """

    where = "in process"

    def __init__(self, law, n_points: int, states=None, response=None):
        self.n_points = int(n_points)
        self.law = law
        self._chunk = GaussChunk(law, np.arange(self.n_points), states, response)

    def evaluate(self, f):
        """(stress (G, 2, 2), tangent (G, 2, 2, 2, 2)) of the step increments f (G, 2, 2)."""
        return self._chunk.evaluate(_check_f(f, self.n_points))

    def commit(self) -> None:
        """Commit every point's trial state."""
        self._chunk.commit()

    def revert(self) -> None:
        """Drop every point's trial state."""
        self._chunk.revert()

    def committed_response(self):
        """(stress, tangent) of the committed states."""
        return self._chunk.committed_response()

    def states(self) -> list:
        """The committed states, in Gauss point order."""
        return self._chunk.states()

    def observables(self) -> dict:
        """Per-point observables of the committed states."""
        return self._chunk.observables()

    def timing(self) -> list[dict]:
        """Per chunk, :meth:`GaussChunk.timing`."""
        return [self._chunk.timing()]

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class DaskGaussPoints:
    """The Gauss points in ``distributed`` Actors, one per contiguous chunk (module docstring).

    Parameters
    ----------
    law : the point law (pickled once to each chunk's worker)
    n_points : int, G
    executor : :class:`gransim.parallel.DaskExecutor` (``--workers N`` or ``--scheduler ADDRESS``)
    n_chunks : int, default the number of workers
    states : optional list of G committed states (a resumed run), sent once to their chunks
    response : optional (stress (G, 2, 2), tangent (G, 2, 2, 2, 2)) committed with them
    """

    def __init__(self, law, n_points: int, executor, n_chunks: int | None = None, states=None, response=None):
        self.law = law
        self.n_points = int(n_points)
        self.executor = executor
        workers = executor.workers()
        if not workers:
            raise InputError("Dask: the cluster has no worker")
        nc = max(1, min(int(n_chunks or len(workers)), self.n_points))
        edges = np.linspace(0, self.n_points, nc + 1).round().astype(int)
        self.index = [np.arange(a, b) for a, b in itertools.pairwise(edges)]
        self.where = executor.describe()
        client = executor.client
        futs = [
            client.submit(
                GaussChunk,
                law,
                ix,
                None if states is None else list(states[ix[0] : ix[-1] + 1]),
                None if response is None else (response[0][ix], response[1][ix]),
                actor=True,
                pure=False,
                workers=[workers[i % len(workers)]],
            )
            for i, ix in enumerate(self.index)
        ]
        self._actors = [f.result() for f in futs]

    def _all(self, method: str, args=None):
        calls = [getattr(a, method)(*(() if args is None else (args[i],))) for i, a in enumerate(self._actors)]
        return [c.result() for c in calls]

    def evaluate(self, f):
        """(stress (G, 2, 2), tangent (G, 2, 2, 2, 2)): each chunk's f goes to its Actor."""
        f = _check_f(f, self.n_points)
        parts = self._all("evaluate", [f[ix] for ix in self.index])
        return _concat(parts, 0), _concat(parts, 1)

    def commit(self) -> None:
        """Commit every chunk's trial states (on its worker)."""
        self._all("commit")

    def revert(self) -> None:
        """Drop every chunk's trial states."""
        self._all("revert")

    def committed_response(self):
        """(stress, tangent) of the committed states, from the workers."""
        parts = self._all("committed_response")
        return _concat(parts, 0), _concat(parts, 1)

    def states(self) -> list:
        """The committed states of every chunk, in Gauss point order (they travel: checkpoints)."""
        return [s for part in self._all("states") for s in part]

    def observables(self) -> dict:
        """Per-point observables of the committed states, computed on the workers."""
        parts = self._all("observables")
        return {k: np.concatenate([p[k] for p in parts]) for k in (parts[0] if parts else {})}

    def pids(self) -> list[int]:
        """Process ids of the chunks' workers (tests)."""
        return self._all("pid")

    def timing(self) -> list[dict]:
        """Per chunk, :meth:`GaussChunk.timing` (measured on its worker)."""
        return self._all("timing")

    def close(self) -> None:
        """Release the Actors (the executor owns the cluster and closes it)."""
        self._actors = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def gauss_points(law, n_points: int, executor=None, n_chunks: int | None = None, states=None, response=None):
    """The Gauss points of ``law``: in process (``executor`` None or in-process) or in Actors on the
    executor's Dask cluster (:func:`gransim.parallel.make_executor`); ``states`` and ``response``
    as :class:`GaussChunk` (a resumed run)."""
    if executor is None or getattr(executor, "kind", "") == "in-process":
        return GaussPoints(law, n_points, states, response)
    return DaskGaussPoints(law, n_points, executor, n_chunks, states, response)


__all__ = [
    "DaskGaussPoints",
    "GaussChunk",
    "GaussPoints",
    "MaterialPointError",
    "freeze",
    "gauss_points",
    "is_frozen",
]
