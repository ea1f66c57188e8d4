"""`gransim slope --resume`: an interrupted run continued from its checkpoint equals the uninterrupted one.

The interruption is the ``--stop-after K`` hook (the run stops right after step K's checkpoint is
written, as a kill after that step would leave it). Every dataset of slope.h5 (mesh, every step's
q, u, F, P, sigma, von Mises, det F, contacts, energy and residual norms, load-settlement) must be
equal, bit for bit, to the uninterrupted run's: with the continuum stand-in, with a Taylor
lattice RVE under the paper load, whose path ends in a limit search (halved increments) (exit 2),
and with the relaxed lattice RVE (service load) started from the previous FE iterate's trial
(``--relaxed-start trial``), whose Gauss-point history at a commit depends on every FE iterate of
the committed attempt: the checkpoint stores and the resume replays them.
"""

import h5py
import numpy as np
import pytest

from gransim import Packing
from gransim.cli import main


def _lattice(tmp_path):
    from gransim.io import save_packing

    a, nx, ny = 1e-3, 5, 6
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    x += np.random.default_rng(1).uniform(-2e-4, 2e-4, x.shape) * a
    p = Packing(positions=x, radii=np.full(len(x), 0.5 * a * 1.0005), cell=np.diag([nx * a, ny * h]))
    path = tmp_path / "lattice.h5"
    save_packing(path, p)
    return path


def _datasets(path) -> dict:
    out = {}
    with h5py.File(path) as f:

        def grab(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[()]

        f.visititems(grab)
        for name in f["steps"]:
            for k in ("load", "cuts"):
                out[f"steps/{name}@{k}"] = np.asarray(f[f"steps/{name}"].attrs[k])
        out["@completed"] = np.asarray(f.attrs["completed"])
        out["@message"] = np.asarray(str(f.attrs["message"]))
    return out


def _same(a: dict, b: dict):
    assert sorted(a) == sorted(b)
    for k, x in a.items():
        assert x.shape == b[k].shape and np.array_equal(x, b[k]), k


def _rc(argv):
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("kind", ["neo-hookean", "taylor", "relaxed"])
def test_resume_is_bitwise_the_uninterrupted_run(tmp_path, kind, capsys):
    base = ["slope", "--mesh", "10x5", "--figures", "none"]
    if kind == "taylor":
        base += [
            "--protocol",
            "paper",
            "--load-steps",
            "5",
            "--min-fraction",
            "0.0625",
            "--packing",
            str(_lattice(tmp_path)),
        ]
        stop, expect = 4, 2  # the paper load on the reduced slope stops at a limit (exit 2, docs/fem.md)
    elif kind == "relaxed":
        base += ["--rve", "relaxed", "--relaxed-start", "trial", "--load-steps", "2"]
        base += ["--packing", str(_lattice(tmp_path))]
        stop, expect = 2, 0
    else:
        base += ["--material", "neo-hookean", "--load-steps", "6"]
        stop, expect = 3, 0
    full, cut = tmp_path / "full", tmp_path / "cut"
    assert _rc(base + ["--out", str(full)]) == expect
    assert _rc(base + ["--out", str(cut), "--stop-after", str(stop)]) == 0
    assert "--resume" in capsys.readouterr().err
    names = sorted(p.name for p in (cut / "checkpoint").iterdir())
    # one atomic file per step, no temporaries left
    assert names == [f"step_{k:03d}.h5" for k in range(1, stop + 1)]
    assert not (cut / "slope.h5").exists()
    assert _rc(base + ["--out", str(cut), "--resume"]) == expect
    assert f"resumed after step {stop}" in (cut / "report.md").read_text()
    _same(_datasets(full / "slope.h5"), _datasets(cut / "slope.h5"))
    if kind == "taylor":
        with h5py.File(full / "slope.h5") as f:
            # the limit search after the checkpoint (halved increments) was resumed too: its partial
            # state is among the equal arrays
            assert not bool(f.attrs["completed"]) and "006_partial" in f["steps"]


def test_resume_refuses_a_checkpoint_of_other_parameters(tmp_path, capsys):
    base = ["slope", "--mesh", "10x5", "--figures", "none", "--material", "neo-hookean", "--out", str(tmp_path)]
    assert _rc(base + ["--load-steps", "4", "--stop-after", "2"]) == 0
    capsys.readouterr()
    assert _rc(base + ["--load-steps", "5", "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "load_steps = 4" in err and "load_steps = 5" in err
    assert _rc(base + ["--load-steps", "4", "--tol", "1e-12", "--resume"]) == 2
    assert "tol" in capsys.readouterr().err
    # the dead load in other steps is another load path
    assert _rc(base + ["--load-steps", "4", "--dead-load-steps", "2", "--resume"]) == 2
    assert "dead_load_steps" in capsys.readouterr().err


def test_resume_without_checkpoint_and_bad_options(tmp_path, capsys):
    base = ["slope", "--mesh", "10x5", "--figures", "none", "--material", "neo-hookean"]
    assert _rc(base + ["--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert _rc(base + ["--out", str(tmp_path), "--stop-after", "0"]) == 2
    assert "--stop-after" in capsys.readouterr().err
    assert _rc(base + ["--out", str(tmp_path), "--dead-load-steps", "0"]) == 2
    assert "--dead-load-steps" in capsys.readouterr().err
    assert _rc(base + ["--out", str(tmp_path), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    assert _rc(base + ["--out", str(tmp_path), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--scheduler" in capsys.readouterr().err
