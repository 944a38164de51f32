"""Soft tasks of the whole-body QP as rows, and PD laws that give their desired accelerations.

A :class:`Task` is a weighted least-squares term on the QP's physical unknowns, joint-space accelerations
``qdd`` (nv) and the world-frame corner forces ``f`` (24, in N, foot-major then corner then xyz):

    cost = sum_k weight_k (qdd_jac_k . qdd + force_jac_k . f - target_k)^2

A builder is a pure function returning one :class:`Task`; the QP (:func:`mjx_coman.wbc.qp.build_qp`)
sums any sequence of them, so a controller adds its own (a momentum-rate task, a null-space posture
objective, ...) without touching the core. A motion task ``||J qdd + Jdot qdot - a_des||^2_W`` is the
soft part of seed 001's eq. 2 and seed 004's motion objective ``J_J`` (eq. 5); weights are in
1/(unit of the row)^2, e.g. 1/(m/s^2)^2 for a CoM row, 1/N^2 for a force row.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman.wbc.batching import per_problem
from mjx_coman.wbc.plant import N_BASE, N_CORNERS, N_FEET, N_FORCES, Plant

LINEAR_XY = (0, 1)  # rows of the centroidal momentum (linear, then angular) selected by seed 004 eq. 8
LINEAR = (0, 1, 2)  # seed 004 eq. 7 (its h is [angular; linear]; ours is [linear; angular])


class Task(NamedTuple):
    """Rows of one soft task (arrays; ``None`` where the task does not see that unknown).

    Attributes:
        qdd_jac: (k, nv) or ``None``.
        force_jac: (k, 24) or ``None``; per newton of corner force.
        target: (k,).
        weight: (k,) non-negative.
    """

    qdd_jac: jax.Array | None
    force_jac: jax.Array | None
    target: jax.Array
    weight: jax.Array


def _rows_weight(weight, k: int) -> jax.Array:
    return jnp.broadcast_to(jnp.asarray(weight), (k,))


def motion_task(jac, bias_acc, acc_des, weight) -> Task:
    """``||J qdd + Jdot qdot - a_des||^2_W`` (seed 001 eq. 2, seed 004 eq. 5 ``J_J``); ``jac`` (k, nv)."""
    jac = jnp.asarray(jac)
    k = jac.shape[0]
    return Task(jac, None, jnp.broadcast_to(acc_des, (k,)) - bias_acc, _rows_weight(weight, k))


def com_task(plant: Plant, acc_des, weight) -> Task:
    """CoM acceleration ``a_com = J_com qdd + Jdot_com qdot`` towards ``acc_des`` (3,) in m/s^2."""
    return motion_task(plant.com_jac, plant.com_bias_acc, acc_des, weight)


def pelvis_orientation_task(plant: Plant, ang_acc_des, weight) -> Task:
    """Angular acceleration of the pelvis (world axes, rad/s^2) towards ``ang_acc_des`` (3,)."""
    return motion_task(plant.pelvis_jac[3:], plant.pelvis_bias_acc[3:], ang_acc_des, weight)


def torso_orientation_task(plant: Plant, ang_acc_des, weight) -> Task:
    """Angular acceleration of the torso (world axes, rad/s^2) towards ``ang_acc_des`` (3,)."""
    return motion_task(plant.torso_jac[3:], plant.torso_bias_acc[3:], ang_acc_des, weight)


def foot_task(plant: Plant, foot: int, acc_des, weight) -> Task:
    """6D acceleration of sole ``foot`` (static: 0 right, 1 left; linear then angular, world) towards
    ``acc_des`` (6,): the swing-foot task. Weight it by ``1 - contact_mask[foot]`` to switch it off in stance
    (a stance foot's acceleration is a hard constraint of the QP anyway)."""
    return motion_task(plant.sole_jac[foot], plant.sole_bias_acc[foot], acc_des, weight)


def joint_acc_task(acc_des, weight, nv: int) -> Task:
    """Actuated-joint accelerations ``qdd[6:]`` towards ``acc_des`` (nu,) in rad/s^2."""
    nu = nv - N_BASE
    jac = jnp.eye(nu, nv, N_BASE)
    return Task(jac, None, jnp.broadcast_to(acc_des, (nu,)), _rows_weight(weight, nu))


def posture_task(q_rad, qd_rad_per_s, q_ref_rad, kp, kd, weight) -> Task:
    """Joint posture: ``qdd_joint -> kp (q_ref - q) - kd qd`` (PD in joint space), all nu joints."""
    q_rad = jnp.asarray(q_rad)
    return joint_acc_task(joint_pd(q_ref_rad, q_rad, qd_rad_per_s, kp, kd), weight, q_rad.shape[-1] + N_BASE)


def momentum_rate_task(cmm, cmm_bias, hdot_des, weight, selection: tuple[int, ...] = LINEAR_XY) -> Task:
    """Selected rows of the centroidal momentum rate ``S (A qdd + Adot qdot) -> S hdot_des`` (seed 004
    eq. 6-8: ``||P S (A vdot - b)||^2`` with ``b = hdot_des - Adot v``).

    Args:
        cmm, cmm_bias: ``A`` (6, nv) and ``Adot qdot`` (6,), rows linear then angular momentum.
        hdot_des: desired momentum rate (6,): N, then N m.
        selection: static row indices kept (default :data:`LINEAR_XY`, seed 004 eq. 8: the vertical
            force is left to the posture, the angular rate to the optimisation).
    """
    sel = list(selection)
    if not sel or any(not 0 <= i < 6 for i in sel):
        raise ValueError(f"selection must be indices of the 6 momentum rows, got {selection}")
    pick = lambda a: jnp.stack([jnp.asarray(a)[i] for i in sel])  # noqa: E731 (static rows, no gather)
    return motion_task(pick(cmm), pick(cmm_bias), pick(hdot_des), weight)


def null_space_task(task_jac, qdd_des, weight) -> Task:
    """``||(I - J^+ J)(qdd - qdd_des)||^2_W`` (seed 004 eq. 10): a privileged acceleration acting only in the
    null space of the stacked task Jacobian ``task_jac`` (k, nv), e.g. straight-knee posture.

    On CPU the pseudo-inverse (an SVD) runs per problem (:func:`mjx_coman.wbc.batching.per_problem`), which
    differentiates in forward mode only: reverse mode through ``task_jac`` raises there.
    """
    task_jac = jnp.asarray(task_jac)
    nv = task_jac.shape[-1]
    pinv = per_problem(lambda j: jnp.linalg.pinv(j))(task_jac)  # SVD: a loop on CPU (batched LAPACK can deadlock there)
    proj = jnp.eye(nv, dtype=task_jac.dtype) - pinv @ task_jac
    return Task(proj, None, proj @ jnp.broadcast_to(qdd_des, (nv,)), _rows_weight(weight, nv))


def qdd_regularization(weight, nv: int) -> Task:
    """``||qdd||^2_W`` (seed 004 eq. 5 ``J_vdot``; seed 001 eq. 2 ``V_Qq`` with ``qdd_d = 0``)."""
    return Task(jnp.eye(nv), None, jnp.zeros(nv), _rows_weight(weight, nv))


def force_regularization(weight) -> Task:
    """``||f||^2_W`` over the 24 corner-force components (seed 004 eq. 5 ``J_rho``, seed 001 ``V_Q_lambda``)."""
    return Task(None, jnp.eye(N_FORCES), jnp.zeros(N_FORCES), _rows_weight(weight, N_FORCES))


def force_distribution_task(contact_pos, com, weight) -> Task:
    """Force cost per foot growing with its horizontal distance from the CoM: ``weight d_foot / (d_0 + d_1)``
    on each of its force components, so the foot closer to the CoM takes more load (seed 001, section II)."""
    centre = jnp.mean(contact_pos, axis=1)  # (2, 3)
    d = jnp.sqrt(jnp.sum((centre[:, :2] - com[:2]) ** 2, axis=-1) + 1e-12)
    per_foot = weight * d / jnp.sum(d)
    w = jnp.repeat(per_foot, N_CORNERS * 3)
    return Task(None, jnp.eye(N_FORCES), jnp.zeros(N_FORCES), w.reshape(N_FEET * N_CORNERS * 3))


# --- PD laws: desired accelerations --------------------------------------------------------------------


def joint_pd(q_ref_rad, q_rad, qd_rad_per_s, kp, kd, qd_ref_rad_per_s=0.0, qdd_ff_rad_per_s2=0.0) -> jax.Array:
    """``qdd_des = qdd_ff + kp (q_ref - q) + kd (qd_ref - qd)`` in rad/s^2 (kp in 1/s^2, kd in 1/s)."""
    return qdd_ff_rad_per_s2 + kp * (q_ref_rad - q_rad) + kd * (qd_ref_rad_per_s - qd_rad_per_s)


def position_pd(pos_des, pos, vel_des, vel, kp, kd, acc_ff=0.0) -> jax.Array:
    """``a_des = a_ff + kp (p_des - p) + kd (v_des - v)`` (CoM, swing foot)."""
    return acc_ff + kp * (pos_des - pos) + kd * (vel_des - vel)


def _vee_skew(r) -> jax.Array:
    """``vee((R - R^T) / 2) = sin(theta) u`` of a rotation ``R = exp(theta [u]x)``."""
    return 0.5 * jnp.stack([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])


def orientation_error(rot_des, rot) -> jax.Array:
    """Rotation vector ``theta u = log(R_des R^T)`` (world axes, rad): the rotation taking ``rot`` to ``rot_des``.

    ``theta = atan2(|v|, (tr - 1) / 2)`` with ``v = vee(skew(R_des R^T))``; smooth at zero error (series of
    ``theta / sin theta``), exact for any angle below pi (at exactly pi the axis is undefined).
    """
    r = rot_des @ jnp.swapaxes(rot, -1, -2)
    v = _vee_skew(r)
    s2 = jnp.sum(v * v)
    small = s2 < 1e-12
    s = jnp.sqrt(jnp.where(small, 1.0, s2))
    theta = jnp.arctan2(s, 0.5 * (jnp.trace(r) - 1.0))
    factor = jnp.where(small, 1.0 + s2 / 6.0, theta / s)
    return factor * v


def orientation_pd(rot_des, rot, omega_des, omega, kp, kd, alpha_ff=0.0) -> jax.Array:
    """``alpha_des = alpha_ff + kp log(R_des R^T) + kd (w_des - w)``, world axes, rad/s^2."""
    return alpha_ff + kp * orientation_error(rot_des, rot) + kd * (omega_des - omega)


def frame_velocity(jac, qvel) -> jax.Array:
    """Velocity ``J qdot`` of a point or frame (e.g. ``plant.pelvis_jac[3:] @ qvel`` is its angular velocity)."""
    return jac @ qvel
