"""``footstep-mpc``'s tick: the three layers of seed 001 on the estimated state, then torques.

Each tick: filter the IMU and estimate the floating base on the stance sole, and on a new step (fixed timing, no
contact sensing: seed 001, sec. III) anchor the new stance sole where the estimate puts it and take the swing
foot's lift-off pose (:mod:`.stepping`); plan the footsteps from the measured CoM state
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

from jaxlp import footsteps as fs
from jaxlp import lipm
from mjx_coman import wbc
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT, Telemetry
from mjx_coman.controllers.footstep_mpc import stepping
from mjx_coman.controllers.footstep_mpc import trajectory as tr
from mjx_coman.controllers.footstep_mpc.config import Config
from mjx_coman.env import MODE_TORQUE, Command

MPC_QP_MAX_ITER = 20

State = stepping.WalkState  # step bookkeeping and the estimator's anchors


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
    return stepping.init_walk(config)


def mpc_weights(config: Config) -> fs.MPCWeights:
    """The planner's weights from the config's tunables (seed 001, eq. 16)."""
    return fs.MPCWeights(config.mpc_com_midpoint_weight, config.mpc_com_step_weight, config.mpc_footstep_weight,
                         config.mpc_footstep_step_weight)


step_timing = stepping.step_timing
start_com_m = stepping.start_com_m
stall_torque_nm = stepping.stall_torque_nm


def step(config: Config, state: State, obs):
    c = config
    dtype = obs.readings.motor_angle_rad.dtype
    f = c.com_ref_m.dtype
    T = c.step_time_s
    state, s = stepping.sense(c, state, obs)
    est, plant = s.tick.base, s.tick.plant
    single, stance, t_in = s.single, s.stance, s.t_in
    heading, turn = state.heading_rad, s.turn

    # third layer: footsteps from the measured CoM state (seed 001, eq. 12-16)
    centre = jnp.mean(plant.contact_pos, axis=1)  # (2, 3) foot centres
    stance_xy = centre[stance, :2]
    z0 = c.com_ref_m[2]
    tau = lipm.time_constant_s(z0)
    sign = jnp.where(stance == 0, 1.0, -1.0).astype(f)
    plan = fs.reference_plan(stance_xy, heading, sign, s.forward, s.lateral, turn, T, c.half_width_m, c.n_steps)
    com_state = jnp.concatenate([plant.com[:2], plant.com_vel[:2]])
    remaining = jnp.clip(T - t_in, c.dt_s, T)
    kw = {}
    if c.mpc_solver == "qpax":
        kw = dict(max_com_offset_m=c.friction_coeff * z0, qp_solver=_mpc_qp_solver)
    sol = fs.plan_footsteps(com_state, stance_xy, remaining, plan, mpc_weights(c), T, tau, solver=c.mpc_solver, **kw)
    next_xy = sol.footsteps_m[0]

    # second layer: references and their PD accelerations (seed 001, sec. III)
    yaw_next = heading + turn * T
    ground_z = state.anchor_m[stance, 2]
    ds = c.double_support_s
    swing_acc, base_acc, swing_error = stepping.swing_and_base(c, state, s, next_xy, yaw_next, T - ds,
                                                                jnp.maximum(t_in - ds, 0.0))
    com_walk = tr.com_reference_acc(plant.com, plant.com_vel, stance_xy, ground_z + z0, c.com_height_kp_per_s2,
                                    c.com_height_kd_per_s, lipm_height_m=z0)
    com_start = stepping.start_com_acc(c, plant, obs.time_s.astype(f))
    com_acc = jnp.where(single, com_walk, com_start)

    # first layer: the whole-body QP (seed 001, eq. 2)
    both = ~single | (t_in < ds)  # the start, and each step's double support
    mask = jnp.where(both, jnp.ones(2, f), jax.nn.one_hot(stance, 2, dtype=f))
    tasks = [wbc.com_task(plant, com_acc, c.com_weight),
             wbc.pelvis_orientation_task(plant, base_acc, c.base_weight),
             *[wbc.foot_task(plant, i, swing_acc, c.swing_weight * (1.0 - mask[i])) for i in range(2)],
             wbc.posture_task(est.qpos[7:], est.qvel[6:], c.posture_rad, c.posture_kp_per_s2, c.posture_kd_per_s,
                              c.posture_weight),
             wbc.qdd_regularization(c.qdd_weight, est.qvel.shape[0]),
             wbc.force_regularization(c.force_weight_per_n2),
             wbc.force_distribution_task(plant.contact_pos, plant.com, c.force_weight_per_n2)]
    qp, tau_nm = stepping.solve_torques(c, s, tasks, mask, obs.time_s, dtype)

    # telemetry: heading frame, relative to the stance foot's centre
    to_local = stepping.rot2(heading).T
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
                    swing_error.astype(dtype),
                    (plant.com_jac @ qp.qdd + plant.com_bias_acc - com_acc).astype(dtype)),
        ok=qp.info.ok & sol.ok,
    )
    return state, Command(tau_nm, jnp.zeros(3, dtype), jnp.asarray(MODE_TORQUE, jnp.int32)), tel


def _mpc_qp_solver(Q, q, A, b, G, h):
    """The planner's QP by the whole-body QP's qpax wrapper (forward and reverse derivatives, CPU batching)."""
    return wbc.qpax_solve(Q, q, A, b, G, h, wbc.solver.stop_tol(Q.dtype), MPC_QP_MAX_ITER)

