"""``wbc-stand``'s tick: filter the IMU, estimate the base, build the standing tasks, solve the QP, send torques."""

from __future__ import annotations

import jax.numpy as jnp

from mjx_coman import wbc
from mjx_coman.controllers import torque
from mjx_coman.controllers.base import standing_telemetry
from mjx_coman.controllers.wbc_stand.config import Config
from mjx_coman.env import MODE_TORQUE, Command

BOTH_FEET = (1.0, 1.0)


def init(config: Config, env_params, key):
    """No orientation yet: the first tick takes the IMU's."""
    return torque.orientation_init(config.com_ref_m.dtype)


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
    state = torque.orientation_step(state, r, config.dt_s, config.imu_filter_s)
    tick = torque.whole_body(r, state.quat, config.sole_anchor_m, jnp.asarray(BOTH_FEET))
    est, plant = tick.base, tick.plant
    extra = {}
    if config.fixed_upper_body:
        extra = dict(fixed_upper_body=True, upper_acc=torque.upper_body_acc(
            config.posture_rad, est.qpos, est.qvel, config.posture_kp_per_s2, config.posture_kd_per_s))
    sol = wbc.solve(plant, tasks(config, plant, est.qpos, est.qvel), jnp.asarray(BOTH_FEET, plant.mass.dtype),
                    tick.tau_min_nm, tick.tau_max_nm, friction_coeff=config.friction_coeff, **extra)
    mid = jnp.mean(config.sole_anchor_m[:, :2], axis=0)
    info = sol.info
    tel = standing_telemetry(dtype, extra=dict(qp_iterations=info.iterations, qp_eq_residual=info.eq_residual.astype(dtype),
                                               qp_ineq_violation=info.ineq_violation.astype(dtype),
                                               qp_kkt_residual=info.kkt_residual.astype(dtype)))
    tel = tel._replace(com_m=(plant.com[:2] - mid).astype(dtype), com_vel_mps=plant.com_vel[:2].astype(dtype), ok=info.ok)
    tau = torque.startup_ramp(obs.time_s, config.dt_s, config.startup_s).astype(dtype) * sol.tau.astype(dtype)
    return state, Command(tau, jnp.zeros(3, dtype), jnp.asarray(MODE_TORQUE, jnp.int32)), tel
