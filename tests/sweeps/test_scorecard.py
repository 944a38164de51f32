"""sweeps.scorecard on made-up results: per-direction impulses with bootstrap intervals, effort columns,
tolerated scenario values, the markdown table."""

import dataclasses

import numpy as np
import pytest

from sweeps.grid import SweepConfig, freeze_scenario
from sweeps.scorecard import markdown, scorecard, tolerated


def test_rows_per_controller_and_scenario_with_each_directions_largest_impulse(fake_run):
    scen = freeze_scenario({"slope_deg": [0, 5]})
    cfg = SweepConfig(model="mjx", phases=(0.25, 0.75), impulses_ns=(2.0, 4.0, 6.0), directions=("0", "180"),
                      repeats=2, scenario=scen).validate()
    slope = lambda g: np.array([0.0, 5.0])[g.scenario_index]  # noqa: E731

    def limit(g, i):  # 0 deg: 6 N s flat, 2 N s on the slope; 180: 4 N s, and 2 in repeat 1 on the slope
        r = i // cfg.n_per_repeat
        if g.direction_rad[i] == 0:
            return 6.0 if slope(g)[i] == 0 else 2.0
        return 4.0 if slope(g)[i] == 0 or r == 0 else 2.0

    a = fake_run(cfg, limit, mean_speed_mps=lambda g: np.full(g.index.size, 0.1),
                 mean_abs_knee_torque_nm=lambda g: 1.0 + slope(g), cost_of_transport=lambda g: np.full(g.index.size, 0.5),
                 peak_abs_knee_torque_nm=lambda g: 10.0 + g.impulse_ns)
    b = fake_run(dataclasses.replace(cfg, controller="dlqr"), lambda g, i: 0.0)
    card = scorecard([a, b])
    rows = card["rows"]
    assert [(r["controller"], r["scenario"]["slope_deg"]) for r in rows] == [
        ("time-projection", 0.0), ("time-projection", 5.0), ("dlqr", 0.0), ("dlqr", 5.0)]
    flat, tilted = rows[0], rows[1]
    assert [p["largest_recovered_impulse_ns"] for p in flat["per_direction"]] == [6.0, 4.0]
    assert flat["per_direction"][0]["interval_ns"] == [6.0, 6.0]
    assert [p["largest_recovered_impulse_ns"] for p in tilted["per_direction"]] == [2.0, 3.0]  # mean of 4 and 2
    lo, hi = tilted["per_direction"][1]["interval_ns"]
    assert lo == 2.0 and hi == 4.0
    assert flat["recovery_rate"] == pytest.approx((6 + 4) / 12) and flat["median_steps_to_recover"] == 2.0
    assert flat["mean_abs_knee_torque_nm"] == 1.0 and tilted["mean_abs_knee_torque_nm"] == 6.0
    assert flat["peak_abs_knee_torque_nm"] == 16.0 and flat["cost_of_transport"] == 0.5
    assert rows[2]["recovery_rate"] == 0.0 and rows[2]["per_direction"][0]["largest_recovered_impulse_ns"] == 0.0
    assert rows[2]["median_steps_to_recover"] is None and "cost_of_transport" not in rows[2]
    assert flat["fell"] == 4 and rows[2]["fell"] == 24 and flat["nan"] == 0
    tol = card["controllers"]["time-projection"]["tolerated"]["slope_deg"]
    assert tol == dict(tolerated_values=[0.0], max_tolerated=0.0)  # 5 deg: under half recovered
    assert card["controllers"]["dlqr"]["tolerated"]["slope_deg"]["max_tolerated"] is None
    md = markdown(card)
    assert "| time-projection | slope_deg=5, terrain=flat | 2.0 [2.0, 2.0] | 3.0 [2.0, 4.0] | 42% | 14 | 0 |" in md
    assert md.count("\n| ") == 1 + 4  # the header and a row per controller and scenario


def test_a_walk_gone_non_finite_did_not_recover(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.5,), impulses_ns=(1.0, 2.0, 3.0, 4.0), direction="left").validate()
    run = fake_run(cfg, lambda g, i: 4.0)
    run.results["nan"][3] = True
    run.results["reason"][3] = "nan"
    (row,) = scorecard([run])["rows"]
    assert row["recovery_rate"] == 0.75 and row["nan"] == 1 and row["fell"] == 0
    assert row["per_direction"][0]["largest_recovered_impulse_ns"] == 3.0


def test_tolerated_terrain_counts_heights_and_stops_at_the_first_failure():
    row = lambda t, rate: dict(scenario=dict(terrain=t), recovery_rate=rate)  # noqa: E731
    got = tolerated([row("flat", 0.9), row("rough:2", 0.6), row("rough:5", 0.2), row("rough:8", 0.7)])
    assert got["terrain"] == dict(tolerated_values=["flat", "rough:2", "rough:8"], max_tolerated=2.0)
    assert tolerated([row("flat", 0.9)]) == {}


def test_tolerance_is_one_axis_at_a_time_from_the_nominal_scenario():
    """An actuator that fails everywhere does not hide the slopes and delays tolerated on the nominal one."""
    rows = [dict(scenario=dict(actuator=act, slope_deg=s, terrain="flat"),
                 recovery_rate=0.0 if act == "sea" or s == 10.0 else 1.0)
            for act in ("ideal", "sea") for s in (0.0, 5.0, 10.0)]
    got = tolerated(rows)
    assert got["slope_deg"] == dict(tolerated_values=[0.0, 5.0], max_tolerated=5.0)
    assert got["actuator"] == dict(tolerated_values=["ideal"], max_tolerated=0.0)


def test_the_scorecard_agrees_with_the_controllers_own_walk_under_the_same_push(tmp_path, capsys):
    """One compare run (time projection, 6 N s left and right at a quarter of walking step 1, 0.1 m/s) against
    ``python -m mjx_coman.walk`` with the same push: the same verdict in each direction, and the two directions
    differ (the full comparison: left recovered, right fell), so agreement is not vacuous. The compare run and the
    walk have the shapes of notebook 08's small run: one compilation each in the session's cache."""
    import json

    from mjx_coman import walk
    from sweeps import cli

    out = tmp_path / "cmp"
    assert cli.main(["compare", "--model", "mjx", "--controllers", "time-projection", "--directions", "left,right",
                     "--phases", "0.25", "--impulses", "6", "--n-steps", "4", "--repeats", "2", "--chunk", "4",
                     "--no-progress",
                     "--out", str(out)]) == 0
    card = json.loads((out / "scorecard.json").read_text())
    swept = {p["direction"]: p["largest_recovered_impulse_ns"] == 6.0 for p in card["rows"][0]["per_direction"]}
    capsys.readouterr()
    walked = {}
    for d in ("left", "right"):
        assert walk.main(["--controller", "time-projection", "--speed", "0.1", "--seconds", "2.0", "--push-ns", "6",
                          "--push-step", "1", "--push-phase", "0.25", "--push-dir", d, "--json"]) == 0
        walked[d] = not json.loads(capsys.readouterr().out)["fell"]
    assert swept == walked == {"left": True, "right": False}
