"""``gransim femxdem`` (stand-in Gauss-point laws): resume bit for bit (also onto Dask), the HDF5
file, the Taylor stand-in's consolidation, options refused before any work, no process left."""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gransim.fem.biaxial import BiaxialSpec
from gransim.fem.femxdem import FemxdemInterrupted, run_femxdem, standin_law
from gransim.fem.point_laws import J2Plasticity
from gransim.io import open_result

ROOT = Path(__file__).resolve().parents[2]
SPEC = BiaxialSpec(nx=2, ny=4, steps=6)


def _arrays(summary):
    out = []
    for r in summary["steps"]:
        out += [r.x, r.stress, r.F, r.strain, r.errors, r.residuals]
        out.append(np.array([r.axial_strain, r.deviatoric_stress, r.volumetric_strain]))
    return out


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    return run_femxdem(SPEC, "j2", tmp_path_factory.mktemp("full"))


def _same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_resume_repeats_the_uninterrupted_run_bit_for_bit(tmp_path, uninterrupted):
    with pytest.raises(FemxdemInterrupted):
        run_femxdem(SPEC, "j2", tmp_path, stop_after=3)
    ck = sorted(p.name for p in (tmp_path / "checkpoint").iterdir())
    assert ck == ["states_003.h5", "step_001.h5", "step_002.h5", "step_003.h5"]  # only the last states kept
    resumed = run_femxdem(SPEC, "j2", tmp_path, resume=True)
    assert resumed["resumed_after"] == 3
    _same(_arrays(uninterrupted), _arrays(resumed))
    # the plastic states matter here: the weak centre element flowed
    with open_result(tmp_path / "femxdem.h5", kind="fem-biaxial") as f:
        assert f["final/observables/alpha"][()].max() > 0


def test_resume_refuses_other_parameters(tmp_path):
    with pytest.raises(FemxdemInterrupted):
        run_femxdem(SPEC, "j2", tmp_path, stop_after=1)
    from gransim.errors import InputError

    with pytest.raises(InputError, match="tol"):
        run_femxdem(BiaxialSpec(nx=2, ny=4, steps=6, tol=1e-3), "j2", tmp_path, resume=True)


def test_resume_on_dask_gives_the_same_bits(tmp_path, uninterrupted):
    pytest.importorskip("distributed")
    from gransim.parallel import make_executor

    with pytest.raises(FemxdemInterrupted):
        run_femxdem(SPEC, "j2", tmp_path, stop_after=2)
    with make_executor(workers=2) as ex:
        resumed = run_femxdem(SPEC, "j2", tmp_path, executor=ex, resume=True, n_chunks=3)
    _same(_arrays(uninterrupted), _arrays(resumed))
    assert "Dask" in resumed["report"]


def test_results_file_carries_curves_and_provenance(uninterrupted):
    path = uninterrupted["files"]["h5"]
    with open_result(path, kind="fem-biaxial") as f:
        assert list(f["curves/step"][()]) == list(range(1, 7))
        assert np.array_equal(f["curves/deviatoric_stress"][()], [r.deviatoric_stress for r in uninterrupted["steps"]])
        assert "git_commit" in f.attrs and "parameters" in f.attrs
        assert '"rve": "j2"' in f.attrs["parameters"]
        assert f["final/stress"].shape == (SPEC.n_gauss, 2, 2)


def test_taylor_standin_is_consolidated_to_the_confining_pressure():
    pytest.importorskip("gransim.rve")
    from fem_helpers import triangular_packing

    spec = BiaxialSpec(nx=1, ny=1)
    law, params = standin_law("taylor", spec, packing=triangular_packing(6, 6, 1.0005))
    sigma, _ = law.response(law.initial_state(0))
    assert 0.5 * np.trace(sigma) == pytest.approx(-spec.pressure, rel=1e-10)
    assert params["consolidation_stretch"] < 1


def _gransim(*args, timeout=300):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(ROOT / ".venv" / "numba-cache")}
    return subprocess.run(
        [sys.executable, "-m", "gransim", "femxdem", *args], capture_output=True, text=True, timeout=timeout, env=env
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rve", "voronoi"], "--rve: expected one of dem, dem-lammps, taylor, j2"),
        (["--mesh", "0x3"], "--mesh"),
        (["--steps", "3", "--stop-after", "4"], "--stop-after"),
        (["--rve", "j2", "--packing", "x.h5"], "--packing: applies to --rve taylor only"),
        (["--element", "Q9", "--gauss", "2"], "hourglass"),
        (["--tol", "2"], "--tol"),
        (["--workers", "0"], "--workers"),
    ],
)
def test_bad_options_are_refused(tmp_path, args, message):
    p = _gransim(*args, "--out", str(tmp_path / "o"))
    assert p.returncode == 2, p.stderr
    assert message in p.stderr
    assert not (tmp_path / "o" / "femxdem.h5").exists()


def test_cli_on_a_local_cluster_leaves_no_process(tmp_path):
    pytest.importorskip("distributed")
    psutil = pytest.importorskip("psutil")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(ROOT / ".venv" / "numba-cache")}
    cmd = [sys.executable, "-m", "gransim", "femxdem", "--rve", "j2", "--steps", "3", "--workers", "2"]
    proc = subprocess.Popen([*cmd, "--out", str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    seen = {}
    parent = psutil.Process(proc.pid)
    while proc.poll() is None:
        try:
            for c in parent.children(recursive=True):
                seen.setdefault(c.pid, c.create_time())
        except psutil.NoSuchProcess:
            break
        time.sleep(0.05)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()[-2000:]
    assert b"Dask, 2 workers" in out
    assert len(seen) >= 2  # the workers were seen running
    procs = []
    for pid, created in seen.items():
        try:
            p = psutil.Process(pid)
            if p.create_time() == created:
                procs.append(p)
        except psutil.NoSuchProcess:
            pass
    _, alive = psutil.wait_procs(procs, timeout=10)  # the resource tracker ends on EOF from its parent
    assert not [(p.pid, p.name()) for p in alive]
    assert (tmp_path / "femxdem.h5").exists() and (tmp_path / "curves.png").exists()


class FailsLater(J2Plasticity):
    """J2 that raises at Gauss point 3 in its fourth update (the run's step 4)."""

    def update(self, f, state):
        if state.updates == 3 and state.yield_stress == 1.5e5 + 1e-3:
            raise RuntimeError("the RVE lost a particle")
        return super().update(f, state)

    def initial_state(self, g):
        s = super().initial_state(g)
        return type(s)(s.stress, s.alpha, s.yield_stress + (1e-3 if g == 3 else 0.0), s.updates)


def test_a_failing_step_keeps_the_converged_outputs(tmp_path):
    from gransim.fem.incremental import StepFailure

    law = FailsLater(1e8, 0.3, 1.5e5, 1e6, -1e5)
    with pytest.raises(StepFailure, match=r"load step 4: Gauss point 3: RuntimeError.*3 converged steps are in"):
        run_femxdem(SPEC, "failing-j2", tmp_path, law=law)
    with open_result(tmp_path / "femxdem.h5", kind="fem-biaxial") as f:
        assert list(f["curves/step"][()]) == [1, 2, 3]
        assert not f.attrs["completed"] and "load step 4" in f.attrs["stopped"]
    assert "STOPPED: load step 4" in (tmp_path / "report.md").read_text()
