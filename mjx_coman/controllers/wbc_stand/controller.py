"""``wbc-stand``'s tick: filter the IMU, estimate the base, build the standing tasks, solve the QP, send torques."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman import dynamics, wbc
from mjx_coman.actuators import make_actuator_params, torque_limits_nm
from mjx_coman.controllers.base import Telemetry, standing_telemetry
from mjx_coman.controllers.wbc_stand.config import Config
from mjx_coman.env import MODE_TORQUE, Command
from mjx_coman.floating_base import estimate, nominal_model
from mjx_coman.sensors import quat_mul

UPPER = slice(12, 23)  # waist and arm joints (mjx_coman.actuators.JOINT_NAMES)
BOTH_FEET = (1.0, 1.0)


class State(NamedTuple):
    """The filtered pelvis orientation (w, x, y, z) and whether it holds one yet."""

    quat: jax.Array
    started: jax.Array


def init(config: Config, env_params, key):
    """No orientation yet: the first tick takes the IMU's."""
    f = config.com_ref_m.dtype
    return State(jnp.asarray([1.0, 0.0, 0.0, 0.0], f), jnp.zeros((), bool))


def filter_orientation(quat, imu_quat, gyro_rad_per_s, dt_s, time_constant_s):
    """Complementary filter: ``q <- q (1, w dt / 2)`` by the gyro (pelvis frame), then ``q <- nlerp(q, q_imu,
    dt / max(T, dt))`` toward the IMU (its white noise averaged over about ``T``, the gyro's drift corrected)."""
    q = quat_mul(quat, jnp.concatenate([jnp.ones(1, quat.dtype), 0.5 * dt_s * gyro_rad_per_s.astype(quat.dtype)]))
    q_imu = imu_quat.astype(quat.dtype)
    q_imu = jnp.where(jnp.dot(q, q_imu) < 0, -q_imu, q_imu)
    a = dt_s / jnp.maximum(time_constant_s, dt_s)
    q = (1.0 - a) * q + a * q_imu
    return q / jnp.linalg.norm(q)


def tasks(config: Config, plant: wbc.Plant, qpos, qvel) -> list:
    """CoM PD to the stance's CoM; pelvis and torso upright; joint posture PD; regularizations."""
    c = config
    up = jnp.eye(3, dtype=qvel.dtype)
    com_ref = c.com_ref_m + jnp.stack([c.com_ahead_m, jnp.zeros_like(c.com_ahead_m), jnp.zeros_like(c.com_ahead_m)])
    com_acc = wbc.position_pd(com_ref, plant.com, 0.0, plant.com_vel, c.com_kp_per_s2, c.com_kd_per_s)
    pelvis_acc = wbc.orientation_pd(up, plant.pelvis_rot, 0.0, plant.pelvis_jac[3:] @ qvel, c.base_kp_per_s2,
                                    c.base_kd_per_s)
    torso_acc = wbc.orientation_pd(up, plant.torso_rot, 0.0, plant.torso_jac[3:] @ qvel, c.base_kp_per_s2,
                                   c.base_kd_per_s)
    return [wbc.com_task(plant, com_acc, c.com_weight),
            wbc.pelvis_orientation_task(plant, pelvis_acc, c.base_weight),
            wbc.torso_orientation_task(plant, torso_acc, c.base_weight),
            wbc.posture_task(qpos[7:], qvel[6:], c.posture_rad, c.posture_kp_per_s2, c.posture_kd_per_s,
                             c.posture_weight),
            wbc.qdd_regularization(c.qdd_weight, qvel.shape[0]),
            wbc.force_regularization(c.force_weight_per_n2),
            wbc.force_distribution_task(plant.contact_pos, plant.com, c.force_weight_per_n2)]


def step(config: Config, state, obs):
    r = obs.readings
    dtype = r.motor_angle_rad.dtype
    f = config.com_ref_m.dtype
    quat = jnp.where(state.started, filter_orientation(state.quat, r.imu_quat, r.gyro_rad_per_s, config.dt_s,
                                                       config.imu_filter_s), r.imu_quat.astype(f))
    state = State(quat, jnp.ones((), bool))
    est = estimate(r._replace(imu_quat=quat.astype(r.imu_quat.dtype)), config.sole_anchor_m, jnp.asarray(BOTH_FEET))
    model, _ = nominal_model()
    plant = wbc.plant_from(dynamics.terms(model, est.data))
    lo, hi = torque_limits_nm(make_actuator_params(), est.qvel[6:])  # the controller's motor model
    extra = {}
    if config.fixed_upper_body:
        extra = dict(fixed_upper_body=True, upper_acc=wbc.joint_pd(
            config.posture_rad[UPPER], est.qpos[7:][UPPER], est.qvel[6:][UPPER], config.posture_kp_per_s2,
            config.posture_kd_per_s))
    sol = wbc.solve(plant, tasks(config, plant, est.qpos, est.qvel), jnp.asarray(BOTH_FEET, plant.mass.dtype),
                    lo, hi, friction_coeff=config.friction_coeff, **extra)
    mid = jnp.mean(config.sole_anchor_m[:, :2], axis=0)
    info = sol.info
    tel = standing_telemetry(dtype, extra=dict(qp_iterations=info.iterations, qp_eq_residual=info.eq_residual.astype(dtype),
                                               qp_ineq_violation=info.ineq_violation.astype(dtype),
                                               qp_kkt_residual=info.kkt_residual.astype(dtype)))
    tel = tel._replace(com_m=(plant.com[:2] - mid).astype(dtype), com_vel_mps=plant.com_vel[:2].astype(dtype), ok=info.ok)
    tau = startup_ramp(obs.time_s, config.dt_s, config.startup_s).astype(dtype) * sol.tau.astype(dtype)
    return state, Command(tau, jnp.zeros(3, dtype), jnp.asarray(MODE_TORQUE, jnp.int32)), tel


def startup_ramp(time_s, dt_s: float, startup_s: float):
    """``min(1, (t + dt) / startup_s)``: the share of the QP's torques sent at the tick starting at ``t``.

    The reset stands the robot on the floor without contact force, and full torques on a foot that bears no
    load yet spin it (ankle torques of 14 N m on a 5 deg downhill did, and the simulation blew up)."""
    return jnp.clip((time_s + dt_s) / max(startup_s, dt_s), 0.0, 1.0)
