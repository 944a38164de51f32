"""sweeps.parallel: sweeps in worker processes give the serial results in job order and carry errors back.

The comparison with the serial results compiles the sweep in this process and in two workers (about 45 s of the
suite's 2 x 15 minutes): it is slow; the default suite's end-to-end compare of two controllers
(tests/sweeps/test_sweeps.py) runs in two workers on a 2-core machine."""

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest

from sweeps.grid import SweepConfig
from sweeps.parallel import SweepJob, default_workers, run_sweeps
from sweeps.runner import SweepConflict, SweepInterrupted


def _jobs(root: Path) -> list[SweepJob]:
    # two small noisy 3LP sweeps that differ (seed), so a mix-up of folders or order shows
    cfg = SweepConfig(phases=(0.25,), impulses_ns=(0.0, 5.0), n_steps=3, noise_std_m=2e-3, chunk=2)
    return [SweepJob(cfg, root / "a", "a"), SweepJob(dataclasses.replace(cfg, seed=1), root / "b", "b")]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    root = tmp_path_factory.mktemp("serial")
    return root, run_sweeps(_jobs(root), workers=1, progress=False)


@pytest.mark.slow
def test_two_workers_give_the_serial_results_in_job_order(tmp_path, serial):
    seen = []
    par = run_sweeps(_jobs(tmp_path), workers=2, progress=False, on_done=lambda i, r: seen.append(i))
    assert sorted(seen) == [0, 1]
    for s, p in zip(serial[1], par):
        assert p.config == s.config and p.timing["rollouts_run"] == 2
        for k in s.results:
            np.testing.assert_array_equal(p.results[k], s.results[k], err_msg=k)
    a, b = (r.results["max_abs_footstep_adjustment_m"] for r in par)
    assert np.all(a != b)  # the two jobs differ, so the order check above is not vacuous


def test_a_worker_error_reaches_the_caller(tmp_path):
    from sweeps.runner import prepare_out_dir

    a, b = _jobs(tmp_path)
    for job, other in ((a, b), (b, a)):  # each folder holds the other sweep's finished work
        prepare_out_dir(job.out_dir, other.config, force=False)
        (job.out_dir / "results.npz").write_bytes(b"")
    with pytest.raises(SweepConflict, match="different sweep"):
        run_sweeps([a, b], workers=2, progress=False)


def test_workers_must_be_positive_and_default_to_the_cores_on_cpu():
    with pytest.raises(ValueError, match="workers must be >= 1, got 0"):
        run_sweeps([], workers=0)
    assert default_workers(1) == 1
    assert 1 <= default_workers(8) <= 8


def test_an_interrupted_sweep_survives_the_trip_back_from_a_worker():
    e = pickle.loads(pickle.dumps(SweepInterrupted(Path("out"), 2, 5)))
    assert (e.out_dir, e.done, e.total) == (Path("out"), 2, 5) and "after 2 of 5 chunks" in str(e)
