"""Sensor models: quantisation, backlash, IMU, F/T and contact flags."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import sensors
from mjx_coman.actuators import NU

WEIGHT_N = 28.8934 * 9.81


def test_link_encoder_quantum_is_12_bits():
    p = sensors.make_sensor_params()
    assert float(p.encoder_resolution_rad) == pytest.approx(2 * np.pi / 4096, rel=1e-6)
    r = float(p.encoder_resolution_rad)
    x = jnp.array([0.0, 0.4 * r, 0.6 * r, -1.6 * r, 1.0])
    out = np.asarray(sensors.quantize(x, p.encoder_resolution_rad))
    assert out[:4] == pytest.approx([0.0, 0.0, r, -2 * r], abs=1e-9)
    assert abs(out[4] - 1.0) <= r / 2 + 1e-7


def test_backlash_is_a_dead_band_with_memory():
    w = jnp.asarray(0.02)
    y = jnp.asarray(0.0)
    trace = []
    for x in [0.005, 0.01, 0.02, 0.015, 0.005, -0.01]:
        y = sensors.backlash(y, jnp.asarray(x), w)
        trace.append(float(y))
    assert trace == pytest.approx([0.0, 0.0, 0.01, 0.01, 0.01, 0.0], abs=1e-7)


@pytest.mark.parametrize("rpy", [(0.1, 0.0, 0.0), (0.0, -0.2, 0.0), (0.0, 0.0, 0.7), (0.05, 0.1, -0.3)])
def test_quat_to_rpy_round_trip(rpy):
    def axis_quat(axis, angle):
        v = np.zeros(3)
        v[axis] = np.sin(angle / 2)
        return jnp.asarray(np.concatenate([[np.cos(angle / 2)], v]))

    roll, pitch, yaw = rpy
    q = sensors.quat_mul(axis_quat(2, yaw), sensors.quat_mul(axis_quat(1, pitch), axis_quat(0, roll)))
    assert np.asarray(sensors.quat_to_rpy(q)) == pytest.approx(rpy, abs=1e-6)


def test_noise_depends_only_on_the_key(stand_run):
    final, _ = stand_run
    p = sensors.make_sensor_params(gyro_noise_rad_per_s=0.1)
    st = sensors.init_sensor_state(final.data.qpos[7:])
    read = lambda k: sensors.read_sensors(p, st, k, final.data, final.actuator.motor_angle_rad,
                                          final.actuator.motor_vel_rad_per_s)[1]
    a, b, c = read(jax.random.PRNGKey(1)), read(jax.random.PRNGKey(1)), read(jax.random.PRNGKey(2))
    assert np.array_equal(a.gyro_rad_per_s, b.gyro_rad_per_s)
    assert not np.array_equal(a.gyro_rad_per_s, c.gyro_rad_per_s)
    assert float(jnp.linalg.norm(a.imu_quat)) == pytest.approx(1.0, abs=1e-5)


def test_standing_feet_carry_the_weight(stand_run):
    final, rec = stand_run
    total = rec["normal_n"][-50:].sum(axis=1)
    assert np.mean(total) == pytest.approx(WEIGHT_N, rel=0.03)
    assert bool(np.all(final.readings.contact))
    # the F/T normal force equals the contact normal force (sensor frame ~ world when flat)
    assert float(final.readings.ft_right[2]) == pytest.approx(float(final.readings.foot_normal_force_n[0]), abs=3.0)
    # each ankle carries about half the weight
    assert rec["normal_n"][-1] == pytest.approx([WEIGHT_N / 2] * 2, rel=0.1)


def test_link_encoders_track_the_links(stand_run):
    final, _ = stand_run
    err = np.asarray(final.readings.link_angle_rad - final.data.qpos[7:])
    assert np.max(np.abs(err)) <= np.pi / 4096 + 1e-6


@pytest.mark.parametrize(
    "kwargs,name",
    [
        (dict(encoder_bits=0), "encoder_bits"),
        (dict(backlash_rad=-0.01), "backlash_rad"),
        (dict(gyro_noise_rad_per_s=-1.0), "gyro_noise_rad_per_s"),
        (dict(contact_threshold_n=float("inf")), "contact_threshold_n"),
        (dict(encoder_offset_rad=np.full(NU, np.nan)), "encoder_offset_rad"),
    ],
)
def test_bad_sensor_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        sensors.make_sensor_params(**kwargs)
