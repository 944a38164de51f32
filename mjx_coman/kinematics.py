"""COMAN leg kinematics in JAX: forward kinematics and closed-form 6-DoF leg IK.

Geometry (``shared/coman/joints.csv``; all joint frames unrotated at the zero
pose, x forward, y left, z up, in the pelvis ``Waist`` frame). Per leg, with
``s = +1`` (left) or ``-1`` (right), the chain is

    hip pitch (y) at (0, 0.023 s, 0) -> hip roll (x) at +(0, 0.0496 s, 0)
    -> hip yaw (z) at +(0, 0, -0.1024) -> knee pitch (y) at +(0, 0, -0.1234)
    -> ankle roll (x) at +(0, 0, -0.201) -> ankle pitch (y) at the same point,

and the sole is 0.09 m below the ankle. The lateral offset between the hip
pitch and hip roll joints lies along the pitch axis (y), so the pitch rotation
leaves it unchanged: the three hip axes intersect at one fixed point, the hip
centre ``(0, 0.0726 s, 0)``, and the hip is a spherical joint (pitch, roll,
yaw). The hip yaw axis and the knee are on one line (thigh 0.2258 m), the
ankle roll and pitch axes intersect at the ankle centre (shank 0.201 m). This
makes the leg inverse kinematics fully closed-form (:func:`leg_ik`).

Angle order of a leg, everywhere in this module: ``(hip pitch, hip roll,
hip yaw, knee, ankle roll, ankle pitch)``. Sign conventions (right-hand rule
about the pelvis/joint axes, the same for both legs): hip pitch > 0 swings the
leg backwards (flexion is negative), hip roll > 0 moves the foot to +y
(abduction of the left leg, adduction of the right one), hip yaw > 0 turns the
toes to the left, knee > 0 is flexion, ankle roll > 0 lifts the foot's +y
edge (the sole normal tilts towards -y), ankle pitch > 0 points the toes down.

Notes:
    The zero-pose sole is 0.1024 + 0.1234 + 0.201 + 0.09 = 0.5168 m below the
    hip axes, while the README rounds it to 0.517 m (0.2 mm apart); this
    module uses the joint offsets as they are.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

HIP_PITCH_OFFSET_Y_M = 0.023  # Waist -> hip pitch joint, times the side sign
HIP_ROLL_OFFSET_Y_M = 0.0496  # hip pitch -> hip roll joint, times the side sign
HIP_HALF_WIDTH_M = HIP_PITCH_OFFSET_Y_M + HIP_ROLL_OFFSET_Y_M  # 0.0726, hip centre to mid-pelvis
HIP_ROLL_TO_YAW_M = 0.1024
HIP_YAW_TO_KNEE_M = 0.1234
THIGH_LENGTH_M = HIP_ROLL_TO_YAW_M + HIP_YAW_TO_KNEE_M  # 0.2258, hip centre to knee
SHANK_LENGTH_M = 0.201  # knee to ankle centre
ANKLE_TO_SOLE_M = 0.09
ANKLE_TO_SOLE_OFFSET_M = (0.0, 0.0, -ANKLE_TO_SOLE_M)  # sole point in the foot frame
FOOT_POINT_OFFSET_M = (0.03, 0.0, 0.0)  # seed 000 "foot point" in the foot frame
PELVIS_POINT_M = (0.0, 0.0, 0.0)  # midway between the hip centres, in the Waist frame
IMU_IN_PELVIS_RPY_RAD = (0.0, 3.14159, 0.0)  # joints.csv imu_joint: IMU frame upside down

# Joint limits (rad) in leg order (hip pitch, hip roll, hip yaw, knee, ankle roll,
# ankle pitch), from joints.csv.
LEFT_LEG_LIMITS_RAD = np.array(
    [[-1.9199, -0.4363, -0.8727, -0.1745, -0.6109, -1.2217],
     [0.7854, 1.0472, 0.8727, 1.9199, 0.6109, 1.2217]])
RIGHT_LEG_LIMITS_RAD = np.array(
    [[-1.9199, -1.0472, -0.8727, -0.1745, -0.6109, -1.2217],
     [0.7854, 0.4363, 0.8727, 1.9199, 0.6109, 1.2217]])

_EPS = 1e-12  # floor under square roots so values and gradients stay finite


class LegPose(NamedTuple):
    """Pose of one leg's points in the pelvis (Waist) frame; positions in m.

    Attributes:
        hip_m: (3,) hip centre (intersection of the three hip axes).
        knee_m: (3,) knee centre (on the knee pitch axis).
        ankle_m: (3,) ankle centre (intersection of the ankle roll and pitch axes).
        sole_m: (3,) sole point, 0.09 m below the ankle along the foot -z.
        foot_point_m: (3,) seed 000 foot point, 0.03 m ahead of the ankle along the foot +x.
        foot_rot: (3, 3) foot frame orientation (columns: foot axes in the pelvis frame).
    """

    hip_m: jax.Array
    knee_m: jax.Array
    ankle_m: jax.Array
    sole_m: jax.Array
    foot_point_m: jax.Array
    foot_rot: jax.Array


class FeetInFrame(NamedTuple):
    """Both legs' points relative to the pelvis point, in a world-aligned frame.

    Index 0 is the left leg, 1 the right leg. Positions in m, from the pelvis
    point (midway between the hip centres), expressed in the frame ``frame_rot``.

    Attributes:
        foot_point_m: (2, 3) pelvis point -> foot point vectors.
        ankle_m: (2, 3) pelvis point -> ankle centre vectors.
        sole_m: (2, 3) pelvis point -> sole point vectors.
        hip_m: (2, 3) pelvis point -> hip centre vectors.
        foot_rot: (2, 3, 3) foot orientations in the frame.
        frame_rot: (3, 3) orientation of the pelvis w.r.t. the frame (pelvis-frame
            vectors map into the frame as ``frame_rot @ v``).
    """

    foot_point_m: jax.Array
    ankle_m: jax.Array
    sole_m: jax.Array
    hip_m: jax.Array
    foot_rot: jax.Array
    frame_rot: jax.Array


def side_sign(side) -> jax.Array | float:
    """Side sign ``+1`` for the left leg and ``-1`` for the right one.

    Args:
        side: ``"left"``/``"right"`` (also ``"l"``/``"r"``), or a number/array already
            equal to +1/-1 (it may be traced, e.g. to vmap over both legs).

    Returns:
        The sign as a float or array.
    """
    if isinstance(side, str):
        key = side.lower()
        if key in ("left", "l"):
            return 1.0
        if key in ("right", "r"):
            return -1.0
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return jnp.asarray(side)


def leg_limits_rad(side: str) -> np.ndarray:
    """(2, 6) lower/upper joint limits of one leg, rad, in leg angle order."""
    return LEFT_LEG_LIMITS_RAD if side_sign(side) > 0 else RIGHT_LEG_LIMITS_RAD


def rot_x(angle_rad: jax.Array) -> jax.Array:
    """(3, 3) rotation about x by ``angle_rad``."""
    c, s = jnp.cos(angle_rad), jnp.sin(angle_rad)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])])


def rot_y(angle_rad: jax.Array) -> jax.Array:
    """(3, 3) rotation about y by ``angle_rad``."""
    c, s = jnp.cos(angle_rad), jnp.sin(angle_rad)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([c, z, s]), jnp.stack([z, o, z]), jnp.stack([-s, z, c])])


def rot_z(angle_rad: jax.Array) -> jax.Array:
    """(3, 3) rotation about z by ``angle_rad``."""
    c, s = jnp.cos(angle_rad), jnp.sin(angle_rad)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def quat_to_rot(quat_wxyz: jax.Array) -> jax.Array:
    """(3, 3) rotation matrix of a quaternion ``(w, x, y, z)`` (MuJoCo order; normalised here)."""
    q = quat_wxyz / _safe_sqrt(jnp.sum(quat_wxyz**2))
    w, x, y, z = q[0], q[1], q[2], q[3]
    return jnp.stack([
        jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
        jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
        jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
    ])


def imu_to_pelvis_rot(imu_rot_world: jax.Array) -> jax.Array:
    """Pelvis (Waist) orientation from the IMU link orientation, both in the world frame.

    The IMU link of joints.csv is rotated by ``IMU_IN_PELVIS_RPY_RAD`` (pitch of
    about pi) w.r.t. the Waist; use this when an orientation is that of the IMU
    frame rather than of the pelvis body.

    Args:
        imu_rot_world: (3, 3) IMU frame orientation in the world.

    Returns:
        (3, 3) pelvis orientation in the world.
    """
    return imu_rot_world @ rot_y(jnp.asarray(IMU_IN_PELVIS_RPY_RAD[1])).T


def yaw_free_rot(rot_world: jax.Array) -> jax.Array:
    """Remove the heading from an orientation: ``Rz(-yaw) @ R``.

    The heading ``yaw = atan2(R[1, 0], R[0, 0])`` is that of the body x axis
    projected on the ground (Z-Y-X Euler yaw). The result is the body orientation
    in the world-aligned frame that turns with the body's heading only.

    Args:
        rot_world: (3, 3) body orientation in the world.

    Returns:
        (3, 3) body orientation w.r.t. the heading frame (only roll and pitch left).
    """
    yaw = jnp.arctan2(rot_world[1, 0], rot_world[0, 0])
    return rot_z(-yaw) @ rot_world


def leg_fk(angles_rad: jax.Array, side) -> LegPose:
    """Forward kinematics of one leg, in the pelvis (Waist) frame.

    The foot orientation is ``Ry(q0) Rx(q1) Rz(q2) Ry(q3) Rx(q4) Ry(q5)``;
    the ankle is ``hip + Ry(q0) Rx(q1) Rz(q2) [(0, 0, -thigh) + Ry(q3) (0, 0, -shank)]``.
    At the zero pose the leg is straight and vertical, sole 0.5168 m below the
    hip centre. Ankle roll > 0 turns the sole normal towards -y.

    Args:
        angles_rad: (6,) ``(hip pitch, hip roll, hip yaw, knee, ankle roll, ankle pitch)``.
        side: ``"left"``/``"right"`` or a +1/-1 sign (see :func:`side_sign`).

    Returns:
        The leg's :class:`LegPose`.
    """
    q = jnp.asarray(angles_rad)
    s = side_sign(side)
    zero = jnp.zeros((), q.dtype)
    hip = jnp.stack([zero, zero + s * HIP_HALF_WIDTH_M, zero])
    r_hip = rot_y(q[0]) @ rot_x(q[1]) @ rot_z(q[2])
    r_shank = r_hip @ rot_y(q[3])
    r_foot = r_shank @ rot_x(q[4]) @ rot_y(q[5])
    knee = hip - THIGH_LENGTH_M * r_hip[:, 2]
    ankle = knee - SHANK_LENGTH_M * r_shank[:, 2]
    sole = ankle + r_foot @ jnp.asarray(ANKLE_TO_SOLE_OFFSET_M, q.dtype)
    foot_point = ankle + r_foot @ jnp.asarray(FOOT_POINT_OFFSET_M, q.dtype)
    return LegPose(hip, knee, ankle, sole, foot_point, r_foot)


def _safe_sqrt(x: jax.Array) -> jax.Array:
    return jnp.sqrt(jnp.maximum(x, _EPS))


def leg_ik(target_pos_m: jax.Array, foot_rot: jax.Array, side,
           foot_offset_m=(0.0, 0.0, 0.0)) -> jax.Array:
    """Closed-form inverse kinematics of one leg (exact, no iterations).

    Derivation. Let ``R`` be the foot orientation, ``A`` the ankle centre and
    ``H`` the fixed hip centre, all in the pelvis frame, and ``r = R^T (H - A)``
    the hip seen from the foot. From :func:`leg_fk`,
    ``r = Ry(-q5) Rx(-q4) w`` with ``w = (-thigh sin q3, 0, shank + thigh cos q3)``.

    1. Knee: ``|r|^2 = thigh^2 + shank^2 + 2 thigh shank cos q3``, taking
       ``q3 >= 0`` (flexion).
    2. Ankle roll: ``Ry(-q5)`` keeps the y component, so ``r_y = sin(q4) w_z``
       and ``cos(q4) w_z = sqrt(r_x^2 + r_z^2 - w_x^2)`` (``cos q4 > 0``).
    3. Ankle pitch: ``Ry(-q5)`` rotates ``(w_x, cos(q4) w_z)`` onto ``(r_x, r_z)``
       in the x-z plane, so ``q5 = atan2(w_x, cos(q4) w_z) - atan2(r_x, r_z)``.
    4. Hip: ``Ry(q0) Rx(q1) Rz(q2) = M = R Ry(q5)^T Rx(q4)^T Ry(q3)^T``, the Y-X-Z
       Euler angles of ``M``: ``q1 = atan2(-M12, hypot(M10, M11))``,
       ``q0 = atan2(M02, M22)``, ``q2 = atan2(M10, M11)``.

    Unreachable targets: ``|r|`` is clamped to the reachable range of the knee
    (0 to its upper limit), keeping the direction of the ankle from the hip, so
    a target too far gives the straight leg pointing at it and a target too close
    the most flexed knee. An orientation the ankle cannot produce
    (``|r_y| > w_z``, ankle roll beyond +-90 degrees) is clamped the same way.
    Square roots are floored at 1e-12, so values and gradients stay finite at
    the straight knee. The other joint limits are not enforced (see
    :func:`leg_limits_rad`).

    Args:
        target_pos_m: (3,) target point position in the pelvis (Waist) frame.
        foot_rot: (3, 3) desired foot orientation in the pelvis frame.
        side: ``"left"``/``"right"`` or a +1/-1 sign (see :func:`side_sign`).
        foot_offset_m: (3,) the target point in the foot frame, from the ankle
            centre: zeros for the ankle (default), ``ANKLE_TO_SOLE_OFFSET_M`` for
            the sole, ``FOOT_POINT_OFFSET_M`` for the seed's foot point.

    Returns:
        (6,) joint angles ``(hip pitch, hip roll, hip yaw, knee, ankle roll, ankle pitch)``, rad.
    """
    p = jnp.asarray(target_pos_m)
    rot = jnp.asarray(foot_rot, p.dtype)
    s = side_sign(side)
    l1, l2 = THIGH_LENGTH_M, SHANK_LENGTH_M
    zero = jnp.zeros((), p.dtype)
    hip = jnp.stack([zero, zero + s * HIP_HALF_WIDTH_M, zero])
    ankle = p - rot @ jnp.asarray(foot_offset_m, p.dtype)

    # Hip seen from the foot, its length clamped to the knee's reach.
    r = rot.T @ (hip - ankle)
    r_norm = _safe_sqrt(jnp.sum(r**2))
    cos_knee_max = float(np.cos(LEFT_LEG_LIMITS_RAD[1, 3]))
    r_min = float(np.sqrt(l1**2 + l2**2 + 2 * l1 * l2 * cos_knee_max))
    r_clamped = jnp.clip(r_norm, r_min, l1 + l2)
    r = r * (r_clamped / r_norm)

    # 1. Knee, flexion positive.
    cos_knee = jnp.clip((r_clamped**2 - l1**2 - l2**2) / (2 * l1 * l2), -1.0, 1.0)
    knee = jnp.arctan2(_safe_sqrt(1.0 - cos_knee**2), cos_knee)
    w_x = -l1 * jnp.sin(knee)
    w_z = l2 + l1 * jnp.cos(knee)

    # 2-3. Ankle roll then pitch.
    c4_wz = _safe_sqrt(r[0] ** 2 + r[2] ** 2 - w_x**2)
    r_y = jnp.clip(r[1], -w_z, w_z)
    ankle_roll = jnp.arctan2(r_y, c4_wz)
    ankle_pitch = jnp.arctan2(w_x, c4_wz) - jnp.arctan2(r[0], r[2])
    ankle_pitch = jnp.arctan2(jnp.sin(ankle_pitch), jnp.cos(ankle_pitch))  # wrap to (-pi, pi]

    # 4. Hip: Y-X-Z Euler angles of the thigh orientation.
    m = rot @ rot_y(ankle_pitch).T @ rot_x(ankle_roll).T @ rot_y(knee).T
    hip_roll = jnp.arctan2(-m[1, 2], _safe_sqrt(m[1, 0] ** 2 + m[1, 1] ** 2))
    hip_pitch = jnp.arctan2(m[0, 2], m[2, 2])
    hip_yaw = jnp.arctan2(m[1, 0], m[1, 1])
    return jnp.stack([hip_pitch, hip_roll, hip_yaw, knee, ankle_roll, ankle_pitch])


def feet_in_frame(pelvis_orientation: jax.Array, left_angles_rad: jax.Array,
                  right_angles_rad: jax.Array, yaw_free: bool = True) -> FeetInFrame:
    """Pelvis-to-foot vectors of both legs in a world-aligned frame.

    The vectors start at the pelvis point (midway between the hip centres,
    which is the Waist origin) and end at the foot point (on the ankle axis,
    0.03 m forward in the foot frame; seed 000, "Sagittal Plane"), the ankle
    centre, the sole point and the hip centre.

    Args:
        pelvis_orientation: pelvis (Waist) orientation in the world, either a (4,)
            quaternion ``(w, x, y, z)`` or a (3, 3) rotation matrix. For a raw IMU
            frame orientation convert it first with :func:`imu_to_pelvis_rot`.
        left_angles_rad: (6,) left leg angles, leg order (see :func:`leg_fk`).
        right_angles_rad: (6,) right leg angles, leg order.
        yaw_free: static; True for the heading frame (world z up, x along the
            pelvis heading, see :func:`yaw_free_rot`), False for the world frame.

    Returns:
        :class:`FeetInFrame` with both legs' vectors and foot orientations in the frame.
    """
    o = jnp.asarray(pelvis_orientation)
    rot = quat_to_rot(o) if o.shape == (4,) else o
    if yaw_free:
        rot = yaw_free_rot(rot)
    left, right = leg_fk(left_angles_rad, 1.0), leg_fk(right_angles_rad, -1.0)
    origin = jnp.asarray(PELVIS_POINT_M, rot.dtype)

    def both(field: str) -> jax.Array:
        return jnp.stack([rot @ (getattr(leg, field) - origin) for leg in (left, right)])

    foot_rot = jnp.stack([rot @ left.foot_rot, rot @ right.foot_rot])
    return FeetInFrame(both("foot_point_m"), both("ankle_m"), both("sole_m"), both("hip_m"),
                       foot_rot, rot)
