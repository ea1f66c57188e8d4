"""Fixtures of the fault tests: fake ``liggghts`` binaries on PATH and a small real deck.

Reusable by every test module in ``tests/faults/``:

``fake_liggghts``
    A factory: ``fake = fake_liggghts(kind)`` writes an executable ``liggghts`` of that kind into
    a fresh temporary directory, prepends the directory to PATH (``monkeypatch``: undone after the
    test) and returns a :class:`fakes.FakeLiggghts` with ``.path``, ``.kind``, ``.pids(role=None)``
    (pids the fake recorded: roles ``fake``, ``grandchild``, ``real``), ``.alive()`` (those still
    running, zombies excluded) and ``.wait_gone(timeout)``. Kinds (details in ``fakes.py``):

    - ``error``: writes an ERROR line in the log, exits 1;
    - ``silent``: exits 0 writing nothing;
    - ``hang``: sleeps forever, with a grandchild in its process group that ignores SIGTERM;
    - ``truncate-log``: runs the real binary, then cuts the log to its first 3 thermo rows;
    - ``cut-dumps``: real run, then keeps only the first frame of every dump file;
    - ``warning``: real run plus a WARNING line in the log;
    - ``slow``: sleeps ``FAKE_LIGGGHTS_DELAY`` s (default 2), then a real run.

    The kinds that run the real binary skip the test when ``liggghts`` is not installed. Every
    fake answers the version query (``-in /dev/null``) with ``LIGGGHTS-PUBLIC 3.8.0 fake-<kind>``
    and marks the banner of the logs it leaves the same way. At teardown any process a fake
    recorded and that is still alive is killed (so a failing test leaves no orphans), and the
    runner's SIGTERM-to-SIGKILL grace is 0.5 s during the test.

``fake_lmp``
    The same factory for a fake ``lmp`` (LAMMPS banner ``LAMMPS (29 Sep 2021 - Update 2
    fake-<kind>)``); the kinds that run the real binary need the real ``lmp``.

``small_lammps_job``
    ``fakes.small_lammps_deck``: the LAMMPS twin of ``small_liggghts_job``.

``small_liggghts_job``
    ``deck, files, outputs = small_liggghts_job(tail="run 10\\n", dump_every=5, local_every=None)``:
    a 36-disk deck LIGGGHTS runs in about half a second, for ``run_job(job_dir, deck, files,
    outputs=outputs, progress=False)`` (``fakes.small_deck``).

``real_liggghts``
    Path of the real binary (skips the test when it is absent).

Tests marked ``@pytest.mark.liggghts`` are skipped when the real binary is not on PATH.
``fakes.pid_alive(pid)`` tells whether a process is still running.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fakes import REAL_KINDS, fakes_on_path, small_deck, small_lammps_deck, write_fake  # noqa: E402

_REAL = shutil.which("liggghts")
_REAL_LMP = shutil.which("lmp")


def pytest_collection_modifyitems(config, items):
    """A test marked ``liggghts`` needs the real binary: skipped, saying so, when it is absent. The
    marker decides, not the keywords (they hold parameter ids too: ``test_x[liggghts]`` of a stored
    output needs no binary and must run, tests/reference_runs/conftest.py)."""
    if _REAL is None:
        skip = pytest.mark.skip(
            reason="needs the liggghts binary (marker liggghts), which is not installed (apt-get install liggghts)"
        )
        here = Path(__file__).resolve().parent
        for item in items:
            if item.get_closest_marker("liggghts") is not None and here in Path(str(item.fspath)).resolve().parents:
                item.add_marker(skip)


@pytest.fixture
def real_liggghts():
    if _REAL is None:
        pytest.skip("needs the real liggghts binary (apt-get install liggghts)")
    return _REAL


@pytest.fixture
def fake_liggghts(tmp_path_factory, monkeypatch):
    def write(bindir, kind, real):
        return write_fake(bindir, kind, real=real)

    yield from fakes_on_path(
        tmp_path_factory, monkeypatch, write, _REAL, REAL_KINDS, "liggghts", "apt-get install liggghts"
    )


@pytest.fixture
def fake_lmp(tmp_path_factory, monkeypatch):
    def write(bindir, kind, real):
        return write_fake(bindir, kind, real=real, engine="lammps")

    yield from fakes_on_path(
        tmp_path_factory, monkeypatch, write, _REAL_LMP, REAL_KINDS, "lmp", "apt-get install lammps"
    )


@pytest.fixture
def small_lammps_job():
    return small_lammps_deck


@pytest.fixture
def small_liggghts_job():
    return small_deck
