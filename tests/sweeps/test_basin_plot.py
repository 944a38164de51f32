"""sweeps.basin_plot on made-up results (no rollouts): each outcome's colour, in one repeat and pooled."""

import numpy as np

from sweeps.basin_plot import map_states
from sweeps.grid import SweepConfig
from sweeps.rows import pooled, repeat_rows
from sweeps.runner import failure_reason


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
