"""``straight-leg``'s tick: ICP planning and feedback, then the momentum-based whole-body QP (seed 004).

Each tick, on the robot's own sensors (:mod:`mjx_coman.controllers.footstep_mpc.stepping`: filters, floating
base on the stance sole, fixed step timing): the reference footsteps from the joystick (seed 001 eq. 14-15,
:func:`jaxlp.footsteps.reference_plan`); the ICP plan over constant CMPs at the previous stance foot, the stance
foot and each planned footstep, smoothed through every transfer (:func:`jaxlp.icp.plan`); the desired CMP by ICP
feedback on the estimated CoM state (:func:`jaxlp.icp.feedback_cmp`) and from it the desired linear momentum
rate ``m omega^2 (x - r_cmp)``, only its x-y rows as a task (eq. 6, 8). With ``step_adjust`` the next footstep
and the later ones move by the ICP error that the CMP, held at the edge of its range in the stance foot, would
leave at touchdown (:func:`jaxlp.icp.step_adjustment`); the feedback tracks the nominal plan. The swing foot
and the pelvis follow seed 001's trajectory layer. The vertical force is free: ``knee_mode="straight"`` adds
the privileged knee angles of :mod:`.legs` as joint accelerations ``kp (q_p - q) - kd qd`` (eq. 9, damping
opposing the velocity) projected into the null space of the task Jacobian ``[S A; J_pelvis; J_swing]`` (eq. 10;
``mjx_coman.wbc.null_space_task``, an SVD pseudo-inverse with a cut-off, finite at a straight knee); ``knee_mode="bent"`` holds the crouched CoM height by a task instead.

Toe-off (sec. IV): in each transfer the trailing foot rolls onto its toe point once the criteria of Fig. 6
hold (:mod:`.toe_off`; the CoP is the last tick's), its pitch left free in the QP (:mod:`mjx_coman.wbc.contacts`);
its swing then starts from the pose at lift-off.

Late touchdown (sec. III-B): where the swing foot's F/T sensor reads no contact at the step's end, the step
clock waits (up to ``late_max_s``; :func:`~mjx_coman.controllers.footstep_mpc.stepping.held_clock`), the foot goes
on down at ``late_down_mps``, its weight rising and the pelvis orientation's falling linearly with the time past.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp import footsteps as fs
from jaxlp import icp
from mjx_coman import wbc
from mjx_coman.actuators import JOINT_INDEX
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT, Telemetry
from mjx_coman.controllers.footstep_mpc import stepping
from mjx_coman.controllers.straight_leg import foothold as fh
from mjx_coman.controllers.straight_leg import legs as lg
from mjx_coman.controllers.straight_leg import toe_off as to
from mjx_coman.controllers.straight_leg.config import Config
from mjx_coman.env import MID_FOOT_AHEAD_M, MODE_TORQUE, Command
from mjx_coman.wbc.contacts import TOE_CORNERS
from mjx_coman.wbc.plant import N_BASE

KNEES = (JOINT_INDEX["RKneeSag"], JOINT_INDEX["LKneeSag"])
LEG_JOINTS = 12
GRAVITY_MPS2 = 9.81


class State(NamedTuple):
    """The walk's bookkeeping, the legs' states, toe-off (1 while the trailing foot is on its toe in this
    transfer), and each foot's CoP (world x-y) and normal force under the last tick's QP forces."""

    walk: stepping.WalkState
    legs: lg.LegState
    toe: jax.Array
    cop_m: jax.Array
    load_n: jax.Array


class Extra(NamedTuple):
    """``Telemetry.extra`` of straight-leg."""

    qp_iterations: jax.Array
    qp_kkt_residual: jax.Array
    qp_eq_residual: jax.Array
    qp_ineq_violation: jax.Array
    leg_mode: jax.Array  # (2,) int32, :mod:`.legs`
    privileged_knee_rad: jax.Array  # (2,)
    knee_rad: jax.Array  # (2,) estimated
    icp_m: jax.Array  # (2,) estimated ICP, world
    icp_ref_m: jax.Array  # (2,) the plan's, world
    cmp_m: jax.Array  # (2,) desired CMP, world
    step_offset_m: jax.Array  # (2,) step adjustment (0 without it)
    swing_error_m: jax.Array
    toe_off: jax.Array  # 1 while the trailing foot is on its toe
    late_s: jax.Array  # time past the expected touchdown of the swing foot still in the air


# the sole corners in order around the sole (mjx_coman.mjcf.FOOT_CORNERS: upper_left, upper_right, lower_left,
# lower_right)
AROUND = (0, 1, 3, 2)


def init(config: Config, env_params, key) -> State:
    f = config.com_ref_m.dtype
    return State(stepping.init_walk(config), lg.init(config.knee_rad, f), jnp.zeros((), f),
                 config.sole_anchor_m[:, :2], jnp.zeros(2, f))


def centre_of_pressure(forces, contact_pos, fallback):
    """(2, 2): each foot's CoP from its corner forces (2, 4, 3); ``fallback`` (2, 2) where it carries < 1 N."""
    fz = jnp.maximum(forces[..., 2], 0.0)
    total = jnp.sum(fz, axis=1)
    cop = jnp.einsum("fc,fci->fi", fz, contact_pos[..., :2]) / jnp.maximum(total, 1e-9)[:, None]
    return jnp.where((total > 1.0)[:, None], cop, fallback)


def omega(config: Config):
    return jnp.sqrt(GRAVITY_MPS2 / config.icp_height_m)


def foot_centre(sole_xy, yaw):
    """The sole's centre (the CMP of a flat foot) from its site and heading."""
    ahead = jnp.stack([jnp.asarray(MID_FOOT_AHEAD_M, sole_xy.dtype), jnp.zeros((), sole_xy.dtype)])
    return sole_xy + stepping.rot2(yaw) @ ahead


def icp_plan(config: Config, walk: stepping.WalkState, s: stepping.Sensed, footsteps_xy, prev_xy):
    """The ICP plan at this tick: CMPs at the previous stance foot, the stance foot, the planned footsteps and,
    last, between the final two (:func:`jaxlp.icp.step_cmps`); the switch into the stance foot at mid-transfer."""
    c = config
    cmps = jnp.concatenate([prev_xy[None], icp.step_cmps(footsteps_xy[0], footsteps_xy[1:], c.n_steps)])
    first = 0.5 * c.transfer_s - s.t_in
    return icp.plan(cmps, first, c.step_time_s, omega(c), c.transfer_s)


def step(config: Config, state: State, obs):
    c = config
    dtype = obs.readings.motor_angle_rad.dtype
    f = c.com_ref_m.dtype
    T = c.step_time_s
    walk, s = stepping.sense(c, state.walk, obs)
    est, plant = s.tick.base, s.tick.plant
    single, stance, swing, t_in = s.single, s.stance, s.swing, s.t_in
    time_s = obs.time_s.astype(f)
    heading = walk.heading_rad
    w = omega(c)
    mass = plant.mass[0, 0]

    # footsteps and the ICP plan (seed 004 sec. II-A, ref. [21])
    stance_xy = foot_centre(walk.anchor_m[stance, :2], heading)
    sign = jnp.where(stance == 0, 1.0, -1.0).astype(f)
    ref = fs.reference_plan(stance_xy, heading, sign, s.forward, s.lateral, s.turn, T, c.half_width_m, c.n_steps)
    start_xy = stepping.start_com_m(c, c.start_s)[0][:2]
    prev_xy = jnp.where(s.step == 0, start_xy, foot_centre(walk.anchor_m[swing, :2], heading))
    xi = icp.capture_point(plant.com[:2], plant.com_vel[:2], w)
    on_terrain = lambda steps: fh.footholds(c.terrain, stance_xy, steps, overhang_m=c.stair_overhang_m,  # noqa: E731
                                            max_step_m=c.stair_max_step_m)
    nominal = ref.footsteps_m
    if c.terrain != "flat":  # static: the footsteps on the known terrain (stairs: whole treads)
        nominal = nominal.at[1:].set(on_terrain(nominal[1:])[0])
    # the CMP feedback tracks the nominal plan (a step adjustment assumes the CMP at its margin till touchdown)
    xi_ref, xid_ref, _ = icp.reference(icp_plan(c, walk, s, nominal, prev_xy), 0.0)
    # step adjustment, in the stance foot's frame: the ICP error the CMP cannot null before touchdown
    to_foot = stepping.rot2(heading).T
    margin = jnp.stack([c.adjust_cmp_margin_x_m, c.adjust_cmp_margin_y_m])
    offset, _ = icp.step_adjustment(to_foot @ xi, to_foot @ xi_ref, w, T - t_in, margin, c.adjust_weight,
                                    c.adjust_icp_weight, c.max_adjustment_m, c.adjust_deadband_m)
    offset = jnp.where(single, c.step_adjust_on * (to_foot.T @ offset), 0.0)
    footsteps = nominal.at[1:].add(offset)
    landing_z = None
    if c.terrain != "flat":  # the adjusted footsteps on the terrain too, soles at its height
        ahead, heights = on_terrain(footsteps[1:])
        footsteps = footsteps.at[1:].set(ahead)
        landing_z = (heights[0] + jnp.mean(c.sole_anchor_m[:, 2])).astype(f)
    cmp = icp.feedback_cmp(xi, xi_ref, xid_ref, w, c.icp_gain)

    # momentum rate: m omega^2 (x - r_cmp) while walking, the start's CoM shift before
    start_acc = stepping.start_com_acc(c, plant, time_s)
    acc_xy = jnp.where(single, icp.lip_com_acceleration(plant.com[:2], cmp, w), start_acc[:2])
    hdot = jnp.concatenate([mass * acc_xy, jnp.zeros(4, f)])

    # toe-off of the trailing (swing) foot in transfer (sec. IV): on once the criteria of Fig. 6 hold
    transfer = single & (t_in < c.transfer_s)
    toe_xy = jnp.mean(plant.contact_pos[swing, jnp.asarray(TOE_CORNERS), :2], axis=0)
    light = state.load_n[swing] < c.toe_off_load_fraction * mass * GRAVITY_MPS2
    crit = to.criteria(xi_ref, xi, cmp, state.cop_m[swing], light, toe_xy,
                       plant.contact_pos[stance, jnp.asarray(AROUND), :2], stance_xy,
                       icp_distance_m=c.toe_off_icp_distance_m, cop_distance_m=c.toe_off_cop_distance_m,
                       cmp_distance_m=c.toe_off_cmp_distance_m)
    toe = jnp.where(s.new, 0.0, state.toe)
    may = crit.all & (t_in >= c.toe_off_delay_s)
    toe = jnp.where(transfer, jnp.maximum(toe, c.toe_off_on * may.astype(f)), 0.0)
    toe_off = jax.nn.one_hot(swing, 2, dtype=f) * toe
    # the swing starts from the pose at lift-off (pitched after a toe-off)
    lift = single & (t_in >= c.transfer_s) & (t_in - c.dt_s < c.transfer_s)
    feet_quat = est.data.xquat[jnp.asarray(stepping.foot_body_ids())]
    walk = walk._replace(swing_start_m=jnp.where(lift, s.sole_pos[swing], walk.swing_start_m),
                         swing_start_quat=jnp.where(lift, feet_quat[swing], walk.swing_start_quat))

    # swing foot and pelvis (seed 001's trajectory layer)
    yaw_next = heading + s.turn * T
    swing_acc, base_acc, swing_error = stepping.swing_and_base(c, walk, s, footsteps[1], yaw_next, c.swing_s,
                                                                jnp.maximum(t_in - c.transfer_s, 0.0),
                                                                c.late_down_mps, landing_z,
                                                                None if landing_z is None else c.step_over_fraction)
    # late touchdown (sec. III-B): the swing foot's weight up, the pelvis's down with the time past touchdown
    swing_w = c.swing_weight * (1.0 + c.late_swing_weight_per_s * walk.late_s)
    base_w = c.base_weight * jnp.maximum(1.0 - c.late_pelvis_weight_per_s * walk.late_s, 0.0)

    # the legs' privileged knees (Fig. 5)
    knees = jnp.stack([est.qpos[7 + KNEES[0]], est.qpos[7 + KNEES[1]]])
    legs = lg.update(state.legs, c, single=single, new=s.new, stance=stance, t_in=t_in, time_s=time_s,
                     knee_rad=knees)
    knee_p = lg.privileged_knee_rad(legs, c, time_s)

    both = ~single | (t_in < c.transfer_s)  # the start, and each step's transfer
    mask = jnp.where(both, jnp.ones(2, f), jax.nn.one_hot(stance, 2, dtype=f))
    nv = est.qvel.shape[0]
    momentum = wbc.momentum_rate_task(plant.cmm, plant.cmm_bias, hdot, c.momentum_weight)
    pelvis = wbc.pelvis_orientation_task(plant, base_acc, base_w)
    feet = [wbc.foot_task(plant, i, swing_acc, swing_w * (1.0 - mask[i])) for i in range(2)]
    posture_w = jnp.ones(nv - N_BASE, f).at[jnp.asarray(KNEES)].set(0.0) * c.posture_weight
    tasks = [momentum, pelvis, *feet,
             wbc.posture_task(est.qpos[7:], est.qvel[6:], c.posture_rad, c.posture_kp_per_s2, c.posture_kd_per_s,
                              posture_w),
             wbc.qdd_regularization(c.qdd_weight, nv),
             wbc.force_regularization(c.force_weight_per_n2),
             wbc.force_distribution_task(plant.contact_pos, plant.com, c.force_weight_per_n2)]
    # straight legs: the privileged knees in the tasks' null space (eq. 9-10); bent (the baseline): the
    # crouched CoM height. Both rows are built, weighted by the variant's switch (one structure for all).
    q_p = est.qpos[7:].at[jnp.asarray(KNEES)].set(knee_p)
    qdd_p = wbc.joint_pd(q_p, est.qpos[7:], est.qvel[6:], c.privileged_kp_per_s2, c.privileged_kd_per_s)
    qdd_p = jnp.concatenate([jnp.zeros(N_BASE, f), qdd_p])
    # the total task Jacobian: the feet are motion objectives too (the stance sole held, the swing sole tracked),
    # else the projected posture fights the stance rows through the soft tasks
    task_rows = [momentum.qdd_jac, pelvis.qdd_jac, plant.sole_jac[0], plant.sole_jac[1]]
    if not c.fixed_upper_body:  # static: the chest upright at the heading (eq. 5's chest objective); the arms
        # keep their posture rows (the posture task covers every joint)
        chest_acc = stepping.upright_acc(c, walk, s, plant.torso_rot, plant.torso_jac[3:] @ est.qvel)
        chest = wbc.torso_orientation_task(plant, chest_acc, c.chest_weight)
        tasks.append(chest)
        task_rows.append(chest.qdd_jac)
    task_jac = jnp.concatenate(task_rows)
    rows_w = jnp.zeros(nv, f).at[N_BASE:N_BASE + LEG_JOINTS].set(c.privileged_weight * c.straight_legs)
    tasks.append(wbc.null_space_task(task_jac, qdd_p, rows_w))
    ground_z = walk.anchor_m[stance, 2]
    z_acc = wbc.position_pd(ground_z + c.com_ref_m[2], plant.com[2], 0.0, plant.com_vel[2],
                            c.com_height_kp_per_s2, c.com_height_kd_per_s)
    z_acc = jnp.where(single, z_acc, start_acc[2])
    tasks.append(wbc.motion_task(plant.com_jac[2:3], plant.com_bias_acc[2:3], z_acc,
                                 c.com_height_weight * (1.0 - c.straight_legs)))
    q_range = jnp.asarray(wbc.joint_range_rad(), f)
    bounds = wbc.joint_acc_bounds(est.qpos[7:], est.qvel[6:], q_range[0], q_range[1], c.joint_limit_horizon_s,
                                  c.joint_limit_max_acc)
    qp, tau_nm = stepping.solve_torques(c, s, tasks, mask, obs.time_s, dtype, toe_off=toe_off, qdd_bounds=bounds)
    cop = centre_of_pressure(qp.forces, plant.contact_pos, state.cop_m)

    to_local = stepping.rot2(heading).T
    rel = lambda v: (to_local @ v).astype(dtype)  # noqa: E731
    tel = Telemetry(
        support=jnp.where(single, jnp.where(both, SUPPORT_DOUBLE, jnp.where(stance == 0, SUPPORT_RIGHT, SUPPORT_LEFT)),
                          SUPPORT_DOUBLE).astype(jnp.int32),
        step=walk.step,
        phase=jnp.where(single, t_in / T, 0.0).astype(dtype),
        next_footstep_m=rel(footsteps[1] - stance_xy),
        footstep_adjustment_m=rel(offset),
        com_m=rel(plant.com[:2] - stance_xy),
        com_vel_mps=rel(plant.com_vel[:2]),
        extra=Extra(qp.info.iterations, qp.info.kkt_residual.astype(dtype),
                    qp.info.eq_residual.astype(dtype), qp.info.ineq_violation.astype(dtype), legs.mode, knee_p.astype(dtype),
                    knees.astype(dtype), xi.astype(dtype), xi_ref.astype(dtype), cmp.astype(dtype),
                    offset.astype(dtype), swing_error.astype(dtype), toe.astype(dtype),
                    walk.late_s.astype(dtype)),
        ok=qp.info.ok,
    )
    load = jnp.sum(jnp.maximum(qp.forces[..., 2], 0.0), axis=1)
    command = Command(tau_nm, jnp.zeros(3, dtype), jnp.asarray(MODE_TORQUE, jnp.int32))
    return State(walk, legs, toe, cop.astype(f), load.astype(f)), command, tel
