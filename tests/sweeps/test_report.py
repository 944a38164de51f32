"""sweeps.report on made-up results (no rollouts): the per-direction summary and the pooled per-phase rows."""

import numpy as np

from sweeps.grid import SweepConfig
from sweeps.report import phase_rows, summarize
from sweeps.rows import blocks, pooled, repeat_rows


def test_each_direction_is_summarised_as_its_own_sweep_and_the_pooled_rows_need_every_direction(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.25, 0.75), impulses_ns=(2.0, 4.0, 6.0),
                      directions=("forward", "90", "backward")).validate()
    limits = {0.0: 6.0, 90.0: 2.0, 180.0: 4.0}  # by heading, both phases alike
    run = fake_run(cfg, lambda g, i: limits[round(float(np.degrees(g.direction_rad[i])))])
    s = summarize(run)
    assert s["directions"] == ["forward", "90", "backward"] and s["rollouts"] == 18
    got = {r["direction"]: r["per_phase"][0]["max_recovered_impulse_ns"] for r in s["per_direction"]}
    assert got == {"forward": 6.0, "90": 2.0, "backward": 4.0}
    assert [r["direction_deg"] for r in s["per_direction"]] == [0.0, 90.0, 180.0]
    assert [r["recovery_rate"] for r in s["per_direction"]] == [1.0, 1 / 3, 2 / 3]
    assert [r["max_recovered_impulse_ns"] for r in phase_rows(cfg, run.results)] == [2.0, 2.0]  # the weakest
    assert [c.direction for c, _ in blocks(cfg, run.results)] == ["forward", "90", "backward"]


def test_one_direction_has_no_per_direction_block(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.5,), impulses_ns=(1.0, 3.0), direction="left").validate()
    s = summarize(fake_run(cfg, lambda g, i: 2.0))
    assert "per_direction" not in s and s["direction"] == "left"
    assert s["per_phase"][0]["max_recovered_impulse_ns"] == 1.0 and s["median_steps_to_recover"] == 2.0


def test_a_push_is_recovered_in_the_pooled_map_only_if_every_repeat_recovered_it(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0), directions=("0", "180"),
                      repeats=3).validate()
    assert cfg.n_rollouts == 3 * 2 * 6
    run = fake_run(cfg, lambda g, i: 3.0 - (i // cfg.n_per_repeat))  # repeat r recovers up to 3 - r N s
    assert [float(repeat_rows(cfg, run.results, r)["impulse_ns"][~repeat_rows(cfg, run.results, r)["fell"]].max())
            for r in range(3)] == [3.0, 2.0, 1.0]
    one = pooled(cfg, run.results)
    assert one["index"].size == cfg.n_per_repeat and one["impulse_ns"][~one["fell"]].max() == 1.0
    s = summarize(run)
    assert [r["per_phase"][0]["recovered_up_to_ns"] for r in s["per_direction"]] == [1.0, 1.0]
    assert [r["per_phase"][0]["max_recovered_impulse_ns"] for r in s["per_direction"]] == [3.0, 3.0]
