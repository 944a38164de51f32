"""Made-up sweep results for the report and scorecard tests (no rollouts)."""

import numpy as np
import pytest

from sweeps.grid import SweepConfig, grid_inputs
from sweeps.runner import SweepRun, failure_reason

TIMING = dict(wall_s=1.0, first_chunk_s=0.5, run_s=0.5, rollouts_per_s=1.0, env_steps_per_s=1000.0,
              rate_includes_compile=False, ticks_per_rollout=10, env_step_s=0.002, rollouts_run=1,
              rollouts_resumed=0, chunks_run=1, chunks_resumed=0, chunk=1, device_count=1, process_count=1,
              backend="cpu", devices=["cpu"])


def _fake_run(cfg: SweepConfig, limit_ns, **extra) -> SweepRun:
    """Every push at or below ``limit_ns(grid_inputs, row)`` recovered in 2 steps, the rest fell; ``extra``
    columns are ``fn(grid_inputs) -> (n,)``."""
    g = grid_inputs(cfg)
    limit = np.array([limit_ns(g, i) for i in range(g.index.size)])
    fell = g.impulse_ns > limit
    nan = np.zeros_like(fell)
    res = dict(g._asdict(), force_n=g.impulse_ns / cfg.push_duration_s, fell=fell, nan=nan,
               steps_to_recover=np.where(fell, -1, np.where(g.impulse_ns > 0, 2, 0)),
               max_abs_footstep_adjustment_m=np.zeros(fell.size), fall_time_s=np.where(fell, 1.0, np.inf),
               **{k: fn(g) for k, fn in extra.items()})
    res["reason"] = failure_reason(fell, nan)
    return SweepRun(cfg, res, TIMING)


@pytest.fixture
def fake_run():
    return _fake_run
