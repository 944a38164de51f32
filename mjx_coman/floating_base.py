"""The floating base from the robot's own sensors, for torque controllers: ``estimate``.

A whole-body QP needs the full state ``(qpos, qvel)``, but the robot measures
only joint angles and rates, the IMU orientation and rate. With the stance
feet assumed flat and still (they are the anchor), leg kinematics gives the
rest: the base is where the measured joint angles put it relative to the
anchored soles,

    p_base = mean_f (a_f - R_imu * r_f(q)),     v_base = -mean_f J_f,lin(q) [0, w_gyro, qdot],

with ``r_f`` the sole of foot ``f`` relative to the base origin (the foot
velocity with a still base is ``J_f qvel`` with the base's linear velocity
zero, and translating the whole robot moves every point alike). The
controller's model is the nominal COMAN (:func:`nominal_model`): a payload or
slope of a scenario is a model error to it, as on the real robot.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_coman import dynamics, load_model


@functools.lru_cache(maxsize=2)
def _nominal(dtype_name: str) -> tuple[mjx.Model, mjx.Data]:
    with jax.ensure_compile_time_eval():  # concrete arrays even when first asked for inside a trace
        model = mjx.put_model(load_model())
        return model, mjx.make_data(model)


def nominal_model() -> tuple[mjx.Model, mjx.Data]:
    """The controller's own model of COMAN (``mjx.Model``) and a blank ``mjx.Data``, in JAX's default float."""
    return _nominal(jnp.dtype(jnp.result_type(float)).name)


def sole_site_ids() -> np.ndarray:
    """Site ids of the right and left soles (foot index 0 = right, as :mod:`mjx_coman.dynamics`)."""
    m = load_model()
    return np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n) for n in dynamics.SOLE_SITES])


def corner_site_ids(model: mujoco.MjModel | None = None) -> np.ndarray:
    """(2, 4) site ids of the sole corners ``{r,l}_foot_<corner>``: right foot first, corners in
    :data:`mjx_coman.dynamics.CORNERS` order."""
    m = load_model() if model is None else model
    return np.array([[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{f}_foot_{c}") for c in dynamics.CORNERS]
                     for f in ("r", "l")])


class BaseState(NamedTuple):
    """The estimated full state and the whole-body terms at it.

    Attributes:
        qpos: (nq,) base position (anchored), IMU orientation, joint encoders.
        qvel: (nv,) base velocity (from the anchored feet), gyro, joint rates.
        data: ``mjx.Data`` of the nominal model at that state (kinematics, com_pos, com_vel run).
    """

    qpos: jax.Array
    qvel: jax.Array
    data: mjx.Data


def estimate(readings, anchor_m: jax.Array, stance: jax.Array) -> BaseState:
    """The floating-base state that puts the stance soles on their anchors.

    Args:
        readings: :class:`mjx_coman.sensors.Readings` (link encoders, motor rates, IMU, gyro).
        anchor_m: (2, 3) world positions of the (right, left) sole sites when in stance.
        stance: (2,) weights of the feet taken as still (e.g. ``[1, 1]`` standing); not both zero.

    Joint angles are the link encoders'; joint rates are the motor encoders'
    rates (the link's at rigid joints; at series-elastic joints they differ
    by the spring's deflection rate).
    """
    model, blank = nominal_model()
    f = blank.qpos.dtype
    quat = readings.imu_quat.astype(f)
    q = readings.link_angle_rad.astype(f)
    qvel0 = jnp.concatenate([jnp.zeros(3, f), readings.gyro_rad_per_s.astype(f), readings.motor_vel_rad_per_s.astype(f)])
    d0 = dynamics.prepare(model, blank.replace(qpos=jnp.concatenate([jnp.zeros(3, f), quat, q]), qvel=qvel0))
    ids = sole_site_ids()
    w = jnp.asarray(stance, f) / jnp.sum(jnp.asarray(stance, f))
    base = jnp.sum(w[:, None] * (anchor_m.astype(f) - d0.site_xpos[ids]), axis=0)
    foot_vel = jnp.stack([dynamics.site_jacobian(model, d0, int(i))[:3] @ qvel0 for i in ids])
    qpos = jnp.concatenate([base, quat, q])
    qvel = qvel0.at[:3].set(-jnp.sum(w[:, None] * foot_vel, axis=0))
    return BaseState(qpos, qvel, dynamics.prepare(model, blank.replace(qpos=qpos, qvel=qvel)))
