"""sweeps.report on made-up results (no rollouts): the per-direction summary and the pooled per-phase rows."""

import numpy as np

from sweeps.grid import SweepConfig, grid_inputs
from sweeps.report import blocks, phase_rows, summarize
from sweeps.runner import SweepRun, failure_reason

TIMING = dict(wall_s=1.0, first_chunk_s=0.5, run_s=0.5, rollouts_per_s=1.0, env_steps_per_s=1.0,
              rate_includes_compile=False, ticks_per_rollout=10, env_step_s=0.002, rollouts_run=1,
              rollouts_resumed=0, chunks_run=1, chunks_resumed=0, chunk=1, device_count=1, process_count=1,
              backend="cpu", devices=["cpu"])


def fake_run(cfg: SweepConfig, limit_ns) -> SweepRun:
    """Every push at or below ``limit_ns(direction_rad, phase)`` recovered in 2 steps, the rest fell."""
    g = grid_inputs(cfg)
    limit = np.array([limit_ns(d, p) for d, p in zip(g.direction_rad, g.phase)])
    fell = g.impulse_ns > limit
    nan = np.zeros_like(fell)
    res = dict(g._asdict(), force_n=g.impulse_ns / cfg.push_duration_s, fell=fell, nan=nan,
               steps_to_recover=np.where(fell, -1, np.where(g.impulse_ns > 0, 2, 0)),
               max_abs_footstep_adjustment_m=np.zeros(fell.size), fall_time_s=np.where(fell, 1.0, np.inf))
    res["reason"] = failure_reason(fell, nan)
    return SweepRun(cfg, res, TIMING)


def test_each_direction_is_summarised_as_its_own_sweep_and_the_pooled_rows_need_every_direction():
    cfg = SweepConfig(model="mjx", phases=(0.25, 0.75), impulses_ns=(2.0, 4.0, 6.0),
                      directions=("forward", "90", "backward")).validate()
    limits = {0.0: 6.0, 90.0: 2.0, 180.0: 4.0}  # by heading, both phases alike
    run = fake_run(cfg, lambda d, p: limits[round(float(np.degrees(d)))])
    s = summarize(run)
    assert s["directions"] == ["forward", "90", "backward"] and s["rollouts"] == 18
    got = {r["direction"]: r["per_phase"][0]["max_recovered_impulse_ns"] for r in s["per_direction"]}
    assert got == {"forward": 6.0, "90": 2.0, "backward": 4.0}
    assert [r["direction_deg"] for r in s["per_direction"]] == [0.0, 90.0, 180.0]
    assert [r["recovery_rate"] for r in s["per_direction"]] == [1.0, 1 / 3, 2 / 3]
    assert [r["max_recovered_impulse_ns"] for r in phase_rows(cfg, run.results)] == [2.0, 2.0]  # the weakest
    assert [c.direction for c, _ in blocks(cfg, run.results)] == ["forward", "90", "backward"]


def test_one_direction_has_no_per_direction_block():
    cfg = SweepConfig(model="mjx", phases=(0.5,), impulses_ns=(1.0, 3.0), direction="left").validate()
    s = summarize(fake_run(cfg, lambda d, p: 2.0))
    assert "per_direction" not in s and s["direction"] == "left"
    assert s["per_phase"][0]["max_recovered_impulse_ns"] == 1.0 and s["median_steps_to_recover"] == 2.0
