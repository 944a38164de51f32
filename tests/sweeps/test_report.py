"""sweeps.report on made-up results (no rollouts): the per-direction summary and the pooled per-phase rows."""

import numpy as np

from sweeps.grid import SweepConfig
from sweeps.report import blocks, map_states, phase_rows, pooled, repeat_rows, summarize
from sweeps.runner import failure_reason

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


def test_a_failed_solve_has_its_own_colour_in_the_pooled_map(fake_run):
    """Repeat 0 falls above 2 N s; repeat 1 ends by a failed solve at 3 N s: the map says solve failed there."""
    cfg = SweepConfig(model="mjx", phases=(0.5,), impulses_ns=(1.0, 2.0, 3.0), repeats=2).validate()
    run = fake_run(cfg, lambda g, i: 2.0)
    res = dict(run.results)
    failed = np.zeros(cfg.n_rollouts, bool)
    failed[cfg.n_per_repeat + 2] = True  # repeat 1, 3 N s (fell there too: a failed solve ends the walk)
    res["reason"] = failure_reason(res["fell"], res["nan"], failed)
    assert list(map_states(repeat_rows(cfg, res, 0))) == [0, 0, 1]
    assert list(map_states(repeat_rows(cfg, res, 1))) == [0, 0, 3]
    one = pooled(cfg, res)
    assert list(one["reason"]) == ["", "", "solve_failed"] and list(map_states(one)) == [0, 0, 3]
