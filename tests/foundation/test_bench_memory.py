"""bench._memory: peak-RSS readings of child processes against allocations of known size."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench._memory import PeakSampler, own_peak_kib, run_child, vm_hwm_kib

MIB = 1024
# `b"x" * n` allocates n bytes and writes every one (all pages resident)
ALLOC = "import time; b = b'x' * ({mib} * 2**20); time.sleep({hold})"
REPORT = "from bench._memory import own_peak_kib; print(own_peak_kib())"


def _py(code: str):
    return [sys.executable, "-c", code]


def _peak(code: str) -> int:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    r = run_child(_py(code + "\n" + REPORT), env=env)
    assert r.returncode == 0, r.stderr
    return int(r.stdout.split()[-1])


def test_own_peak_of_a_known_allocation():
    bare = _peak("pass")
    extra = (_peak(ALLOC.format(mib=160, hold=0)) - bare) / MIB
    # the interpreter's own start-up peak is partly reused by the allocation: a few MiB below 160
    assert 150 <= extra <= 165, extra


def test_peak_is_not_inherited_from_a_big_parent():
    # ru_maxrss would report the parent's 256 MiB (the kernel keeps the pre-exec high-water mark);
    # VmHWM starts afresh at exec
    hold = np.ones(2**25)  # 256 MiB resident here
    assert own_peak_kib() > 256 * MIB
    assert _peak("pass") < 100 * MIB
    del hold


def test_child_failure_and_timeout_are_reported():
    assert run_child(_py("raise SystemExit(3)")).returncode == 3
    r = run_child(_py("import time; time.sleep(30)"), timeout=0.5)
    assert r.returncode < 0 and r.wall_s < 10


def test_sampler_sums_concurrent_descendants():
    # a child that starts two grandchildren holding 100 MiB each at the same time: the sampler
    # sees both (about 2 x 100 MiB plus two bare interpreters)
    code = f"""
import subprocess, sys
cmd = [sys.executable, "-S", "-c", {ALLOC.format(mib=100, hold=0.8)!r}]
procs = [subprocess.Popen(cmd) for _ in range(2)]
for p in procs:
    p.wait()
"""
    proc = subprocess.Popen(_py(code))
    sampler = PeakSampler(root=proc.pid, interval=0.05)
    sampler.start()
    proc.wait()
    peaks = sampler.stop()
    assert len(peaks) == 2, peaks
    for _, kib in peaks.values():
        assert 100 * MIB <= kib <= 120 * MIB
    assert sampler.total_kib == sum(k for _, k in peaks.values())


@pytest.mark.parametrize("match", [True, False])
def test_sampler_filters_by_command_name(match):
    comm = Path(sys.executable).name[:15]  # the kernel's command name: executable basename, 15 chars
    sampler = PeakSampler(names={comm if match else "no-such-name"}, interval=0.05)
    proc = subprocess.Popen(_py(ALLOC.format(mib=20, hold=0.5)))
    sampler.start()
    proc.wait()
    peaks = sampler.stop()
    if match:
        # the child is seen with its peak; any other descendant sampled has the same name (a test worker
        # may hold other python children, e.g. a Dask cluster of another test module)
        assert proc.pid in peaks and peaks[proc.pid][1] >= 20 * MIB
        assert all(name == comm for name, _ in peaks.values())
    else:
        assert peaks == {}


def test_vm_hwm_of_a_missing_process():
    assert vm_hwm_kib(2**22 + 12345) is None
