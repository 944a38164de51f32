"""The plants' environments: the walking gains, the torque loops and their delays."""

import numpy as np
import pytest

from mjx_coman.actuators import JOINT_INDEX, TORQUE_LOOPS, default_kp_v_per_rad
from mjx_coman.plants import SEA_TORQUE_DELAY_S, plant_env_params, walking_env_params


def test_walking_env_params_rejects_a_bad_gain():
    with pytest.raises(ValueError, match="ankle_roll_kp"):
        walking_env_params(0.0)


def test_walking_gains_are_the_seeds_but_a_stiffer_ankle_roll():
    kp = np.asarray(walking_env_params(250.0).actuator.kp_v_per_rad)
    roll = [JOINT_INDEX["RAnkLat"], JOINT_INDEX["LAnkLat"]]
    np.testing.assert_allclose(kp[roll], 250.0)
    others = np.ones(len(kp), bool)
    others[roll] = False
    np.testing.assert_allclose(kp[others], np.asarray(default_kp_v_per_rad())[others])


def test_each_plant_gets_its_torque_loop_and_delay():
    ideal, sea = plant_env_params("torque-ideal").actuator, plant_env_params("torque-sea").actuator
    assert int(ideal.torque_loop) == TORQUE_LOOPS["ideal"] and int(sea.torque_loop) == TORQUE_LOOPS["sea"]
    assert int(ideal.delay_ticks) == 0 and int(sea.delay_ticks) == round(SEA_TORQUE_DELAY_S / 0.002) == 5
    with pytest.raises(ValueError, match="plant='current'"):
        plant_env_params("current")
