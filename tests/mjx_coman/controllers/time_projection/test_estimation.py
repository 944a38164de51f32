"""Tests of the time-projection estimation: 3LP relative state from encoders + IMU, filters, error (eq. 15, 26)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from jaxlp import filters
from mjx_coman import load_model
from mjx_coman.actuators import JOINT_INDEX, NU
from mjx_coman.env import standing_posture
from mjx_coman.sensors import Readings, quat_to_rpy
from mjx_coman.controllers.time_projection import estimation as est
from mjx_coman.ground_truth import foot_body_ids

EXACT_TOL_M = 1e-5  # FK of exact angles against MuJoCo (float32)
QUANT_TOL_M = 4e-3  # 12-bit link encoders: 1.5 mrad per joint, six joints per leg, ~0.5 m lever arms
POSES = [
    dict(hip=(-0.2, 0.1), knee=(0.6, 0.3), roll=0.0, pitch=0.0, yaw=0.0),
    dict(hip=(0.15, -0.25), knee=(0.2, 0.9), roll=0.08, pitch=-0.1, yaw=0.7),
    dict(hip=(-0.4, 0.05), knee=(1.0, 0.4), roll=-0.15, pitch=0.2, yaw=-2.0),
]


def _quat(roll, pitch, yaw):
    q = np.zeros(4)
    mujoco.mju_euler2Quat(q, np.array([roll, pitch, yaw]), "XYZ")  # extrinsic x, y, z = intrinsic ZYX
    return q


def _pose(p):
    """Native MuJoCo data of a leg pose with the pelvis at an orientation; plus the (23,) joint angles."""
    m = load_model()
    d = mujoco.MjData(m)
    q = np.array(standing_posture()[0])
    for s, hip, knee in (("L", p["hip"][0], p["knee"][0]), ("R", p["hip"][1], p["knee"][1])):
        q[JOINT_INDEX[s + "HipSag"]] = hip
        q[JOINT_INDEX[s + "KneeSag"]] = knee
        q[JOINT_INDEX[s + "AnkSag"]] = -(hip + knee) + 0.1
        q[JOINT_INDEX[s + "HipLat"]] = 0.05 if s == "L" else -0.08
        q[JOINT_INDEX[s + "AnkLat"]] = -0.03
        q[JOINT_INDEX[s + "HipYaw"]] = 0.04
    d.qpos[:3] = (0.3, -0.2, 0.5)
    d.qpos[3:7] = _quat(p["roll"], p["pitch"], p["yaw"])
    d.qpos[7:] = q
    mujoco.mj_kinematics(m, d)
    return d, q


def _readings(link_q, quat):
    z = jnp.zeros(NU)
    return Readings(link_angle_rad=jnp.asarray(link_q, jnp.float32), motor_angle_rad=z, motor_vel_rad_per_s=z,
                    imu_quat=jnp.asarray(quat, jnp.float32), imu_rpy_rad=quat_to_rpy(jnp.asarray(quat)),
                    gyro_rad_per_s=jnp.zeros(3), ft_right=jnp.zeros(6), ft_left=jnp.zeros(6),
                    foot_normal_force_n=jnp.zeros(2), contact=jnp.zeros(2, bool))


@pytest.mark.parametrize("pose", POSES)
@pytest.mark.parametrize("d", [1.0, -1.0])
def test_measured_relative_state_matches_mujoco_truth(pose, d):
    """Encoders + IMU -> 3LP relative positions equal the simulator's poses in the heading frame."""
    data, q = _pose(pose)
    truth = est.relative_from_feet(*est.true_feet(data, foot_body_ids(), 1), d)
    exact = est.measure_relative(_readings(q, data.qpos[3:7]), d)
    np.testing.assert_allclose(exact, truth, atol=EXACT_TOL_M)
    quantum = 2 * np.pi / 4096
    coarse = est.measure_relative(_readings(np.round(q / quantum) * quantum, data.qpos[3:7]), d)
    assert np.max(np.abs(np.asarray(coarse) - np.asarray(truth))) < QUANT_TOL_M


@pytest.mark.parametrize("d", [1.0, -1.0])
def test_relative_positions_pick_swing_and_stance_by_phase(d):
    left, right = jnp.array([0.1, 0.08, -0.4]), jnp.array([-0.05, -0.07, -0.41])
    rel = np.asarray(est.relative_from_feet(left, right, d))
    swing, stance = (left, right) if d > 0 else (right, left)
    np.testing.assert_allclose(rel[:, 0], (swing - stance)[:2], atol=1e-7)  # s1 = swing - stance
    np.testing.assert_allclose(rel[:, 1], -stance[:2], atol=1e-7)  # s2 = pelvis - stance
    assert np.sign(rel[1, 0]) == np.sign(d)  # the swing foot is on the d side


def test_filter_converges_and_estimates_velocity():
    """Eq. 26 IIR: a ramp s = v t is tracked with a lag and its slope recovered once the window is full."""
    zeta, dt, v = 0.1, 0.002, np.array([[0.3, -0.1], [0.05, 0.2]])
    state = est.estimator_init(30)
    q_nom = jnp.zeros((2, 6))
    step = jax.jit(lambda s, raw: est.estimator_step(s, raw, q_nom, 1.0, zeta, dt))
    for k in range(300):
        state, e = step(state, jnp.asarray(v * k * dt, jnp.float32))
    np.testing.assert_allclose(e.vel_mps, v, rtol=2e-3, atol=2e-4)
    lag = (1 - zeta) / zeta * dt  # steady-state lag of the IIR on a ramp, s
    np.testing.assert_allclose(e.pos_m, v * (299 * dt - lag), atol=2e-5)
    np.testing.assert_allclose(e.error[:, :2], e.pos_m, atol=1e-7)  # zero nominal: error = state


def test_swap_keeps_positions_consistent_and_pelvis_velocity():
    """At a phase change s1' = -s1, s2' = s2 - s1; with both feet down the pelvis velocity carries over."""
    state = est.estimator_init(30)
    for k in range(40):
        state, _, _ = filters.filter_step(state, jnp.array([[0.1 + 0.4 * k * 0.002, 0.02 + 0.3 * k * 0.002],
                                                            [0.14, 0.07]]), 0.1, 0.002)
    new = est.estimator_swap(state)
    p = np.asarray(state.position)
    np.testing.assert_allclose(new.position[:, 0], -p[:, 0], atol=1e-7)
    np.testing.assert_allclose(new.position[:, 1], p[:, 1] - p[:, 0], atol=1e-7)
    np.testing.assert_allclose(jnp.mean(new.diffs, 0)[:, 0], 0.0, atol=1e-7)
    np.testing.assert_allclose(jnp.mean(new.diffs, 0)[:, 1], jnp.mean(state.diffs, 0)[:, 1], atol=1e-6)


@pytest.mark.parametrize("d", [1.0, -1.0])
def test_nominal_error_is_zero_on_the_nominal_and_mirrors_lateral(d):
    q = jnp.array([[0.05, 0.02, 0.0, 0.3, 0.2, 0.0], [0.1, 0.05, 0.0, -0.1, 0.2, 0.0]]) * jnp.array([[1.0], [d]])
    pos, vel = est.nominal_relative(q)
    np.testing.assert_allclose(est.nominal_error(pos, vel, q, d), 0.0, atol=1e-7)
    bumped = est.nominal_error(pos.at[1, 1].add(0.01), vel, q, d)
    assert float(bumped[1, 1]) == pytest.approx(0.01 * d, abs=1e-6)  # lateral error in the d = +1 frame


EST_TOL_M = 6e-3  # encoders (12 bit) + IMU noise against the simulator's truth, during a walk


@pytest.mark.parametrize("name", ["time-projection", "open-loop"])
def test_state_estimate_matches_the_simulator_during_a_walk(family_walks, name):
    """The controller's measured relative positions (encoders + IMU) against the true poses of the shared walk."""
    from mjx_coman.kinematics import quat_to_rot, rot_z

    batch = family_walks(name)
    rows, res = batch.rows, batch.res
    i = next(i for i, (n, p, _, d) in enumerate(rows) if n == name and p is None and d == 0.0)
    saved = jax.tree_util.tree_map(lambda x: x[i], res.saved)
    d = saved["telemetry"].extra[batch.member].d

    def truth(feet, pelvis, quat, d):
        rot = quat_to_rot(quat)
        to_heading = rot_z(-jnp.arctan2(rot[1, 0], rot[0, 0]))
        left, right = (to_heading @ (feet[j] - pelvis) for j in (0, 1))
        return est.relative_from_feet(left, right, d)

    true_rel = jax.vmap(truth)(saved["feet_m"], saved["pelvis_m"], saved["pelvis_quat"], d)
    measured = jax.vmap(est.measure_relative)(saved["readings"], d)
    err = np.abs(np.asarray(measured) - np.asarray(true_rel))
    assert err.max() < EST_TOL_M, err.max(axis=0)
