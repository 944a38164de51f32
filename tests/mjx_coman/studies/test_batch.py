"""The rows' environments and checks (the batched walk itself runs in tests/mjx_coman/test_notebook_06.py)."""

import numpy as np
import pytest

from mjx_coman import actuators, rollout as ro
from mjx_coman.scenarios import Scenario
from mjx_coman.studies import batch


def test_each_row_gets_its_scenario_and_actuator_values():
    rows = [batch.Row(), batch.Row(scenario=Scenario(delay_ms=10.0, imu_noise_deg=3.0)),
            batch.Row(actuator=(("torque_loop", "sea"), ("delay_s", 0.01), ("torque_bandwidth_hz", 5.0))),
            batch.Row(scenario=Scenario(slope_deg=10.0, payload_kg=1.0))]
    env, axes = batch._env("torque-ideal", rows)
    act = env.actuator
    assert np.asarray(act.delay_ticks).tolist() == [0, 5, 5, 0]  # 2 ms ticks: 10 ms of scenario or of the loop
    assert np.asarray(act.torque_loop).tolist() == [actuators.TORQUE_LOOPS[k] for k in ("ideal", "ideal", "sea",
                                                                                         "ideal")]
    assert np.asarray(act.torque_bandwidth_hz)[2] == 5.0
    assert np.asarray(env.sensor.imu_orientation_noise_rad)[1] == pytest.approx(np.radians(3.0))
    g = np.asarray(env.model.opt.gravity)
    assert np.allclose(g[0], [0, 0, -9.81]) and g[3, 0] < 0  # the slope tilts gravity back (+x uphill)
    mass = np.asarray(env.model.body_mass)
    assert mass[3].sum() == pytest.approx(mass[0].sum() + 1.0, rel=1e-6)
    base = ro.plant_env_params("torque-ideal")
    assert int(np.asarray(base.actuator.delay_ticks)) == 0


@pytest.mark.parametrize("row,seconds,match", [
    (batch.Row(forward_mps=0.9), 5.0, "0.9"),
    (batch.Row(push_ns=3.0, push_start_s=4.9), 5.0, "after the walk"),
    (batch.Row(scenario=Scenario(slope_deg=45.0)), 5.0, "slope_deg=45"),
    (batch.Row(), float("nan"), "seconds=nan"),
])
def test_bad_rows_are_refused_naming_the_value(row, seconds, match):
    with pytest.raises(ValueError, match=match):
        batch.check_rows("footstep-mpc", [row], seconds)
    with pytest.raises(ValueError, match="no rows"):
        batch.check_rows("footstep-mpc", [], 1.0)
