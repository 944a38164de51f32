"""straight-leg's settings and config pytree: validation, variants as array switches, Froude-scaled timing."""

import jax
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman.controllers.straight_leg import config as slc


def test_variants_share_one_tree_structure_and_differ_by_their_switches():
    names = ("straight-leg", "straight-leg-no-toe-off", "bent-knee", "straight-leg-step-adjust")
    cfgs = {n: controllers.default_config(n) for n in names}
    trees = {jax.tree_util.tree_structure(c) for c in cfgs.values()}
    assert len(trees) == 1  # one compiled batch for the family
    assert float(cfgs["straight-leg"].straight_legs) == 1 and float(cfgs["bent-knee"].straight_legs) == 0
    assert float(cfgs["straight-leg"].step_adjust_on) == 0 and float(cfgs["straight-leg-step-adjust"].step_adjust_on) == 1
    assert float(cfgs["straight-leg"].toe_off_on) == 1 and float(cfgs["straight-leg-no-toe-off"].toe_off_on) == 0


def test_timing_is_atlas_scaled_by_the_square_root_of_the_leg_length():
    c = controllers.default_config("straight-leg")
    scale = np.sqrt(0.432 / 0.85)  # COMAN's hip-to-ankle against Atlas's leg
    assert c.swing_s == pytest.approx(0.60 * scale, abs=0.01) and c.transfer_s == pytest.approx(0.25 * scale, abs=0.01)
    assert c.step_time_s == pytest.approx(c.swing_s + c.transfer_s)


def test_tunables_are_array_leaves_that_replace_reaches():
    c = controllers.default_config("straight-leg")
    d = c.replace(icp_gain=3.0)
    assert float(d.icp_gain) == 3.0 and float(c.icp_gain) == 2.5
    assert set(controllers.get("straight-leg").tunables()) <= set(c.leaves)
    with pytest.raises(ValueError, match="swing_s"):
        c.replace(swing_s=0.5)


@pytest.mark.parametrize("kw, name", [
    ({"knee_mode": "crouched"}, "knee_mode"), ({"icp_gain": 1.0}, "icp_gain"), ({"icp_gain": float("nan")}, "icp_gain"),
    ({"swing_s": 0.401}, "swing_s"), ({"transfer_s": 0.5}, "transfer_s"), ({"n_steps": 1}, "n_steps"),
    ({"plant": "position"}, "plant"), ({"step_adjust": "yes"}, "step_adjust"), ({"icp_height_m": -1.0}, "icp_height_m"),
    ({"toe_off": 1}, "toe_off"), ({"contact_slack_weight": 0.0}, "contact_slack_weight"), ({"bogus": 1.0}, "bogus"),
    ({"late_touchdown": "no"}, "late_touchdown"), ({"terrain": "hills"}, "hills"), ({"terrain": 5}, "terrain"),
    ({"stair_overhang_m": 0.5}, "stair_overhang_m"), ({"stair_max_step_m": 1.0}, "stair_max_step_m"),
    ({"stairs_swing_s": 0.401}, "stairs_swing_s"), ({"stairs_swing_s": 5.0}, "stairs_swing_s"),
    ({"terrain": "stairs:5", "stairs_swing_s": 0.15}, "transfer_s"),  # the stairs swing shorter than the transfer
    ({"step_over_fraction": 0.9}, "step_over_fraction"), ({"chest_weight": -1.0}, "chest_weight"),
    ({"joint_limit_horizon_s": 0.0}, "joint_limit_horizon_s"), ({"joint_limit_max_acc": 0.0}, "joint_limit_max_acc"),
    ({"late_max_s": -0.1}, "late_max_s"),
    ({"adjust_deadband_m": float("inf")}, "adjust_deadband_m"), ({"toe_off_load_fraction": 2.0}, "toe_off_load_fraction"),
])
def test_bad_settings_are_value_errors_naming_them(kw, name):
    with pytest.raises(ValueError, match=name):
        slc.make_config(**kw)


def test_the_qp_retry_stops_before_the_full_solve():
    assert controllers.default_config("straight-leg").qp_retry_iter == 0  # off: the iteration keeps its best iterate
    with pytest.raises(ValueError, match="qp_retry_iter"):
        slc.make_config(qp_max_iter=12, qp_retry_iter=12)
