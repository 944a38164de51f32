"""``footstep-mpc``'s tick: the three layers of seed 001 on the estimated state, then torques.

Each tick: filter the IMU and estimate the floating base on the stance sole (:mod:`mjx_coman.controllers.torque`);
on a new step (fixed timing, no contact sensing: seed 001, sec. III) anchor the new stance sole where the
estimate puts it and take the swing foot's lift-off pose; plan the footsteps from the measured CoM state
(:mod:`jaxlp.footsteps`, eq. 12-16, so a push moves the next footstep within one tick); build the swing-foot,
base and CoM references (:mod:`.trajectory`, eq. 3 and 8) and their PD accelerations; solve the whole-body QP
(:mod:`mjx_coman.wbc`, eq. 2) with the stance sole in contact. Step ``k`` stands on the right foot when ``k``
is even. Before step 0, a double support of ``start_s`` shifts the CoM toward the right foot; each step may
keep the previous stance foot in contact for ``double_support_s`` before it swings. The QP's torque bounds
are the stall torque (:func:`stall_torque_nm`); the actuator applies the voltage bound.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import footsteps as fs
from jaxlp import lipm
from mjx_coman import wbc
from mjx_coman.actuators import make_actuator_params, torque_limits_nm
from mjx_coman.controllers import torque
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT, Telemetry
from mjx_coman.controllers.footstep_mpc import trajectory as tr
from mjx_coman.controllers.footstep_mpc.config import Config
from mjx_coman.env import MID_FOOT_AHEAD_M, MODE_TORQUE, Command
from mjx_coman.floating_base import sole_site_ids
from mjx_coman.kinematics import quat_to_rot

MPC_QP_MAX_ITER = 20


class State(NamedTuple):
    """Step bookkeeping and the estimator's anchors.

    Attributes:
        orient: the IMU filter's state.
        step: int32 index of the current step (-1: the start's double support).
        anchor_m: (2, 3) world positions of the (right, left) sole sites where last in stance.
        swing_start_m: (3,) the swing sole at lift-off.
        swing_start_quat: (4,) its orientation then.
        heading_rad: base yaw at the start of the current step (the stance foot's yaw).
        joint_rad: (23,) the filtered link angles (:func:`mjx_coman.controllers.torque.filter_joints`).
    """

    orient: torque.OrientationState
    step: jax.Array
    anchor_m: jax.Array
    swing_start_m: jax.Array
    swing_start_quat: jax.Array
    heading_rad: jax.Array
    joint_rad: jax.Array


class Extra(NamedTuple):
    """``Telemetry.extra`` of footstep-mpc."""

    qp_iterations: jax.Array
    qp_kkt_residual: jax.Array
    qp_eq_residual: jax.Array
    qp_ineq_violation: jax.Array
    mpc_ok: jax.Array
    heading_rad: jax.Array
    swing_error_m: jax.Array  # |swing sole - its reference|
    com_acc_error_mps2: jax.Array  # (3,) the QP's CoM acceleration minus the reference's


def init(config: Config, env_params, key) -> State:
    f = config.com_ref_m.dtype
    return State(torque.orientation_init(f), jnp.asarray(-1, jnp.int32), config.sole_anchor_m,
                 config.sole_anchor_m[1], jnp.asarray([1.0, 0.0, 0.0, 0.0], f), jnp.zeros((), f),
                 config.posture_rad)


def mpc_weights(config: Config) -> fs.MPCWeights:
    """The planner's weights from the config's tunables (seed 001, eq. 16)."""
    return fs.MPCWeights(config.mpc_com_midpoint_weight, config.mpc_com_step_weight, config.mpc_footstep_weight,
                         config.mpc_footstep_step_weight)


def _rot2(yaw):
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def step_timing(config: Config, time_s):
    """``(step, time in step s)``: step ``-1`` before ``start_s``."""
    rel = time_s - config.start_s
    k = jnp.floor(rel / config.step_time_s + 1e-6)
    k = jnp.where(rel < 0, -1.0, k)
    return k.astype(jnp.int32), jnp.where(rel < 0, 0.0, rel - jnp.maximum(k, 0.0) * config.step_time_s)


def joystick_now(config: Config, joystick, time_s):
    """The joystick's velocities ramped in over ``joystick_ramp_s`` (seed 001, Fig. 4)."""
    ramp = jnp.clip(time_s / jnp.maximum(config.joystick_ramp_s, 1e-9), 0.0, 1.0)
    return ramp * joystick.forward_mps, ramp * joystick.lateral_mps, ramp * joystick.turn_rad_per_s


def start_com_m(config: Config, time_s):
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


def step(config: Config, state: State, obs):
    c = config
    r = obs.readings
    dtype = r.motor_angle_rad.dtype
    f = c.com_ref_m.dtype
    T = c.step_time_s
    ids = sole_site_ids()
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
    est, plant = tick.base, tick.plant
    sole_pos = est.data.site_xpos[ids]  # (2, 3)
    k, t_in = step_timing(c, obs.time_s.astype(f))
    single = k >= 0
    stance = jnp.where(k % 2 == 0, 0, 1)
    swing = 1 - stance
    new = single & (k != state.step)
    measured_yaw = tr.quat_yaw(orient.quat)
    heading = jnp.where(new, jnp.where(k == 0, measured_yaw, state.heading_rad + turn * T), state.heading_rad)
    anchor = jnp.where(new, state.anchor_m.at[stance].set(sole_pos[stance]), state.anchor_m)
    foot_bodies = np.asarray(_foot_body_ids())
    swing_quat_now = est.data.xquat[foot_bodies][swing]
    swing_start = jnp.where(new, sole_pos[swing], state.swing_start_m)
    swing_start_quat = jnp.where(new, swing_quat_now, state.swing_start_quat)
    state = State(orient, jnp.where(single, k, state.step), anchor, swing_start, swing_start_quat, heading, joints)

    # third layer: footsteps from the measured CoM state (seed 001, eq. 12-16)
    centre = jnp.mean(plant.contact_pos, axis=1)  # (2, 3) foot centres
    stance_xy = centre[stance, :2]
    z0 = c.com_ref_m[2]
    tau = lipm.time_constant_s(z0)
    sign = jnp.where(stance == 0, 1.0, -1.0).astype(f)
    plan = fs.reference_plan(stance_xy, heading, sign, fwd, lat, turn, T, c.half_width_m, c.n_steps)
    com_state = jnp.concatenate([plant.com[:2], plant.com_vel[:2]])
    remaining = jnp.clip(T - t_in, c.dt_s, T)
    kw = {}
    if c.mpc_solver == "qpax":
        kw = dict(max_com_offset_m=c.friction_coeff * z0, qp_solver=_mpc_qp_solver)
    sol = fs.plan_footsteps(com_state, stance_xy, remaining, plan, mpc_weights(c), T, tau, solver=c.mpc_solver, **kw)
    next_xy = sol.footsteps_m[0]

    # second layer: references and their PD accelerations (seed 001, sec. III)
    yaw_next = heading + turn * T
    target_sole = next_xy - _rot2(yaw_next) @ jnp.stack([jnp.asarray(MID_FOOT_AHEAD_M, f), jnp.zeros((), f)])
    ground_z = anchor[stance, 2]
    ds = c.double_support_s
    ref = tr.swing_foot_reference(jnp.maximum(t_in - ds, 0.0), T - ds, swing_start, target_sole,
                                  ground_z - c.touchdown_depth_m, c.clearance_m, swing_start_quat,
                                  yaw_next)
    sole_vel = plant.sole_jac[swing] @ est.qvel  # (6,)
    swing_lin = wbc.position_pd(ref.pos, sole_pos[swing], ref.vel, sole_vel[:3], c.swing_kp_per_s2, c.swing_kd_per_s,
                                ref.acc)
    swing_ang = wbc.orientation_pd(quat_to_rot(ref.quat), plant.sole_rot[swing], ref.ang_vel, sole_vel[3:],
                                   c.swing_kp_per_s2, c.swing_kd_per_s, ref.ang_acc)
    base_quat, base_w, base_wd = tr.base_reference(t_in, T, heading, jnp.where(single, turn, 0.0))
    base_acc = wbc.orientation_pd(quat_to_rot(base_quat), plant.pelvis_rot, base_w, plant.pelvis_jac[3:] @ est.qvel,
                                  c.base_kp_per_s2, c.base_kd_per_s, base_wd)
    com_walk = tr.com_reference_acc(plant.com, plant.com_vel, stance_xy, ground_z + z0, c.com_height_kp_per_s2,
                                    c.com_height_kd_per_s, lipm_height_m=z0)
    p_start, v_start, a_start = start_com_m(c, obs.time_s.astype(f))
    com_start = wbc.position_pd(p_start, plant.com, v_start, plant.com_vel, c.com_height_kp_per_s2,
                                c.com_height_kd_per_s, a_start)
    com_acc = jnp.where(single, com_walk, com_start)

    # first layer: the whole-body QP (seed 001, eq. 2)
    both = ~single | (t_in < ds)  # the start, and each step's double support
    mask = jnp.where(both, jnp.ones(2, f), jax.nn.one_hot(stance, 2, dtype=f))
    swing_acc = jnp.concatenate([swing_lin, swing_ang])
    tasks = [wbc.com_task(plant, com_acc, c.com_weight),
             wbc.pelvis_orientation_task(plant, base_acc, c.base_weight),
             *[wbc.foot_task(plant, i, swing_acc, c.swing_weight * (1.0 - mask[i])) for i in range(2)],
             wbc.posture_task(est.qpos[7:], est.qvel[6:], c.posture_rad, c.posture_kp_per_s2, c.posture_kd_per_s,
                              c.posture_weight),
             wbc.qdd_regularization(c.qdd_weight, est.qvel.shape[0]),
             wbc.force_regularization(c.force_weight_per_n2),
             wbc.force_distribution_task(plant.contact_pos, plant.com, c.force_weight_per_n2)]
    extra = {}
    if c.fixed_upper_body:
        extra = dict(fixed_upper_body=True, upper_acc=torque.upper_body_acc(
            c.posture_rad, est.qpos, est.qvel, c.posture_kp_per_s2, c.posture_kd_per_s))
    lo, hi = stall_torque_nm(tick.tau_min_nm)
    qp = wbc.solve(plant, tasks, mask, lo, hi, friction_coeff=c.friction_coeff, max_iter=c.qp_max_iter,
                   contact_slack_weight=c.contact_slack_weight or None, **extra)
    tau_nm = torque.startup_ramp(obs.time_s, c.dt_s, c.startup_s).astype(dtype) * qp.tau.astype(dtype)

    # telemetry: heading frame, relative to the stance foot's centre
    to_local = _rot2(heading).T
    rel = lambda v: (to_local @ v).astype(dtype)  # noqa: E731
    tel = Telemetry(
        support=jnp.where(single, jnp.where(stance == 0, SUPPORT_RIGHT, SUPPORT_LEFT), SUPPORT_DOUBLE).astype(jnp.int32),
        step=state.step,
        phase=jnp.where(single, t_in / T, 0.0).astype(dtype),
        next_footstep_m=rel(next_xy - stance_xy),
        footstep_adjustment_m=rel(jnp.where(single, next_xy - plan.footsteps_m[1], 0.0)),
        com_m=rel(plant.com[:2] - stance_xy),
        com_vel_mps=rel(plant.com_vel[:2]),
        extra=Extra(qp.info.iterations, qp.info.kkt_residual.astype(dtype), qp.info.eq_residual.astype(dtype),
                    qp.info.ineq_violation.astype(dtype), sol.ok, heading.astype(dtype),
                    jnp.where(single, jnp.linalg.norm(ref.pos - sole_pos[swing]), 0.0).astype(dtype),
                    (plant.com_jac @ qp.qdd + plant.com_bias_acc - com_acc).astype(dtype)),
        ok=qp.info.ok & sol.ok,
    )
    return state, Command(tau_nm, jnp.zeros(3, dtype), jnp.asarray(MODE_TORQUE, jnp.int32)), tel


def stall_torque_nm(like):
    """``(lo, hi)``: the QP's torque bounds, the motors' stall torque. The speed-dependent voltage bound is left
    to the actuator: at a touchdown the landing leg's joint rates jump for a tick, and the voltage bound at those
    rates excluded every torque that holds the new contact (the QP was infeasible)."""
    return torque_limits_nm(make_actuator_params(), jnp.zeros_like(like))


def _mpc_qp_solver(Q, q, A, b, G, h):
    """The planner's QP by the whole-body QP's qpax wrapper (forward and reverse derivatives, CPU batching)."""
    return wbc.qpax_solve(Q, q, A, b, G, h, wbc.solver.QPAX_TOL, MPC_QP_MAX_ITER)


def _foot_body_ids() -> tuple[int, int]:
    """MuJoCo ids of the (right, left) foot bodies (foot index 0 = right)."""
    from mjx_coman.ground_truth import foot_body_ids

    left, right = foot_body_ids()
    return right, left
