"""The experiments' plans and reductions (no walk is run here: tests/mjx_coman/test_notebook_06.py runs them)."""

import math

import numpy as np
import pytest

from mjx_coman import controllers, studies
from mjx_coman.studies import seed001
from mjx_coman.studies.batch import check_rows

FLAT = [n for n in studies.names() if n not in ("terrain", "stairs")]  # each of their terrains is a scene


def test_largest_tolerated_stops_at_the_first_fall_by_magnitude():
    assert seed001.largest_tolerated([1, 2, 3, 4], [True, True, False, True]) == 2
    assert seed001.largest_tolerated([-5, -2.5, -10], [True, True, False]) == -5
    assert seed001.largest_tolerated([1, 2], [False, True]) is None
    assert seed001.largest_tolerated([0.5, 0.25], [True, True]) == 0.5


@pytest.mark.parametrize("seconds", [1.0, 3.0, 10.0])
def test_commanded_heading_is_the_integral_of_the_ramped_rate(seconds):
    t = np.linspace(0.0, seconds, 200001)
    rate = 0.4 * np.clip(t / 3.0, 0.0, 1.0)
    integral = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))
    assert seed001.commanded_heading_rad(0.4, seconds, 3.0) == pytest.approx(integral, rel=1e-6)


@pytest.mark.parametrize("name", studies.names())
def test_every_plan_is_valid_and_small_is_its_first_rows(name):
    full = studies.plan(name, "footstep-mpc", "full")
    small = studies.plan(name, "footstep-mpc", "small", seed=3)
    assert len(full.rows) == len(full.labels) and len(set(map(str, full.labels))) == len(full.labels)
    check_rows("footstep-mpc", full.rows, full.seconds, full.overrides)
    check_rows("footstep-mpc", small.rows, small.seconds, small.overrides)
    assert small.labels == full.labels[: len(small.rows)] and all(r.seed == 3 for r in small.rows)
    if name in FLAT:  # one compilation for every small flat experiment: the same walk length and batch
        assert small.seconds == seed001.SMALL_S and len(small.rows) == seed001.SMALL_ROWS
        assert all(r.scenario.terrain == "flat" for r in small.rows)
        if name != "toe-off":  # at full size toe-off also walks down stairs (seed 004 sec. IV)
            assert all(r.scenario.terrain == "flat" for r in full.rows)


def test_the_papers_values_are_in_the_grids():
    push = studies.plan("push")
    at3 = [lab for lab in push.labels if lab["impulse_ns"] == 3.0]
    assert len(at3) == 8 * 4 and {lab["direction_deg"] for lab in at3} == set(range(0, 360, 45))
    assert all(r.push_duration_s == 0.3 and r.forward_mps == 0.2 for r in push.rows)
    gait = controllers.get("footstep-mpc").gait(controllers.default_config("footstep-mpc"))
    for r, lab in zip(push.rows, push.labels):  # inside walking step 5 at its phase, ended before the walk ends
        assert r.push_start_s == pytest.approx(gait.first_step_s + (5 + lab["phase"]) * gait.step_time_s)
    speeds = [lab["speed_mps"] for lab in studies.plan("speeds").labels]
    assert sorted(speeds) == pytest.approx([-0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4])
    mass = studies.plan("model-error")
    backpack = [r for r, lab in zip(mass.rows, mass.labels) if lab == {"body": "DWYTorso", "payload_kg": 1.0}]
    assert backpack and backpack[0].scenario.payload_com_m == (-0.01, 0.0, 0.0)
    assert {15.0, -15.0} <= {lab["slope_deg"] for lab in studies.plan("slope").labels}
    noise = studies.plan("noise").labels
    assert {"imu_noise_deg": 3.0, "joint_noise_deg": 1.0, "axis": "imu"} in noise
    assert 10.0 in [lab["delay_ms"] for lab in studies.plan("delay").labels]
    terrain = studies.plan("terrain")
    assert terrain.seconds == 30.0 and {r.scenario.terrain for r in terrain.rows} == {"rough:5:0", "rough:5:1",
                                                                                   "rough:5:2"}
    steer = studies.plan("steer", overrides={"joystick_ramp_s": 1.0, "encoder_filter_s": 0.1})
    assert steer.overrides == {"joystick_ramp_s": 3.0, "encoder_filter_s": 0.1}  # the experiment's ramp wins


def test_steer_and_actuators_refuse_controllers_they_cannot_judge():
    with pytest.raises(ValueError, match="does not steer"):
        studies.plan("steer", "time-projection")
    with pytest.raises(ValueError, match="position-controlled"):
        studies.plan("actuators", "time-projection")
    plan = studies.plan("speeds", "time-projection")  # its speed range: +-0.3 m/s
    assert max(abs(lab["speed_mps"]) for lab in plan.labels) <= 0.3


@pytest.mark.parametrize("args,match", [
    (("walkies",), "unknown experiment 'walkies'; choose one of speeds"),
    (("speeds", "nobody"), "unknown controller 'nobody'"),
    (("speeds", "wbc-stand"), "wbc-stand does not walk"),
    (("speeds", "footstep-mpc", "huge"), "size='huge'"),
    (("speeds", "footstep-mpc", "small", -1), "seed=-1"),
])
def test_bad_plans_name_the_value(args, match):
    with pytest.raises(ValueError, match=match):
        studies.plan(*args)


def _result(fell):
    return {"fell": fell, "fall_time_s": 2.0 if fell else None, "mean_speed_mps": 0.19, "heading_change_rad": 1.0,
            "steps_to_recover": None if fell else 3, "series": {}}


def test_reductions_report_the_largest_tolerated_values():
    plan = studies.plan("delay")
    res = [_result(lab["delay_ms"] > 6.0) for lab in plan.labels]
    out = seed001.EXPERIMENTS["delay"].reduce(plan, res)
    assert out["largest_delay_ms"] == 6.0 and all("series" not in r for r in out["rows"])
    plan = studies.plan("steer")
    res = [_result(lab["turn_rad_per_s"] > 0.3) for lab in plan.labels]
    out = seed001.EXPERIMENTS["steer"].reduce(plan, res)
    assert out["largest_turn_rad_per_s_by_speed"]["0.1"] == 0.2
    walked = next(r for r in out["rows"] if not r["fell"])
    assert walked["heading_ratio"] == pytest.approx(1.0 / seed001.commanded_heading_rad(
        walked["turn_rad_per_s"], plan.seconds, 3.0))
    plan = studies.plan("push")
    res = [_result(lab["impulse_ns"] > 4.5 or lab["direction_deg"] == 90) for lab in plan.labels]
    out = seed001.EXPERIMENTS["push"].reduce(plan, res)["by_direction_deg"]
    assert out["0"]["largest_recovered_ns"] == 4.5 and out["90"]["largest_recovered_ns"] is None
    assert out["0"]["recovered_at_3ns"] == 4 and out["0"]["mean_steps_to_recover"] == 3
    assert math.isclose(out["180"]["largest_recovered_ns"], 4.5)
