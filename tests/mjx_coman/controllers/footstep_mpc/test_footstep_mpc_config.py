"""footstep-mpc's settings' checks and its step timing and start-up CoM shift (pure pieces of the tick)."""

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.footstep_mpc.config import make_config
from mjx_coman.controllers.footstep_mpc.controller import start_com_m, step_timing


@pytest.fixture(scope="module")
def config():
    return make_config()


@pytest.mark.parametrize("kw, name", [(dict(step_time_s=0.401), "step_time_s"), (dict(step_time_s=0.1), "step_time_s"),
                                      (dict(mpc_solver="osqp"), "mpc_solver"), (dict(plant="position"), "plant"),
                                      (dict(n_steps=0), "n_steps"), (dict(half_width_m=0.01), "half_width_m"),
                                      (dict(clearance_m=float("nan")), "clearance_m"), (dict(foo=1.0), "foo"),
                                      (dict(double_support_s=0.3), "double_support_s"),
                                      (dict(double_support_s=-0.01), "double_support_s"),
                                      (dict(contact_slack_weight=-1.0), "contact_slack_weight"),
                                      (dict(contact_slack_weight=float("inf")), "contact_slack_weight"),
                                      (dict(qp_max_iter=0), "qp_max_iter"), (dict(qp_max_iter=2.5), "qp_max_iter")])
def test_bad_settings_name_the_value(kw, name):
    with pytest.raises(ValueError, match=name):
        make_config(**kw)


def test_steps_start_after_the_start_and_last_step_time_s(config):
    t = jnp.asarray([0.0, config.start_s - 0.002, config.start_s, config.start_s + 0.398, config.start_s + 0.4,
                     config.start_s + 0.81])
    k, t_in = step_timing(config, t)
    np.testing.assert_array_equal(np.asarray(k), [-1, -1, 0, 0, 1, 2])
    np.testing.assert_allclose(np.asarray(t_in), [0.0, 0.0, 0.0, 0.398, 0.0, 0.01], atol=1e-5)


def test_the_start_shifts_the_com_onto_the_right_foot_and_arrives_at_rest(config):
    p0, v0, a0 = start_com_m(config, jnp.asarray(0.0))
    p1, v1, a1 = start_com_m(config, jnp.asarray(config.start_s))
    right, left = np.asarray(config.sole_anchor_m)
    assert np.isclose(float(p0[1]), (right[1] + left[1]) / 2, atol=1e-6)  # between the feet
    assert np.isclose(float(p0[1] - p1[1]), float(config.shift_m), atol=1e-6)  # toward the right foot (y < 0)
    assert float(p1[0]) > right[0]  # over the sole centre, ahead of the ankles
    np.testing.assert_allclose(np.asarray([v0, a0, v1, a1]), 0.0, atol=1e-6)
    assert np.isclose(float(p1[2]), float(config.com_ref_m[2]))


def test_the_qp_torque_bounds_are_the_stall_torque_and_contain_the_voltage_bounds_at_any_rate():
    from mjx_coman.actuators import make_actuator_params, torque_limits_nm
    from mjx_coman.controllers.footstep_mpc.controller import stall_torque_nm

    lo, hi = (np.asarray(b) for b in stall_torque_nm(jnp.zeros(23)))
    p = make_actuator_params()
    stall = np.asarray(p.supply_v / p.beta_v_per_nm)
    assert np.allclose(hi, stall) and np.allclose(lo, -stall)
    for rate in (-8.0, -1.0, 0.5, 8.0):
        vlo, vhi = (np.asarray(b) for b in torque_limits_nm(p, jnp.full(23, rate)))
        assert np.all(lo <= vlo + 1e-6) and np.all(vhi <= hi + 1e-6)
