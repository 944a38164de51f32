"""What the torque-controlled families (``wbc-stand``, ``footstep-mpc``) share: the crouched stance's references,
the orientation filter, the start-up ramp of the torques, and the estimated floating base with its whole-body terms."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_coman import dynamics, load_model, wbc
from mjx_coman.actuators import make_actuator_params, torque_limits_nm
from mjx_coman.env import standing_posture
from mjx_coman.floating_base import BaseState, estimate, nominal_model, sole_site_ids
from mjx_coman.sensors import quat_mul

UPPER = slice(12, 23)  # waist and arm joints (mjx_coman.actuators.JOINT_NAMES)


class OrientationState(NamedTuple):
    """The filtered pelvis orientation (w, x, y, z) and whether it holds one yet."""

    quat: jax.Array
    started: jax.Array


def orientation_init(dtype) -> OrientationState:
    """No orientation yet: the first tick takes the IMU's."""
    return OrientationState(jnp.asarray([1.0, 0.0, 0.0, 0.0], dtype), jnp.zeros((), bool))


def filter_orientation(quat, imu_quat, gyro_rad_per_s, dt_s, time_constant_s):
    """Complementary filter: ``q <- q (1, w dt / 2)`` by the gyro (pelvis frame), then ``q <- nlerp(q, q_imu,
    dt / max(T, dt))`` toward the IMU (its white noise averaged over about ``T``, the gyro's drift corrected)."""
    q = quat_mul(quat, jnp.concatenate([jnp.ones(1, quat.dtype), 0.5 * dt_s * gyro_rad_per_s.astype(quat.dtype)]))
    q_imu = imu_quat.astype(quat.dtype)
    q_imu = jnp.where(jnp.dot(q, q_imu) < 0, -q_imu, q_imu)
    a = dt_s / jnp.maximum(time_constant_s, dt_s)
    q = (1.0 - a) * q + a * q_imu
    return q / jnp.linalg.norm(q)


def filter_joints(joint_rad, link_angle_rad, motor_vel_rad_per_s, dt_s, time_constant_s):
    """Complementary filter of the link encoders: ``q <- q + qd_motor dt`` by the motor encoders' rates (exact
    at rigid joints; at series-elastic ones they differ by the spring's deflection rate), then
    ``q <- q + a (q_link - q)`` with ``a = dt / max(T, dt)`` (``T = 0``: the link encoders as read). White
    encoder noise of std s leaves about ``s sqrt(a / 2)``."""
    f = joint_rad.dtype
    q = joint_rad + dt_s * motor_vel_rad_per_s.astype(f)
    a = dt_s / jnp.maximum(time_constant_s, dt_s)
    return q + a * (link_angle_rad.astype(f) - q)


def orientation_step(state: OrientationState, readings, dt_s: float, time_constant_s) -> OrientationState:
    """One tick of :func:`filter_orientation` (the IMU's own reading on the first tick)."""
    f = state.quat.dtype
    quat = jnp.where(state.started, filter_orientation(state.quat, readings.imu_quat, readings.gyro_rad_per_s, dt_s,
                                                       time_constant_s), readings.imu_quat.astype(f))
    return OrientationState(quat, jnp.ones((), bool))


def startup_ramp(time_s, dt_s: float, startup_s: float):
    """``min(1, (t + dt) / startup_s)``: the share of the QP's torques sent at the tick starting at ``t``.

    The reset stands the robot on the floor without contact force, and full torques on a foot that bears no
    load yet spin it (ankle torques of 14 N m on a 5 deg downhill did, and the simulation blew up)."""
    return jnp.clip((time_s + dt_s) / max(startup_s, dt_s), 0.0, 1.0)


class Tick(NamedTuple):
    """The estimated base, the whole-body terms of the nominal model there, and this tick's torque limits."""

    base: BaseState
    plant: wbc.Plant
    tau_min_nm: jax.Array
    tau_max_nm: jax.Array


def whole_body(readings, quat, anchor_m, stance) -> Tick:
    """The floating base from the filtered orientation ``quat`` and the stance soles on ``anchor_m``
    (:func:`mjx_coman.floating_base.estimate`), the nominal model's whole-body terms there
    (:func:`mjx_coman.dynamics.terms`) and the controller's motor model's torque limits at the joint rates."""
    est = estimate(readings._replace(imu_quat=quat.astype(readings.imu_quat.dtype)), anchor_m, stance)
    model, _ = nominal_model()
    plant = wbc.plant_from(dynamics.terms(model, est.data))
    lo, hi = torque_limits_nm(make_actuator_params(), est.qvel[6:])
    return Tick(est, plant, lo, hi)


def upper_body_acc(posture_rad, qpos, qvel, kp, kd):
    """Waist and arm accelerations held outside the QP (seed 001's fixed upper body): a joint PD to ``posture_rad``."""
    return wbc.joint_pd(posture_rad[UPPER], qpos[7:][UPPER], qvel[6:][UPPER], kp, kd)


@functools.lru_cache(maxsize=4)
def stance_references(knee_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(posture (23,), CoM (3,), sole anchors (2, 3))`` of the crouched stance the env resets to (MuJoCo C).

    The CoM's x-y is the mid-point of the sole sites (under the ankles); ``com_ahead_m`` moves it forward.
    """
    q, root = standing_posture(knee_rad)
    m = load_model()
    d = mujoco.MjData(m)
    d.qpos[:7], d.qpos[7:] = root, q
    mujoco.mj_forward(m, d)
    soles = d.site_xpos[sole_site_ids()].copy()
    com = np.array(d.subtree_com[1])
    com[:2] = soles[:, :2].mean(axis=0)
    return q, com, soles
