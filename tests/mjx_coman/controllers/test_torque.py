"""The torque-controlled families' shared pieces: the IMU's complementary filter and the start-up ramp."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.torque import filter_joints, filter_orientation, startup_ramp
from mjx_coman.sensors import quat_mul

DT = 0.002


def _angle_deg(a, b):
    return np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(a * b, -1)), 0, 1)))


def _rotvec_quat(v):
    th = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.concatenate([np.cos(th / 2), np.sinc(th / (2 * np.pi)) * v / 2], -1)


@pytest.fixture(scope="module")
def filtered():
    """3 deg white IMU noise at 500 Hz on a pelvis turning at a steady 0.3 rad/s about y; exact gyro."""
    n, w = 1500, np.array([0.0, 0.3, 0.0])
    truth = np.stack([_rotvec_quat(w * DT * k) for k in range(n)])
    noise = _rotvec_quat(np.random.default_rng(0).normal(0.0, np.radians(3.0), (n, 3)))
    imu = np.stack([np.asarray(quat_mul(jnp.asarray(t), jnp.asarray(e))) for t, e in zip(truth, noise)])

    def run(tau):
        def step(q, meas):
            q = filter_orientation(q, meas, jnp.asarray(w, jnp.float32), DT, jnp.asarray(tau, jnp.float32))
            return q, q
        return jax.lax.scan(step, jnp.asarray(imu[0], jnp.float32), jnp.asarray(imu[1:], jnp.float32))[1]

    jitted = jax.jit(run)
    return truth[1:], imu[1:], lambda tau: np.asarray(jitted(tau))


def test_the_filter_averages_the_imu_noise_and_follows_the_gyro(filtered):
    truth, imu, run = filtered
    raw = _angle_deg(imu[500:], truth[500:])
    filt = _angle_deg(run(0.05)[500:], truth[500:])
    assert np.sqrt(np.mean(raw ** 2)) > 4.5  # 3 deg per axis: about 5.2 deg in all
    # first-order averaging over T = 0.05 s (25 ticks): the noise's std falls by about sqrt(a / 2), a = 1/25
    assert np.sqrt(np.mean(filt ** 2)) < 0.25 * np.sqrt(np.mean(raw ** 2))
    assert abs(np.mean(filt) - np.mean(_angle_deg(run(0.05)[-200:], truth[-200:]))) < 0.5  # no drift, no lag build-up


def test_a_zero_time_constant_is_the_raw_imu(filtered):
    truth, imu, run = filtered
    np.testing.assert_allclose(_angle_deg(run(0.0), imu), 0.0, atol=0.1)  # float32 arccos near 1: 0.06 deg


def test_torques_ramp_in_over_the_start_up():
    t = np.arange(40) * DT
    ramp = np.asarray(startup_ramp(jnp.asarray(t), DT, 0.05))
    np.testing.assert_allclose(ramp[:25], (np.arange(25) + 1) / 25, rtol=1e-6)  # linear over 0.05 s
    assert np.all(ramp[24:] == 1.0)
    assert float(startup_ramp(0.0, DT, 0.0)) == 1.0  # none: full torques from the first tick


def test_joint_filter_follows_the_motor_rates_and_averages_the_encoder_noise():
    """A joint swinging at 1 Hz read by encoders with 1 deg of white noise and exact motor rates: the filter's
    error is the noise reduced to about ``sqrt(a / 2)`` (a = dt / T), with no lag; T = 0 passes the encoders."""
    dt, n, std = 0.002, 5000, np.radians(1.0)
    t = np.arange(n) * dt
    true = 0.3 * np.sin(2 * np.pi * t)
    rate = 0.3 * 2 * np.pi * np.cos(2 * np.pi * (t + dt))  # the rate over the next tick (midpoint-accurate enough)
    noisy = true + std * np.random.default_rng(0).normal(size=n)

    def run(T):
        def tick(q, x):
            q = filter_joints(q, x[0][None], x[1][None], dt, T)
            return q, q[0]
        _, out = jax.lax.scan(tick, jnp.asarray([noisy[0]], jnp.float64 if jax.config.jax_enable_x64 else jnp.float32),
                              (jnp.asarray(noisy[1:]), jnp.asarray(rate[:-1])))
        return np.asarray(out) - true[1:]

    err = run(0.1)[1000:]
    a = dt / 0.1
    assert abs(np.mean(err)) < 0.1 * std  # no lag: the motor rates carry the motion
    assert np.std(err) == pytest.approx(std * np.sqrt(a / (2 - a)), rel=0.15)  # AR(1) variance of the noise
    assert np.allclose(run(0.0), noisy[1:] - true[1:], atol=1e-6)  # T = 0: the encoders as read
