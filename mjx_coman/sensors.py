"""COMAN's sensors in JAX: encoders, pelvis IMU, ankle F/T, foot contact.

Seed 000 ("Sensor Quality"): motor-side optical encoders are precise;
link-side absolute encoders cover 360 degrees with 12 bits (quantum
``2 pi / 4096`` rad) and the joints show backlash. The pelvis IMU gives the
orientation and the angular rate. Six-axis force/torque sensors sit 0.065 m
below each ankle pitch axis; here they read the ground reaction wrench of
their foot (from the solved contact forces), expressed in the sensor frame.

Noise is Gaussian and drawn from explicit PRNG keys passed in by the caller
and split here. All constants live in :class:`SensorParams` (vmappable).

The IMU measures relative to gravity, as a real one does: in a scene whose
gravity a scenario rotates (a slope, :mod:`mjx_coman.scenarios`), the
orientation is expressed in the gravity-aligned frame, so a robot standing on
the slope reads the tilt; the gyro measures in the pelvis frame either way.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_coman.actuators import NU

N_CONTACTS = 8  # four sole-corner spheres per foot, right foot first
EFC_ROWS_PER_CONTACT = 4  # condim 3, pyramidal cone


@functools.lru_cache(maxsize=1)
def model_ids() -> dict:
    """Static MuJoCo ids used by the sensors and the environment (ints; the foot sphere geoms as tuples).

    Taken from the packaged model; a custom ``MjModel`` passed to
    ``make_env_params`` must keep the same bodies, geoms and sites in the same
    order (the scene variants of :func:`mjx_coman.mjcf.scene_xml` add theirs after the robot's).
    """
    from mjx_coman import load_model

    m = load_model()

    def site(n):
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n)

    def body(n):
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)

    def geom(n):
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n)

    from mjx_coman.mjcf import foot_contact_geoms

    feet = tuple(geom(n) for n in foot_contact_geoms())  # right foot's four, then the left's
    return dict(
        n_robot_bodies=m.nbody,  # a scene variant's gravity frame is body n_robot_bodies (mjx_coman.mjcf.scene_xml)
        r_foot_geoms=feet[:4],
        l_foot_geoms=feet[4:],
        pelvis_body=body("Waist"),
        l_foot_body=body("LFoot"),
        r_foot_body=body("RFoot"),
        torso_body=body("DWYTorso"),
        r_ft_site=site("r_ft"),
        l_ft_site=site("l_ft"),
        r_sole_site=site("r_sole"),
        l_sole_site=site("l_sole"),
        torso_site=site("torso"),
        imu_site=site("imu"),
    )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SensorParams:
    """Sensor constants (arrays; vmappable).

    Attributes:
        encoder_resolution_rad: link encoder quantum (2 pi / 4096 for 12 bits).
        encoder_offset_rad: constant link encoder offsets, (NU,).
        backlash_rad: dead-band width of the link reading, (NU,).
        imu_orientation_noise_rad: std of the IMU orientation error (rotation vector, each axis).
        joint_noise_rad: std of white Gaussian noise on the link encoder readings (seed 001, experiments:
            1 deg); the motor encoders stay exact.
        gyro_noise_rad_per_s: std of the angular-rate noise.
        ft_force_noise_n, ft_torque_noise_nm: std of the F/T noise.
        contact_threshold_n: normal force above which a foot is in contact.
    """

    encoder_resolution_rad: jax.Array
    encoder_offset_rad: jax.Array
    backlash_rad: jax.Array
    imu_orientation_noise_rad: jax.Array
    gyro_noise_rad_per_s: jax.Array
    ft_force_noise_n: jax.Array
    ft_torque_noise_nm: jax.Array
    contact_threshold_n: jax.Array
    joint_noise_rad: jax.Array


def make_sensor_params(
    *,
    encoder_bits: int = 12,
    encoder_offset_rad=0.0,
    backlash_rad=0.0,
    imu_orientation_noise_rad: float = 0.002,
    gyro_noise_rad_per_s: float = 0.01,
    ft_force_noise_n: float = 0.5,
    ft_torque_noise_nm: float = 0.05,
    contact_threshold_n: float = 20.0,
    joint_noise_rad: float = 0.0,
) -> SensorParams:
    """Build validated sensor parameters.

    Raises:
        ValueError: naming the bad value (``encoder_bits`` < 1, negative
            backlash, noise or threshold, non-finite offsets).
    """
    if int(encoder_bits) != encoder_bits or encoder_bits < 1:
        raise ValueError(f"encoder_bits must be a positive integer, got {encoder_bits}")
    off = np.broadcast_to(np.asarray(encoder_offset_rad, float), (NU,))
    if not np.all(np.isfinite(off)):
        raise ValueError(f"encoder_offset_rad must be finite, got {off.tolist()}")
    for name, v in [("backlash_rad", backlash_rad), ("imu_orientation_noise_rad", imu_orientation_noise_rad),
                    ("gyro_noise_rad_per_s", gyro_noise_rad_per_s), ("ft_force_noise_n", ft_force_noise_n),
                    ("ft_torque_noise_nm", ft_torque_noise_nm), ("contact_threshold_n", contact_threshold_n),
                    ("joint_noise_rad", joint_noise_rad)]:
        arr = np.asarray(v, float)
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"{name} must be finite and non-negative, got {arr.tolist()}")
    f32 = float  # JAX's default float (float64 under jax_enable_x64)
    return SensorParams(
        encoder_resolution_rad=jnp.asarray(2 * np.pi / 2**encoder_bits, f32),
        encoder_offset_rad=jnp.asarray(off, f32),
        backlash_rad=jnp.asarray(np.broadcast_to(np.asarray(backlash_rad, float), (NU,)), f32),
        imu_orientation_noise_rad=jnp.asarray(imu_orientation_noise_rad, f32),
        gyro_noise_rad_per_s=jnp.asarray(gyro_noise_rad_per_s, f32),
        ft_force_noise_n=jnp.asarray(ft_force_noise_n, f32),
        ft_torque_noise_nm=jnp.asarray(ft_torque_noise_nm, f32),
        contact_threshold_n=jnp.asarray(contact_threshold_n, f32),
        joint_noise_rad=jnp.asarray(joint_noise_rad, f32),
    )


class SensorState(NamedTuple):
    """Hysteresis state: the link reading behind the backlash dead band, (NU,)."""

    backlash_output_rad: jax.Array


class Readings(NamedTuple):
    """One control tick's sensor readings.

    Attributes:
        link_angle_rad: quantised link encoders, (NU,).
        motor_angle_rad: motor encoders (precise), (NU,).
        motor_vel_rad_per_s: motor velocities, (NU,).
        imu_quat: pelvis orientation quaternion (w, x, y, z) in the gravity-aligned frame (the world frame
            unless a scenario rotates gravity: :func:`gravity_frame_quat`), (4,).
        imu_rpy_rad: roll, pitch, yaw of the pelvis, (3,).
        gyro_rad_per_s: pelvis angular rate in the pelvis frame, (3,).
        ft_right, ft_left: ankle F/T (fx, fy, fz, mx, my, mz) in the sensor frame, (6,).
        foot_normal_force_n: total normal force on (right, left) foot, (2,).
        contact: (right, left) normal force above the threshold, (2,) bool.
    """

    link_angle_rad: jax.Array
    motor_angle_rad: jax.Array
    motor_vel_rad_per_s: jax.Array
    imu_quat: jax.Array
    imu_rpy_rad: jax.Array
    gyro_rad_per_s: jax.Array
    ft_right: jax.Array
    ft_left: jax.Array
    foot_normal_force_n: jax.Array
    contact: jax.Array


def init_sensor_state(q_rad: jax.Array) -> SensorState:
    """Backlash reading centred on the link angle."""
    return SensorState(jnp.asarray(q_rad))


def quantize(x: jax.Array, resolution: jax.Array) -> jax.Array:
    """Round to the encoder quantum: ``round(x / r) * r``, with the derivative of ``x`` (straight through).

    A rounded reading has zero derivative almost everywhere, which would cut every feedback through the
    encoders out of a gradient through a rollout; its slope on average (over the quantum) is 1.
    """
    return x + jax.lax.stop_gradient(jnp.round(x / resolution) * resolution - x)


def backlash(prev_output: jax.Array, x: jax.Array, width: jax.Array) -> jax.Array:
    """Play (dead-band hysteresis) operator: the output moves only once ``x`` leaves ``[y - w/2, y + w/2]``."""
    return jnp.clip(prev_output, x - width / 2, x + width / 2)


def quat_mul(a: jax.Array, b: jax.Array) -> jax.Array:
    """Hamilton product of (w, x, y, z) quaternions (last axis; leading batch axes broadcast)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return jnp.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_to_rpy(q: jax.Array) -> jax.Array:
    """Roll, pitch, yaw (ZYX convention) of a (w, x, y, z) quaternion."""
    w, x, y, z = q
    roll = jnp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jnp.arcsin(jnp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return jnp.stack([roll, pitch, yaw])


def _small_rotation_quat(rotvec: jax.Array) -> jax.Array:
    angle = jnp.sqrt(jnp.sum(rotvec**2) + 1e-18)
    axis = rotvec / angle
    return jnp.concatenate([jnp.cos(angle / 2)[None], jnp.sin(angle / 2) * axis])


def contact_wrenches_world(data) -> tuple[jax.Array, jax.Array]:
    """World-frame force and position of each contact of ``data`` (8 foot contacts on the packaged floor).

    Decodes the pyramidal-cone constraint forces (normal = sum of the four
    edge forces, tangent_i = (f_2i - f_2i+1) mu_i) and rotates them out of the
    contact frame. The force is the one on the contact's ``geom2`` (the frame's
    normal points from ``geom1`` to ``geom2``): on the packaged floor, whose
    plane is every pair's ``geom1``, the force on the robot.
    """
    c = data._impl.contact
    rows = c.efc_address[:, None] + jnp.arange(EFC_ROWS_PER_CONTACT)[None, :]
    f = jnp.take(data._impl.efc_force, jnp.clip(rows, 0, None)) * (c.efc_address[:, None] >= 0)
    normal = f.sum(axis=1)
    t1 = (f[:, 0] - f[:, 1]) * c.friction[:, 0]
    t2 = (f[:, 2] - f[:, 3]) * c.friction[:, 1]
    local = jnp.stack([normal, t1, t2], axis=1)
    world = jnp.einsum("ci,cij->cj", local, c.frame)
    return world, c.pos


def contact_signs(data, geoms) -> jax.Array:
    """(ncon,) sign of each contact's force (:func:`contact_wrenches_world`) on the geoms ``geoms`` (ids):
    +1 where one is the contact's ``geom2``, -1 where one is its ``geom1`` (MJX orders a pair by geom type,
    so a sphere comes before a box), 0 for other contacts."""
    c = data._impl.contact
    g = jnp.asarray(tuple(geoms))
    on2 = jnp.any(c.geom2[:, None] == g[None, :], axis=1)
    on1 = jnp.any(c.geom1[:, None] == g[None, :], axis=1)
    return on2.astype(data.qpos.dtype) - on1.astype(data.qpos.dtype)


def foot_contact_weights(data) -> jax.Array:
    """(2, ncon) :func:`contact_signs` of the (right, left) foot spheres."""
    ids = model_ids()
    return jnp.stack([contact_signs(data, ids["r_foot_geoms"]), contact_signs(data, ids["l_foot_geoms"])])


def foot_wrenches(data) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Ground reaction wrench of each foot at its F/T site, in the sensor frame.

    The packaged scene's eight contacts (right foot first) are summed four by
    four; a scene variant's contacts (terrain pairs: any number, in MJX's
    order) are assigned to the feet by their geoms (:func:`foot_contact_weights`).

    Returns:
        ``(ft_right, ft_left, normal_force_n)``: two (6,) wrenches
        (force, torque about the F/T site) and the (2,) world-z (upward) components of the foot forces.
    """
    ids = model_ids()
    force, pos = contact_wrenches_world(data)
    weights = foot_contact_weights(data) if force.shape[0] != N_CONTACTS else None
    out = []
    normals = []
    for k, site in enumerate((ids["r_ft_site"], ids["l_ft_site"])):
        p0 = data.site_xpos[site]
        rot = data.site_xmat[site].reshape(3, 3)
        if weights is None:
            sl = slice(4 * k, 4 * k + 4)
            f_w = force[sl].sum(0)
            m_w = jnp.cross(pos[sl] - p0, force[sl]).sum(0)
        else:
            fk = weights[k][:, None] * force
            f_w = fk.sum(0)
            m_w = jnp.cross(pos - p0, fk).sum(0)
        out.append(jnp.concatenate([rot.T @ f_w, rot.T @ m_w]))
        normals.append(f_w[2])
    return out[0], out[1], jnp.stack(normals)


def quat_conj(q: jax.Array) -> jax.Array:
    """Conjugate (inverse rotation) of a (w, x, y, z) unit quaternion."""
    return q * jnp.asarray([1.0, -1.0, -1.0, -1.0], q.dtype)


def gravity_frame_quat(data) -> jax.Array | None:
    """World-to-gravity-frame rotation of a scene variant as a quaternion (the orientation of its gravity
    frame body, z against gravity), or ``None`` for a scene without one (gravity along -z: the packaged one).

    Static: decided by the number of bodies (:func:`mjx_coman.mjcf.scene_xml` puts that body right after
    the robot's).
    """
    n = model_ids()["n_robot_bodies"]
    return data.xquat[n] if data.xquat.shape[0] > n else None


def pelvis_quat_gravity(data) -> jax.Array:
    """True pelvis orientation in the gravity-aligned frame: ``conj(q_gravity) q_pelvis`` (world frame if none)."""
    q = data.xquat[model_ids()["pelvis_body"]]
    g = gravity_frame_quat(data)
    return q if g is None else quat_mul(quat_conj(g), q)


def read_sensors(
    params: SensorParams,
    state: SensorState,
    key: jax.Array,
    data,
    motor_angle_rad: jax.Array,
    motor_vel_rad_per_s: jax.Array,
) -> tuple[SensorState, Readings]:
    """Read every sensor from an ``mjx.Data`` and the motor states.

    Args:
        params: sensor constants.
        state: backlash hysteresis state.
        key: PRNG key for this tick's noise (split here).
        data: ``mjx.Data`` after the physics step (contacts solved).
        motor_angle_rad, motor_vel_rad_per_s: motor shaft states (NU,).

    Returns:
        the new sensor state and the readings.
    """
    k_imu, k_gyro, k_ft = jax.random.split(key, 3)
    q = data.qpos[7:]
    out = backlash(state.backlash_output_rad, q, params.backlash_rad)
    link = quantize(out + params.encoder_offset_rad, params.encoder_resolution_rad)
    # Its own stream (fold_in), so that the IMU, gyro and F/T draws stay those of a walk without it.
    k_joint = jax.random.fold_in(key, 3)
    link = link + params.joint_noise_rad * jax.random.normal(k_joint, link.shape, link.dtype)

    quat_true = pelvis_quat_gravity(data)
    noise = params.imu_orientation_noise_rad * jax.random.normal(k_imu, (3,), quat_true.dtype)
    quat = quat_mul(quat_true, _small_rotation_quat(noise))
    quat = quat / jnp.linalg.norm(quat)
    gyro = data.qvel[3:6] + params.gyro_noise_rad_per_s * jax.random.normal(k_gyro, (3,), quat_true.dtype)

    ft_r, ft_l, normal = foot_wrenches(data)
    scale = jnp.concatenate([jnp.full(3, params.ft_force_noise_n), jnp.full(3, params.ft_torque_noise_nm)])
    n = jax.random.normal(k_ft, (2, 6), quat_true.dtype) * scale
    readings = Readings(
        link_angle_rad=link,
        motor_angle_rad=motor_angle_rad,
        motor_vel_rad_per_s=motor_vel_rad_per_s,
        imu_quat=quat,
        imu_rpy_rad=quat_to_rpy(quat),
        gyro_rad_per_s=gyro,
        ft_right=ft_r + n[0],
        ft_left=ft_l + n[1],
        foot_normal_force_n=normal,
        contact=normal > params.contact_threshold_n,
    )
    return SensorState(out), readings
