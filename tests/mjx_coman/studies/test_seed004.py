"""Seed 004's experiments: plans and reductions (no walk is run here)."""

import math

import numpy as np
import pytest

from mjx_coman import controllers, studies
from mjx_coman.studies import seed001, seed004
from mjx_coman.scenarios import terrain as T
from mjx_coman.studies.batch import check_rows


@pytest.mark.parametrize("name", ["flat", "toe-off", "mid-swing-push"])
@pytest.mark.parametrize("controller", ["straight-leg", "footstep-mpc"])
def test_plans_are_valid_and_small_shares_the_flat_compilation(name, controller):
    full = studies.plan(name, controller, "full")
    small = studies.plan(name, controller, "small")
    check_rows(controller, full.rows, full.seconds, full.overrides)
    check_rows(controller, small.rows, small.seconds, small.overrides)
    assert small.seconds == seed001.SMALL_S and len(small.rows) == seed001.SMALL_ROWS
    assert small.labels == full.labels[: len(small.rows)]


def test_mid_swing_is_the_middle_of_the_swing_after_the_transfer():
    cfg = controllers.default_config("straight-leg")
    ph = seed004.mid_swing_phase("straight-leg")
    assert ph * cfg.step_time_s == pytest.approx(cfg.transfer_s + 0.5 * cfg.swing_s)
    assert seed004.mid_swing_phase("footstep-mpc") == pytest.approx(0.5)  # no transfer by default
    push = studies.plan("mid-swing-push", "straight-leg")
    gait = controllers.get("straight-leg").gait(cfg)
    assert {lab["direction_deg"] for lab in push.labels} == set(range(0, 360, 45))
    assert all(r.push_duration_s == 0.1 and r.forward_mps == seed004.PUSH_MPS for r in push.rows)
    for r in push.rows:
        assert r.push_start_s == pytest.approx(gait.first_step_s + (seed004.PUSH_STEP + ph) * gait.step_time_s)
    assert max(lab["impulse_ns"] for lab in push.labels) >= 10.0  # the common ICP-stack test's size


def test_flat_speed_is_atlas_scaled_by_froude():
    plan = studies.plan("flat", "straight-leg")
    assert plan.labels[0]["speed_mps"] == pytest.approx(0.26 * math.sqrt(0.432 / 0.85), abs=0.005)
    assert plan.seconds == 20.0


def _result(fell, steps=2):
    return {"fell": fell, "fall_time_s": 1.0 if fell else None, "nan": False, "solve_failed": False,
            "touchdowns": 10, "mean_speed_mps": 0.15, "heading_change_rad": 0.0, "cycle": {},
            "steps_to_recover": None if fell else steps, "series": {}}


def test_push_reduction_reads_the_largest_recovered_impulse_below_the_first_fall():
    plan = studies.plan("mid-swing-push", "straight-leg")
    res = [_result(lab["impulse_ns"] > 5.0 or (lab["direction_deg"] == 90 and lab["impulse_ns"] == 2.0),
                   steps=int(lab["impulse_ns"])) for lab in plan.labels]
    out = seed004.EXPERIMENTS["mid-swing-push"].reduce(plan, res)["by_direction_deg"]
    assert out["0"]["largest_recovered_ns"] == 5.0 and out["90"]["largest_recovered_ns"] == 1.0
    assert out["0"]["median_steps_to_recover"] == pytest.approx(np.median([1, 2, 3, 4, 5]))
    assert out["90"]["median_steps_to_recover"] == 1.0  # only what lies below the first fall


def test_stairs_rows_are_one_scene_per_riser_up_and_down_and_climbing_needs_two_risers_of_rise():
    plan = studies.plan("stairs", "straight-leg")
    assert [r.scenario.terrain for r in plan.rows] == [f"stairs:{h}" for h in seed004.RISERS_CM]
    assert max(seed004.RISERS_CM) >= 0.197 / 2 * 100  # Atlas's riser scaled by the leg length
    assert -min(seed004.RISERS_CM) >= 0.197 / 2 * 100  # and down
    check_rows("straight-leg", plan.rows, plan.seconds)
    # up: climbed to 7 cm; down: the CoM falls by 2.5 risers to 5 cm, and rises at 7 cm (stuck, no fall)
    rise = {h: (2.5 * h / 100 if h < 8 else 0.01) if h > 0 else (2.5 * h / 100 if h > -6 else 0.01)
            for h in seed004.RISERS_CM}
    res = [dict(_result(False), riser_cm=h, com_rise_m=rise[h]) for h in seed004.RISERS_CM]
    out = seed004.EXPERIMENTS["stairs"].reduce(plan, res)
    assert out["largest_riser_up_cm"] == 7 and out["climbed"]["10"] is False
    assert out["largest_riser_down_cm"] == 5 and out["climbed"]["-7"] is False
    assert not seed004.climbed(dict(_result(True), com_rise_m=1.0), 2)  # a fall is not a climb
    assert not seed004.climbed(dict(_result(False), com_rise_m=0.1), -2)  # going up is not a descent


def test_toe_off_rows_walk_at_the_three_speeds_and_down_stairs():
    plan = studies.plan("toe-off", "straight-leg-no-toe-off")
    assert [lab["speed_mps"] for lab in plan.labels] == [*seed004.TOE_OFF_MPS, seed004.STAIR_MPS]
    assert [r.scenario.terrain for r in plan.rows] == ["flat"] * 3 + [seed004.TOE_OFF_STAIRS] and plan.seconds == 20.0
    assert T.parse_terrain(seed004.TOE_OFF_STAIRS).height_m < 0  # down
    res = [dict(_result(False), toe_off_fraction=0.1 * i) for i in range(4)]
    out = seed004.EXPERIMENTS["toe-off"].reduce(plan, res)
    assert [x["toe_off_fraction"] for x in out["by_speed"]] == [0.0, 0.1, 0.2]
    assert [(x["terrain"], x["toe_off_fraction"]) for x in out["down_stairs"]] == [(seed004.TOE_OFF_STAIRS, 0.1 * 3)]
