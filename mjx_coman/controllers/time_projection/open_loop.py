"""Open-loop blocks of the position-controlled 3LP walking (seed 000, eq. 21-25).

Pure JAX functions (jittable, vmappable) for the blocks "A" to "C" of the
seed's Figure 3: the nominal 3LP gait in Cartesian space augmented by the
foot-lift strategies (eq. 22-23), inverse kinematics to joint angles, the SEA
knee compensation (eq. 21) and the motor-shaft position loops with the hip
switching rule (eq. 24-25).

Frames. The 3LP state (:func:`jaxlp.gait.nominal_state`) gives horizontal
positions relative to the stance foot, axis 0 sagittal (x forward) and axis 1
lateral (y left); ``d = +1`` is a left-swing phase (swing hip on +y), ``d =
-1`` a right-swing phase. :func:`cartesian_targets` returns vectors from the
*pelvis point* (midway between the hip centres, the Waist origin) to the
*foot points* (on the ankle axis, 3 cm forward in the foot frame,
``kinematics.FOOT_POINT_OFFSET_M``; the 3LP feet), expressed in the
world-aligned heading frame (x forward, y left, z up). The pelvis itself is
rolled by eq. 22 in that frame; :func:`joint_targets` rotates the targets into
the pelvis frame before the leg IK. Feet are flat (foot frame = heading frame).

Pelvis roll geometry (eq. 22, Figure 8B). The pelvis is a rigid bar of
half-width ``pw = 0.0726 m`` that turns about the *stance* hip, which keeps
its 3LP position at ``pelvis_height_m`` above the stance foot; the swing leg
hangs from the swing hip, so its foot rises with it by ``2 pw sin(roll)``
(1.45 cm at 0.1 rad, the seed's "1.4 cm"), on top of the fixed lift of eq. 23
(1 cm): about 2.4 cm in total, as in the seed.

Lateral bounce. The seed drops the 3LP lateral pelvis sway ("there is no need
to use lateral bounces of 3LP anymore"); with ``lateral_bounce=False``
(default) the pelvis stays laterally midway between the feet lines
(``d * step_width / 2`` from the stance foot) while the swing foot keeps its
3LP lateral path. ``lateral_bounce=True`` keeps the 3LP pelvis sway.

Reach. With T = 0.4 s, a 0.25 m step width and the 0.4 rad knee crouch
(pelvis 0.417 m above the feet), the stance knee straightens to about 0.1 rad
at 0.2 m/s and reaches full extension near 0.3 m/s, where ``leg_ik`` clamps
(the feet then miss their targets); all joint targets stay within the joint
limits up to 0.3 m/s.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.gait import Gait, nominal_state
from jaxlp.params import ThreeLPParams
from mjx_coman.actuators import JOINT_INDEX
from mjx_coman.kinematics import FOOT_POINT_OFFSET_M, HIP_HALF_WIDTH_M, leg_fk, leg_ik, rot_x, rot_y

LEG_JOINTS = ("HipSag", "HipLat", "HipYaw", "KneeSag", "AnkLat", "AnkSag")  # kinematics leg order
LEFT_LEG_INDEX = np.array([JOINT_INDEX["L" + n] for n in LEG_JOINTS])
RIGHT_LEG_INDEX = np.array([JOINT_INDEX["R" + n] for n in LEG_JOINTS])


def _leg_slice(index: np.ndarray) -> slice:
    """A leg's joints as a static slice (they are contiguous in ``JOINT_NAMES``): no gather in traced code, whose
    int64 indices under float64 forward-mode AD met int32 ones (``lax.add`` dtype error)."""
    if not np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        raise ValueError(f"leg joints {index.tolist()} are not contiguous in JOINT_NAMES")
    return slice(int(index[0]), int(index[0]) + len(index))


LEFT_LEG = _leg_slice(LEFT_LEG_INDEX)
RIGHT_LEG = _leg_slice(RIGHT_LEG_INDEX)
LEFT_HIP_PITCH = JOINT_INDEX["LHipSag"]
RIGHT_HIP_PITCH = JOINT_INDEX["RHipSag"]
LEFT_KNEE = JOINT_INDEX["LKneeSag"]
RIGHT_KNEE = JOINT_INDEX["RKneeSag"]

FIXED_LIFT_M = 0.01  # eq. 23 amplitude
ROLL_AMP_RAD = 0.1  # eq. 22 amplitude
HIP_SWITCH_RATIO = 0.2  # t1 = 0.2 T (eq. 24)


class CartesianTargets(NamedTuple):
    """Desired Cartesian posture at one instant of a phase (blocks "A" + lift of Figure 3).

    Attributes:
        swing_m: (3,) pelvis point -> swing foot point, heading frame, m.
        stance_m: (3,) pelvis point -> stance foot point, heading frame, m.
        pelvis_m: (3,) stance foot point -> pelvis point, heading frame, m.
        roll_rad: desired pelvis roll about +x (eq. 22, signed so the swing hip rises).
        lift_m: fixed swing-foot lift of eq. 23, m (already included in ``swing_m``).
    """

    swing_m: jax.Array
    stance_m: jax.Array
    pelvis_m: jax.Array
    roll_rad: jax.Array
    lift_m: jax.Array


def _half_sine(t_s, step_time_s) -> jax.Array:
    """``sin(pi t / T)`` with ``t / T`` clipped to [0, 1] (never negative)."""
    phase = jnp.clip(jnp.asarray(t_s) / step_time_s, 0.0, 1.0)
    return jnp.sin(jnp.pi * phase)


def cartesian_targets(
    params3lp: ThreeLPParams,
    gait: Gait,
    t_s,
    d,
    pelvis_height_m,
    lift_m=FIXED_LIFT_M,
    roll_amp_rad=ROLL_AMP_RAD,
    step_time_s=None,
    lateral_bounce: bool = False,
) -> CartesianTargets:
    """Desired feet positions relative to the pelvis point (seed 000, eq. 10, 22, 23).

    The nominal 3LP state ``q_bar(t)`` (eq. 10) gives the horizontal swing
    foot, pelvis and stance foot positions; the pelvis is placed
    ``pelvis_height_m`` above the feet (the robot's crouched height, see
    :func:`crouched_pelvis_height_m`, not the 3LP ``h1``), the pelvis rolls by
    ``delta_theta_roll = d roll_amp sin(pi t / T)`` (eq. 22; the swing-side hip
    rises) about the stance hip, and the swing foot is lifted by
    ``delta_z_fixed = lift sin(pi t / T)`` (eq. 23) on top of the rise of its
    hip. See the module docstring for the frames.

    Args:
        params3lp: 3LP parameters of the gait (e.g. ``get_params("coman-mjcf")``).
        gait: periodic gait from :func:`jaxlp.gait.periodic_gait`.
        t_s: time since the phase start, s (clipped to [0, T] in the sines).
        d: phase sign, +1 left swing, -1 right swing.
        pelvis_height_m: pelvis point height above the foot points, m.
        lift_m: amplitude of eq. 23, m (seed: 0.01).
        roll_amp_rad: amplitude of eq. 22, rad (seed: 0.1).
        step_time_s: T of eq. 22-23; ``None`` takes ``gait.step_time_s``.
        lateral_bounce: static; keep the 3LP lateral pelvis sway (the seed does not).

    Returns:
        :class:`CartesianTargets`.
    """
    T = gait.step_time_s if step_time_s is None else step_time_s
    d = jnp.asarray(d, dtype=gait.q0.dtype)
    q = nominal_state(params3lp, gait, t_s, d)  # (2, 6): [s, p, a, ...] per axis
    return targets_from_state(q, gait.step_width_m, t_s, d, pelvis_height_m, lift_m, roll_amp_rad, T,
                              lateral_bounce)


def targets_from_state(q, step_width_m, t_s, d, pelvis_height_m, lift_m=FIXED_LIFT_M, roll_amp_rad=ROLL_AMP_RAD,
                       step_time_s=0.4, lateral_bounce: bool = False) -> CartesianTargets:
    """:func:`cartesian_targets` from a given 3LP state ``q`` (2, 6) instead of the gait.

    Lets a caller that has the nominal state already (a per-tick table) skip
    the matrix exponential of :func:`jaxlp.gait.nominal_state`; same frames
    and equations (seed 000, eq. 22-23).
    """
    T = step_time_s
    q = jnp.asarray(q)
    d = jnp.asarray(d, dtype=q.dtype)
    swing_xy, pelvis_xy, stance_xy = q[:, 0], q[:, 1], q[:, 2]
    if not lateral_bounce:
        pelvis_xy = pelvis_xy.at[1].set(stance_xy[1] + 0.5 * d * step_width_m)
    sine = _half_sine(t_s, T)
    roll = d * roll_amp_rad * sine
    lift = lift_m * sine
    h = jnp.asarray(pelvis_height_m, q.dtype)
    pw = HIP_HALF_WIDTH_M
    zero = jnp.zeros_like(h)
    c, s = jnp.cos(roll), jnp.sin(roll)
    stance_hip = jnp.stack([pelvis_xy[0], pelvis_xy[1] - d * pw, h])
    pelvis = stance_hip + jnp.stack([zero, d * pw * c, d * pw * s])
    swing_hip_shift = jnp.stack([zero, 2 * d * pw * (c - 1), 2 * d * pw * s])  # rolled - unrolled swing hip
    swing = jnp.stack([swing_xy[0], swing_xy[1], zero]) + swing_hip_shift + jnp.stack([zero, zero, lift])
    stance = jnp.stack([stance_xy[0], stance_xy[1], zero])
    return CartesianTargets(swing - pelvis, stance - pelvis, pelvis - stance, roll, lift)


def joint_targets(targets: CartesianTargets, d, posture_q_rad, swing_pitch_rad=0.0) -> jax.Array:
    """Desired joint angles by inverse kinematics of both legs (block "B" of Figure 3).

    The targets are rotated from the heading frame into the pelvis frame by the
    pelvis roll ``R = Rx(roll)`` (eq. 22; no pitch, no yaw) and each leg is
    solved in closed form (:func:`mjx_coman.kinematics.leg_ik`) for its foot
    point with a flat foot (foot orientation ``R^T`` in the pelvis frame).

    Args:
        targets: from :func:`cartesian_targets`.
        d: phase sign, +1 left swing, -1 right swing.
        posture_q_rad: (23,) posture for the joints not set here (waist, arms),
            in ``actuators.JOINT_NAMES`` order, e.g. ``env.standing_posture()[0]``.
        swing_pitch_rad: pitch of the swing foot about +y in the heading frame
            (toes down > 0; seed 000, eq. 30 feedback), rad; 0 keeps it flat.

    Returns:
        (23,) desired joint angles, rad, ``actuators.JOINT_NAMES`` order.
    """
    q = jnp.asarray(posture_q_rad)
    left_swing = jnp.asarray(d) > 0
    left_m = jnp.where(left_swing, targets.swing_m, targets.stance_m)
    right_m = jnp.where(left_swing, targets.stance_m, targets.swing_m)
    r_t = rot_x(jnp.asarray(targets.roll_rad, q.dtype)).T
    r_swing = r_t @ rot_y(jnp.asarray(swing_pitch_rad, q.dtype))
    left = leg_ik(r_t @ left_m, jnp.where(left_swing, r_swing, r_t), 1.0, FOOT_POINT_OFFSET_M)
    right = leg_ik(r_t @ right_m, jnp.where(left_swing, r_t, r_swing), -1.0, FOOT_POINT_OFFSET_M)
    return q.at[LEFT_LEG].set(left.astype(q.dtype)).at[RIGHT_LEG].set(right.astype(q.dtype))


def open_loop_joint_targets(params3lp: ThreeLPParams, gait: Gait, t_s, d, pelvis_height_m, posture_q_rad,
                            **kwargs) -> jax.Array:
    """:func:`cartesian_targets` then :func:`joint_targets`: (23,) desired angles, rad.

    ``kwargs`` go to :func:`cartesian_targets` (``lift_m``, ``roll_amp_rad``,
    ``step_time_s``, ``lateral_bounce``).
    """
    return joint_targets(cartesian_targets(params3lp, gait, t_s, d, pelvis_height_m, **kwargs), d, posture_q_rad)


def feet_from_joints(q_rad, roll_rad) -> tuple[jax.Array, jax.Array]:
    """Left and right foot points from the pelvis point in the heading frame (FK of :func:`joint_targets`).

    Args:
        q_rad: (23,) joint angles, ``actuators.JOINT_NAMES`` order.
        roll_rad: pelvis roll about +x, rad.

    Returns:
        ``(left_m (3,), right_m (3,))``.
    """
    q = jnp.asarray(q_rad)
    r = rot_x(jnp.asarray(roll_rad, q.dtype))
    left = leg_fk(q[LEFT_LEG], 1.0).foot_point_m
    right = leg_fk(q[RIGHT_LEG], -1.0).foot_point_m
    return r @ left, r @ right


def crouched_pelvis_height_m(knee_rad: float = 0.4) -> float:
    """Pelvis point height above the foot points in the crouched standing posture (host helper).

    FK of :func:`mjx_coman.env.standing_posture` (knees ``knee_rad``, flat
    feet, upright pelvis): about 0.4172 m at 0.4 rad. Not jittable (loads the
    MJCF once); call it outside ``jit`` and pass the float.
    """
    from mjx_coman.env import standing_posture

    q, _ = standing_posture(float(knee_rad))
    return float(-np.asarray(leg_fk(jnp.asarray(q[LEFT_LEG]), 1.0).foot_point_m)[2])


def hip_switch_gamma(t_s, step_time_s, swing) -> jax.Array:
    """Weight ``gamma`` of the hip switching rule (seed 000, eq. 24).

    ``gamma = exp(-(t / t1)^2)`` for the stance hip and ``1 - exp(-(t / t1)^2)``
    for the swing hip, ``t`` the time since the phase start and ``t1 = 0.2 T``
    (about the double-support share). ``gamma = 1`` tracks the desired hip
    angle, ``gamma = 0`` the upright torso: each hip hands over smoothly at the
    contact switch.

    Args:
        t_s: time since the phase start, s.
        step_time_s: T, s.
        swing: True for the swing-side hip (bool or traced bool).

    Returns:
        ``gamma`` in [0, 1].
    """
    t1 = HIP_SWITCH_RATIO * jnp.asarray(step_time_s)
    e = jnp.exp(-((jnp.asarray(t_s) / t1) ** 2))
    return jnp.where(swing, 1.0 - e, e)


def hip_voltage(kd, theta_des, theta_act, pelvis_pitch_rad, gamma) -> jax.Array:
    """Hip pitch motor voltage with the torso switch (seed 000, eq. 24).

    ``v = k_d (gamma (theta_des - theta_act) + (1 - gamma)(0 - theta_pitch))``
    where the seed's ``theta_pitch`` is the torso angle as the stance hip
    moves it. Here ``pelvis_pitch_rad`` is the pelvis rotation about +y in the
    kinematics convention (positive leans forward, nose down). With the stance
    leg fixed, hip pitch + pelvis pitch is constant (hip pitch > 0 swings the leg
    back), so the seed's ``theta_pitch = -pelvis_pitch_rad`` and a forward lean
    gives a positive (hip-extending, uprighting) voltage.

    Args:
        kd: position gain k_d, V/rad (seed: 100 V/rad on hip pitch).
        theta_des: desired hip pitch angle, rad.
        theta_act: measured hip pitch (motor shaft) angle, rad.
        pelvis_pitch_rad: pelvis pitch about +y from the IMU, rad (forward lean > 0).
        gamma: from :func:`hip_switch_gamma`.

    Returns:
        Voltage, V (not saturated).
    """
    return kd * (gamma * (theta_des - theta_act) + (1.0 - gamma) * pelvis_pitch_rad)


def position_voltage(kd, theta_des, theta_act) -> jax.Array:
    """Proportional motor-shaft position loop ``v = k_d (theta_des - theta_act)`` (seed 000, eq. 25).

    Args:
        kd: gain(s), V/rad (seed: 10 ankle roll, 100 hip pitch, 500 others;
            ``actuators.default_kp_v_per_rad()``).
        theta_des: desired angle(s), rad.
        theta_act: measured motor-shaft angle(s), rad.

    Returns:
        Voltage(s), V (not saturated), broadcast shape of the inputs.
    """
    return kd * (theta_des - theta_act)


def knee_compensation(force_left_n, force_right_n, total_weight_n, mu_left_rad, mu_right_rad):
    """Feed-forward knee angles against the SEA spring compression (seed 000, eq. 21).

    ``delta_theta = -|F| / (m g) mu`` per leg, added to the desired knee angle:
    zero without contact, ``-mu`` when the leg carries the whole weight.
    ``mu`` is the mean steady-state spring deflection ``link - motor`` of a
    loaded knee (> 0 here, knee flexion being positive), identified from an
    open-loop in-place gait (seed Figure 7): adding ``-mu`` to the motor
    command brings the loaded link back to the desired angle.

    Args:
        force_left_n: left foot contact force (normal component or norm), N.
        force_right_n: right foot contact force, N.
        total_weight_n: total weight ``m g``, N.
        mu_left_rad: mean left knee spring deflection, rad.
        mu_right_rad: mean right knee spring deflection, rad.

    Returns:
        ``(delta_left_rad, delta_right_rad)``.
    """
    return (-jnp.abs(force_left_n) / total_weight_n * mu_left_rad,
            -jnp.abs(force_right_n) / total_weight_n * mu_right_rad)


def command_voltages(kp_v_per_rad, q_des_rad, q_act_rad, pelvis_pitch_rad, t_s, step_time_s, d) -> jax.Array:
    """All 23 motor voltages: eq. 24 on both hip pitch joints, eq. 25 elsewhere.

    Args:
        kp_v_per_rad: (23,) gains, ``actuators.JOINT_NAMES`` order.
        q_des_rad: (23,) desired angles (e.g. :func:`joint_targets` plus the knee
            compensation of :func:`knee_compensation`).
        q_act_rad: (23,) measured motor-shaft angles.
        pelvis_pitch_rad: pelvis pitch about +y, rad (forward lean > 0).
        t_s: time since the phase start, s.
        step_time_s: T, s.
        d: phase sign, +1 left swing, -1 right swing.

    Returns:
        (23,) voltages, V (not saturated).
    """
    kp, qd, qa = jnp.asarray(kp_v_per_rad), jnp.asarray(q_des_rad), jnp.asarray(q_act_rad)
    v = position_voltage(kp, qd, qa)
    left_swing = jnp.asarray(d) > 0
    for idx, swing in ((LEFT_HIP_PITCH, left_swing), (RIGHT_HIP_PITCH, ~left_swing)):
        gamma = hip_switch_gamma(t_s, step_time_s, swing)
        v = v.at[idx].set(hip_voltage(kp[idx], qd[idx], qa[idx], pelvis_pitch_rad, gamma).astype(v.dtype))
    return v

