"""An MJX sweep sharded over 2 host devices with chunks of 64 (issue 21): it finishes, and both devices agree.

A chunk of 64 puts 32 rollouts on each device, past the batch (25 matrices of 29 x 29) from which jaxlib's
CPU Cholesky splits its batch over the intra-op thread pool and blocks a pool thread until the pieces are
done; with a pool no larger than the device count every thread blocked and the sweep hung.
:mod:`jaxlp.xla_flags` sizes the pool to cores + devices (``PJRT_NPROC``).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxlp import xla_flags

ROOT = Path(__file__).resolve().parents[2]
TWO = "--xla_force_host_platform_device_count=2"
# One push timing x 32 impulses, twice (--repeats 2: without noise or randomisation both copies are the same
# walks): 64 rollouts of 0.4 s, one chunk, rows 0-31 on device 0, 32-63 on device 1. The physics' Cholesky
# factorisations are what hung, whatever the controller: joint-pd, the one that compiles fastest.
GRID = ["map", "--model", "mjx", "--controller", "joint-pd", "--phases", "0.0", "--impulses", "0:6:32",
        "--repeats", "2", "--n-steps", "1", "--push-step", "0", "--chunk", "64", "--no-progress"]


def _env(**extra):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for name in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES", xla_flags.POOL_ENV, "NPROC"):  # the CLI sets them itself
        env.pop(name, None)
    env.update(extra)
    return env


def _sweep(out: Path, **env):
    return subprocess.run([sys.executable, "-m", "sweeps", *GRID, "--out", str(out)], cwd=ROOT, env=_env(**env),
                          capture_output=True, text=True, timeout=600)


def _results(out: Path) -> dict:
    with np.load(out / "results.npz") as z:
        return {k: z[k] for k in z.files}


def test_several_host_devices_get_a_thread_per_core_besides_one_per_device(monkeypatch):
    for name in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES", xla_flags.POOL_ENV, "NPROC"):
        monkeypatch.delenv(name, raising=False)
    cores = xla_flags.cpu_cores()
    xla_flags.configure_cpu()
    assert xla_flags.POOL_ENV not in os.environ  # one device: XLA's own pool (one thread per core)
    monkeypatch.setenv("XLA_FLAGS", TWO)
    assert TWO in xla_flags.configure_cpu().split() and os.environ[xla_flags.POOL_ENV] == str(cores + 2)
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=4")
    xla_flags.configure_cpu()  # inherited from a 2-device parent: raised
    assert os.environ[xla_flags.POOL_ENV] == str(cores + 4)
    monkeypatch.setenv(xla_flags.POOL_ENV, "64")
    xla_flags.configure_cpu()  # a larger pool asked for is kept
    assert os.environ[xla_flags.POOL_ENV] == "64"
    monkeypatch.delenv(xla_flags.POOL_ENV)
    monkeypatch.setenv("JAX_NUM_CPU_DEVICES", "3")
    assert xla_flags.host_device_count() == 3


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_the_cpu_client_starts_the_larger_pool():
    code = ("import sweeps, os, jax; jax.devices(); "
            "print(jax.device_count(), sum('XLAEigen' in open(f'/proc/self/task/{t}/comm').read() "
            "for t in os.listdir('/proc/self/task')))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(XLA_FLAGS=TWO), capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["2", str(xla_flags.cpu_cores() + 2)]


@pytest.fixture(scope="module")
def two_devices(tmp_path_factory):
    out = tmp_path_factory.mktemp("two-devices")
    r = _sweep(out, XLA_FLAGS=TWO)
    assert r.returncode == 0, r.stderr
    return out


def test_two_host_devices_finish_a_chunk_of_64_and_agree(two_devices):
    summary = json.loads((two_devices / "summary.json").read_text())
    assert summary["device_count"] == 2 and summary["chunk"] == 64
    assert summary["rollouts"] == 64 and summary["chunks_run"] == 1 and summary["backend"] == "cpu"
    res = _results(two_devices)
    assert not res["nan"].any() and not res["fell"].any()  # 0-6 N s pushes on a crouched stance: none falls
    knee = res["peak_abs_knee_torque_nm"][:32]  # the hardest pushes load the knees most
    assert knee[-8:].min() > knee[:8].max() + 1.0, knee
    for k, v in res.items():  # device 1 walked the same pushes as device 0
        if k != "index":
            np.testing.assert_array_equal(v[32:], v[:32], err_msg=k)


@pytest.mark.slow
def test_two_host_devices_match_one(two_devices, tmp_path):
    r = _sweep(tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["device_count"] == 1
    a, b = _results(two_devices), _results(tmp_path)
    for k in ("fell", "nan", "steps_to_recover", "touchdowns", "reason", "impulse_ns"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_allclose(a["fall_time_s"], b["fall_time_s"], rtol=0, atol=1e-5)
    # float32 programs of 32 and 64 rows round differently: knee torques of ~15 N m differ by up to 1.5e-4
    np.testing.assert_allclose(a["peak_abs_knee_torque_nm"], b["peak_abs_knee_torque_nm"], rtol=1e-4)
