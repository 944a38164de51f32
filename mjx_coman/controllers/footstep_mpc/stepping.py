"""What the torque-controlled walking families (``footstep-mpc``, ``straight-leg``) share around their planners.

Fixed step timing without contact sensing (seed 001, sec. III): step ``k`` stands on the right foot when ``k`` is
even; before step 0 a double support of ``start_s`` shifts the CoM toward the right foot. A config may hold
the clock for a late touchdown, sensed by the F/T contact flags (:func:`held_clock`, seed 004 sec. III-B). Each tick
(:func:`sense`): filter the encoders and the IMU, estimate the floating base on the previous tick's stance
soles (:func:`mjx_coman.controllers.torque.whole_body`), and on a new step anchor the new stance sole where the
estimate puts it and take the swing foot's lift-off pose. :func:`swing_and_base` turns a planned footstep
into the swing-foot and pelvis task accelerations (seed 001's trajectory layer,
:mod:`mjx_coman.controllers.footstep_mpc.trajectory`).

A config using these has the fields ``dt_s``, ``step_time_s``, ``start_s``, ``double_support_s``,
``encoder_filter_s``, ``imu_filter_s``, ``joystick_ramp_s``, ``shift_m``, ``com_ref_m``, ``sole_anchor_m``,
``posture_rad``, ``touchdown_depth_m``, ``clearance_m``, ``swing_kp_per_s2``, ``swing_kd_per_s``,
``base_kp_per_s2``, ``base_kd_per_s``, ``com_height_kp_per_s2``, ``com_height_kd_per_s``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_coman import wbc
from mjx_coman.actuators import make_actuator_params, torque_limits_nm
from mjx_coman.controllers import torque
from mjx_coman.controllers.base import Gait
from mjx_coman.controllers.footstep_mpc import trajectory as tr
from mjx_coman.env import MID_FOOT_AHEAD_M
from mjx_coman.floating_base import sole_site_ids
from mjx_coman.kinematics import quat_to_rot


class WalkState(NamedTuple):
    """Step bookkeeping and the estimator's anchors.

    Attributes:
        orient: the IMU filter's state.
        step: int32 index of the current step (-1: the start's double support).
        anchor_m: (2, 3) world positions of the (right, left) sole sites where last in stance.
        swing_start_m: (3,) the swing sole at lift-off.
        swing_start_quat: (4,) its orientation then.
        heading_rad: base yaw at the start of the current step (the stance foot's yaw).
        joint_rad: (23,) the filtered link angles (:func:`mjx_coman.controllers.torque.filter_joints`).
        delay_s: how far the step clock has been held back by late touchdowns, s.
        late_s: how long past its expected touchdown the current swing foot is still in the air, s.
    """

    orient: torque.OrientationState
    step: jax.Array
    anchor_m: jax.Array
    swing_start_m: jax.Array
    swing_start_quat: jax.Array
    heading_rad: jax.Array
    joint_rad: jax.Array
    delay_s: jax.Array
    late_s: jax.Array


class Sensed(NamedTuple):
    """One tick's estimate and timing (:func:`sense`).

    Attributes:
        readings: the sensor readings with the filtered link angles.
        tick: the estimated base, its whole-body terms and torque limits.
        sole_pos: (2, 3) estimated sole sites.
        step: int32 current step (-1 before step 0); ``t_in``: time into it, s.
        single: after the start; ``new``: the first tick of a step.
        stance, swing: 0 (right) or 1 (left).
        forward, lateral, turn: the ramped joystick (m/s, m/s, rad/s).
    """

    readings: object
    tick: torque.Tick
    sole_pos: jax.Array
    step: jax.Array
    t_in: jax.Array
    single: jax.Array
    new: jax.Array
    stance: jax.Array
    swing: jax.Array
    forward: jax.Array
    lateral: jax.Array
    turn: jax.Array


def init_walk(config) -> WalkState:
    f = config.com_ref_m.dtype
    return WalkState(torque.orientation_init(f), jnp.asarray(-1, jnp.int32), config.sole_anchor_m,
                     config.sole_anchor_m[1], jnp.asarray([1.0, 0.0, 0.0, 0.0], f), jnp.zeros((), f),
                     config.posture_rad, jnp.zeros((), f), jnp.zeros((), f))


def rot2(yaw):
    """2D rotation matrix of ``yaw`` (rad)."""
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def step_timing(config, time_s):
    """``(step, time in step s)``: step ``-1`` before ``start_s``."""
    rel = time_s - config.start_s
    k = jnp.floor(rel / config.step_time_s + 1e-6)
    k = jnp.where(rel < 0, -1.0, k)
    return k.astype(jnp.int32), jnp.where(rel < 0, 0.0, rel - jnp.maximum(k, 0.0) * config.step_time_s)


def held_clock(config, state: WalkState, time_s, swing_contact):
    """``(step, time in step, delay_s, late_s)``: :func:`step_timing` held back by late touchdowns (seed 004
    sec. III-B; configs with ``late_touchdown_on``, else never held). Where the clock would start a new step
    while the foot that swung (``swing_contact``: its F/T contact flag) has not touched down, it waits a tick,
    up to ``late_max_s`` per step; ``late_s`` counts the wait."""
    c = config
    k, _ = step_timing(c, time_s - state.delay_s)
    wait = (getattr(c, "late_touchdown_on", 0.0) > 0.5) & (state.step >= 0) & (k != state.step)
    wait = wait & ~swing_contact & (state.late_s < getattr(c, "late_max_s", 0.0) - 0.5 * c.dt_s)  # whole ticks
    delay = jnp.where(wait, state.delay_s + c.dt_s, state.delay_s)
    late = jnp.where(wait, state.late_s + c.dt_s, jnp.zeros_like(state.late_s))
    k, t_in = step_timing(c, time_s - delay)
    return k, t_in, delay, late


def joystick_now(config, joystick, time_s):
    """The joystick's velocities ramped in over ``joystick_ramp_s`` (seed 001, Fig. 4)."""
    ramp = jnp.clip(time_s / jnp.maximum(config.joystick_ramp_s, 1e-9), 0.0, 1.0)
    return ramp * joystick.forward_mps, ramp * joystick.lateral_mps, ramp * joystick.turn_rad_per_s


def start_com_m(config, time_s):
    """``(position, velocity, acceleration)`` of the CoM during the start: over the feet's centre at the
    stance height, shifted by ``shift_m`` toward the right foot along :func:`.trajectory.blend` (a CoM near
    the first stance foot at rest walks off into a near-periodic first step; from the centre, the LIPM would
    need a 0.4 m first step)."""
    c = config
    f = c.com_ref_m.dtype
    centre = jnp.mean(c.sole_anchor_m[:, :2], axis=0) + jnp.stack([jnp.asarray(MID_FOOT_AHEAD_M, f), jnp.zeros((), f)])
    s, sd, sdd = tr.blend(time_s, max(c.start_s, c.dt_s))
    toward = c.sole_anchor_m[0, :2] - c.sole_anchor_m[1, :2]
    toward = jnp.concatenate([toward / jnp.linalg.norm(toward), jnp.zeros(1, f)]) * c.shift_m
    return jnp.concatenate([centre, c.com_ref_m[2:]]) + s * toward, sd * toward, sdd * toward


def start_com_acc(config, plant, time_s):
    """The CoM acceleration of the start's shift (:func:`start_com_m`) by the height PD's gains."""
    c = config
    p, v, a = start_com_m(c, time_s)
    return wbc.position_pd(p, plant.com, v, plant.com_vel, c.com_height_kp_per_s2, c.com_height_kd_per_s, a)


def sense(config, state: WalkState, obs) -> tuple[WalkState, Sensed]:
    """Filter, estimate and advance the step bookkeeping (module docstring)."""
    c = config
    r = obs.readings
    f = c.com_ref_m.dtype
    joints = jnp.where(state.orient.started, torque.filter_joints(state.joint_rad, r.link_angle_rad,
                                                                    r.motor_vel_rad_per_s, c.dt_s, c.encoder_filter_s),
                       r.link_angle_rad.astype(f))  # the first tick: the encoders as read
    r = r._replace(link_angle_rad=joints.astype(r.link_angle_rad.dtype))
    orient = torque.orientation_step(state.orient, r, c.dt_s, c.imu_filter_s)
    fwd, lat, turn = (v.astype(f) for v in joystick_now(c, obs.joystick, obs.time_s.astype(f)))

    # estimate on the stance of the previous tick; a new step re-anchors (fixed timing, no contact sensing)
    was_single = state.step >= 0
    prev_stance = jnp.where(state.step % 2 == 0, 0, 1)
    est_mask = jnp.where(was_single, jax.nn.one_hot(prev_stance, 2, dtype=f), jnp.ones(2, f))
    tick = torque.whole_body(r, orient.quat, state.anchor_m, est_mask)
    est = tick.base
    sole_pos = est.data.site_xpos[sole_site_ids()]  # (2, 3)
    k, t_in, delay, late = held_clock(c, state, obs.time_s.astype(f), r.contact[1 - prev_stance])
    single = k >= 0
    stance = jnp.where(k % 2 == 0, 0, 1)
    swing = 1 - stance
    new = single & (k != state.step)
    measured_yaw = tr.quat_yaw(orient.quat)
    heading = jnp.where(new, jnp.where(k == 0, measured_yaw, state.heading_rad + turn * c.step_time_s),
                        state.heading_rad)
    anchor = jnp.where(new, state.anchor_m.at[stance].set(sole_pos[stance]), state.anchor_m)
    swing_quat_now = est.data.xquat[np.asarray(foot_body_ids())][swing]
    swing_start = jnp.where(new, sole_pos[swing], state.swing_start_m)
    swing_start_quat = jnp.where(new, swing_quat_now, state.swing_start_quat)
    state = WalkState(orient, jnp.where(single, k, state.step), anchor, swing_start, swing_start_quat, heading, joints,
                      delay, late)
    return state, Sensed(r, tick, sole_pos, k, t_in, single, new, stance, swing, fwd, lat, turn)


def swing_and_base(config, state: WalkState, s: Sensed, next_xy, yaw_next, swing_duration_s, swing_t_s,
                   late_down_mps=0.0, ground_z_m=None, lift_fraction=None):
    """Swing-foot (6,) and pelvis-orientation (3,) task accelerations toward the footstep ``next_xy`` (the foot's
    centre) at heading ``yaw_next`` (seed 001, sec. III; eq. 8), and the swing sole's position error, m.

    The swing runs from lift-off to ``swing_duration_s``; ``swing_t_s`` is the time into it. Past it, while
    the touchdown is late (``state.late_s``), the foot goes on down at ``late_down_mps`` (seed 004 sec. III-B).
    The footstep's sole lands at ``ground_z_m`` (a known terrain), else at the stance sole's height; with
    ``lift_fraction`` the foot steps over an edge (:func:`~.trajectory.step_over_reference`)."""
    c = config
    f = c.com_ref_m.dtype
    plant, est = s.tick.plant, s.tick.base
    target_sole = next_xy - rot2(yaw_next) @ jnp.stack([jnp.asarray(MID_FOOT_AHEAD_M, f), jnp.zeros((), f)])
    ground_z = state.anchor_m[s.stance, 2] if ground_z_m is None else ground_z_m
    args = (swing_t_s, swing_duration_s, state.swing_start_m, target_sole, ground_z - c.touchdown_depth_m,
            c.clearance_m, state.swing_start_quat, yaw_next)
    ref = tr.swing_foot_reference(*args) if lift_fraction is None else tr.step_over_reference(*args, lift_fraction)
    down = jnp.asarray([0.0, 0.0, 1.0], f) * late_down_mps
    ref = ref._replace(pos=ref.pos - state.late_s * down, vel=jnp.where(state.late_s > 0, -down, ref.vel))
    sole_vel = plant.sole_jac[s.swing] @ est.qvel  # (6,)
    lin = wbc.position_pd(ref.pos, s.sole_pos[s.swing], ref.vel, sole_vel[:3], c.swing_kp_per_s2, c.swing_kd_per_s,
                          ref.acc)
    ang = wbc.orientation_pd(quat_to_rot(ref.quat), plant.sole_rot[s.swing], ref.ang_vel, sole_vel[3:],
                             c.swing_kp_per_s2, c.swing_kd_per_s, ref.ang_acc)
    base_acc = upright_acc(c, state, s, plant.pelvis_rot, plant.pelvis_jac[3:] @ est.qvel)
    error = jnp.where(s.single, jnp.linalg.norm(ref.pos - s.sole_pos[s.swing]), 0.0)
    return jnp.concatenate([lin, ang]), base_acc, error


def upright_acc(config, state: WalkState, s: Sensed, rot, ang_vel):
    """Angular acceleration (3,) of a body (rotation ``rot``, world angular velocity ``ang_vel``) toward upright at
    the walk's heading, turning with the joystick over the step (seed 001, sec. III: the base; seed 004: the
    pelvis and the chest)."""
    c = config
    quat, w, wd = tr.base_reference(s.t_in, c.step_time_s, state.heading_rad, jnp.where(s.single, s.turn, 0.0))
    return wbc.orientation_pd(quat_to_rot(quat), rot, w, ang_vel, c.base_kp_per_s2, c.base_kd_per_s, wd)


def solve_torques(config, s: Sensed, tasks, mask, time_s, dtype, toe_off=None, qdd_bounds=None):
    """The whole-body QP of ``tasks`` with the stance ``mask`` (fixed upper body held by a joint PD outside it when
    the config says so; the stall torque as bounds; the config's iteration cap, retry and stance-row slack; the
    feet in ``toe_off``, :mod:`mjx_coman.wbc.contacts`; joint-acceleration bounds ``qdd_bounds``), and its torques
    ramped in after the reset: ``(qp, tau)``."""
    c = config
    est = s.tick.base
    extra = {} if toe_off is None else {"toe_off": toe_off}
    if qdd_bounds is not None:
        extra["qdd_bounds"] = qdd_bounds
    if c.fixed_upper_body:
        extra |= dict(fixed_upper_body=True, upper_acc=torque.upper_body_acc(
            c.posture_rad, est.qpos, est.qvel, c.posture_kp_per_s2, c.posture_kd_per_s))
    lo, hi = stall_torque_nm(s.tick.tau_min_nm)
    qp = wbc.solve(s.tick.plant, tasks, mask, lo, hi, friction_coeff=c.friction_coeff, max_iter=c.qp_max_iter,
                   retry_iter=c.qp_retry_iter or None, contact_slack_weight=c.contact_slack_weight or None, **extra)
    return qp, torque.startup_ramp(time_s, c.dt_s, c.startup_s).astype(dtype) * qp.tau.astype(dtype)


def gait(config, limits) -> Gait:
    """The :class:`~mjx_coman.controllers.base.Gait` of a config on this step clock; ``limits`` has the family's
    ``MAX_FORWARD_MPS``, ``MAX_LATERAL_MPS`` and ``MAX_TURN_RAD_PER_S``."""
    return Gait(knee_rad=config.knee_rad, control_period_s=config.dt_s, first_step_s=config.start_s,
                step_time_s=config.step_time_s, max_forward_mps=limits.MAX_FORWARD_MPS,
                max_lateral_mps=limits.MAX_LATERAL_MPS, max_turn_rad_per_s=limits.MAX_TURN_RAD_PER_S,
                plant=config.plant)


def stall_torque_nm(like):
    """``(lo, hi)``: the QP's torque bounds, the motors' stall torque. The speed-dependent voltage bound is left
    to the actuator: at a touchdown the landing leg's joint rates jump for a tick, and the voltage bound at those
    rates excluded every torque that holds the new contact (the QP was infeasible)."""
    return torque_limits_nm(make_actuator_params(), jnp.zeros_like(like))


def foot_body_ids() -> tuple[int, int]:
    """MuJoCo ids of the (right, left) foot bodies (foot index 0 = right)."""
    from mjx_coman.ground_truth import foot_body_ids as left_right

    left, right = left_right()
    return right, left
