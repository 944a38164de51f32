"""Assembly of the whole-body QP (seed 001 eq. 2; seed 004 eq. 5) in qpax's form.

    min_x  1/2 x^T Q x + q^T x   s.t.   A x = b,   G x <= h

Unknowns ``x = [qdd_free, f / FORCE_SCALE_N]``: the joint-space accelerations that are decision variables
(all ``nv``, or the base and the 12 leg joints with the upper body fixed) and the 24 world-frame corner
forces in units of :data:`FORCE_SCALE_N`. Torques are not unknowns: from the actuated rows of
``M qdd + h - passive = S^T tau + J_c^T f`` they are the affine map ``tau = T x + tau_0`` (``QP.tau_map``,
``QP.tau_offset``), applied after the solve. Hard rows:

* equalities: the 6 unactuated (floating-base) rows of the dynamics, in units of FORCE_SCALE_N;
  per foot, stance acceleration or zero wrench (:func:`mjx_coman.wbc.contacts.contact_equalities`);
* inequalities: ``tau_min <= tau <= tau_max`` in units of :data:`TORQUE_SCALE_NM`; friction pyramids and
  unilateral (min) normal force per corner in units of FORCE_SCALE_N (which also keeps each CoP in its
  foot, see :mod:`mjx_coman.wbc.contacts`); optionally (``qdd_bounds``, static presence) joint-acceleration
  bounds on the actuated unknowns (seed 004 eq. 5, e.g. from the joint limits: :mod:`mjx_coman.wbc.limits`)
  in units of :data:`ACC_SCALE`.

The soft tasks (:mod:`mjx_coman.wbc.tasks`) give ``Q = 2 sum R^T W R + eps I`` and ``q = -2 sum R^T W t``
(``eps``, ``hessian_eps``, keeps ``Q`` positive definite). Scaling keeps rows and unknowns O(1-10):
forces ~100 N per unit, torques ~10 N m per unit, accelerations in SI.

With ``fixed_upper_body`` (a Python bool, static; seed 001 keeps waist and arms still) the 11 waist and
arm accelerations are not unknowns but given (``upper_acc``, e.g. :func:`mjx_coman.wbc.tasks.joint_pd`
towards their reference); their torques still follow from the same affine map and are limited.

With ``contact_slack_weight`` w (static presence) 12 more unknowns ``e`` (m/s^2, rad/s^2) relax the stance
rows to ``J_sole qdd + Jdot qdot = e`` at a cost ``w |e|^2`` (a lifted foot's slack has no row and is held
at 0 by its cost). The hard problem can be infeasible: a foot declared in stance at its scheduled time
while the torque bounds or the friction pyramid cannot hold it still; the relaxed one always has a solution
(zero forces, ``tau = 0``, the stance feet accelerating with the free-falling body) and equals the hard one
where that is feasible, up to ``O(1 / w)``.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from mjx_coman.wbc.contacts import check_n_faces, contact_equalities, corner_mask, force_share, friction_rows
from mjx_coman.wbc.plant import LEG_JOINTS, N_BASE, N_FORCES, Plant, check_plant
from mjx_coman.wbc.tasks import Task

FORCE_SCALE_N = 100.0
TORQUE_SCALE_NM = 10.0
ACC_SCALE = 10.0  # rad/s^2 per unit of a joint-acceleration bound row
DESIGN_FRICTION = 0.7  # below the model's 1.0
N_SLACK = 12  # stance-row slacks (6 per foot) with contact_slack_weight


class QP(NamedTuple):
    """One assembled QP and the maps back to physical quantities (arrays; vmappable).

    Attributes:
        Q, q, A, b, G, h: qpax's data; ``n`` unknowns, ``m`` equalities, ``p`` inequalities.
        qdd_map, qdd_offset: ``qdd = qdd_map x + qdd_offset``, (nv, n), (nv,).
        force_map: ``f = force_map x`` in N, (24, n).
        tau_map, tau_offset: ``tau = tau_map x + tau_offset`` in N m, (nu, n), (nu,).
        eq_scale, ineq_scale: per row, physical units of one unit of the scaled row, (m,), (p,).
    """

    Q: jax.Array
    q: jax.Array
    A: jax.Array
    b: jax.Array
    G: jax.Array
    h: jax.Array
    qdd_map: jax.Array
    qdd_offset: jax.Array
    force_map: jax.Array
    tau_map: jax.Array
    tau_offset: jax.Array
    eq_scale: jax.Array
    ineq_scale: jax.Array


def free_joints(nv: int, fixed_upper_body: bool) -> np.ndarray:
    """Indices into qdd of the acceleration unknowns (static)."""
    return np.arange(N_BASE + LEG_JOINTS if fixed_upper_body else nv)


def problem_size(nv: int = 29, fixed_upper_body: bool = False, n_faces: int = 4,
                 contact_slack: bool = False, qdd_bounds: bool = False) -> dict[str, int]:
    """``{variables, equalities, inequalities}`` of the QP (static)."""
    n_q = len(free_joints(nv, fixed_upper_body))
    n = n_q + N_FORCES + (N_SLACK if contact_slack else 0)
    bounds = 2 * (n_q - N_BASE) if qdd_bounds else 0
    return dict(variables=n, equalities=N_BASE + 12, inequalities=2 * (nv - N_BASE) + 8 * (n_faces + 1) + bounds)


def _task_rows(task: Task, qdd_map, qdd_offset, force_map):
    """A task's rows on ``x`` and its target moved by the fixed accelerations."""
    rows, target = 0.0, task.target
    if task.qdd_jac is not None:
        rows = rows + task.qdd_jac @ qdd_map
        target = target - task.qdd_jac @ qdd_offset
    if task.force_jac is not None:
        rows = rows + task.force_jac @ force_map
    return rows, target


def build_qp(plant: Plant, tasks: Sequence[Task], contact_mask, tau_min_nm, tau_max_nm, *,
             friction_coeff=DESIGN_FRICTION, min_normal_force_n=0.0, hessian_eps=1e-6,
             fixed_upper_body: bool = False, upper_acc=None, n_faces: int = 4, contact_slack_weight=None,
             toe_off=None, qdd_bounds=None) -> QP:
    """Assemble the whole-body QP of one state (pure; vmap it for a batch).

    Args:
        plant: the state's :class:`~mjx_coman.wbc.plant.Plant`.
        tasks: soft :class:`~mjx_coman.wbc.tasks.Task` s (a static sequence; at least one).
        contact_mask: (2,) 1 for a foot in stance, 0 for a lifted one (right, left).
        tau_min_nm, tau_max_nm: torque limits (nu,) of this tick.
        friction_coeff: design friction coefficient of the pyramids.
        min_normal_force_n: least normal force per stance corner, scalar or (2, 4).
        hessian_eps: added to Q's diagonal.
        fixed_upper_body: static; waist and arm accelerations given by ``upper_acc`` (11,).
        n_faces: static number of pyramid faces (>= 4).
        contact_slack_weight: ``None`` (hard stance rows) or the weight of the stance-row slacks (module
            docstring), per (m/s^2)^2.
        toe_off: ``None`` or (2,) 1 for a stance foot on its toe (:mod:`mjx_coman.wbc.contacts`): its heel
            forces are cut and its pitch freed; needs ``contact_slack_weight``. Ignored for a lifted foot.
        qdd_bounds: ``None`` or ``(lo, hi)``, each (nu,): hard bounds on the actuated joints' accelerations
            that are unknowns (the legs' with ``fixed_upper_body``), rad/s^2.

    Raises:
        ValueError: wrong plant shapes, no tasks, or ``upper_acc`` given or missing against
            ``fixed_upper_body``.
    """
    nv = check_plant(plant)
    nu = nv - N_BASE
    if not tasks:
        raise ValueError("tasks is empty: the QP needs at least one soft task (e.g. a regularization)")
    if fixed_upper_body and upper_acc is None:
        raise ValueError("fixed_upper_body=True needs upper_acc, the waist and arm accelerations")
    if not fixed_upper_body and upper_acc is not None:
        raise ValueError("upper_acc is given but fixed_upper_body=False: the upper body is free")
    if toe_off is not None and contact_slack_weight is None:
        raise ValueError("toe_off needs contact_slack_weight: a toe-off foot's free pitch is a zero stance row")
    check_n_faces(n_faces)  # before any work
    dt = plant.mass.dtype
    free = free_joints(nv, fixed_upper_body)
    n_q = len(free)
    n_f = n_q + N_FORCES
    n = n_f + (0 if contact_slack_weight is None else N_SLACK)
    qdd_map = jnp.zeros((nv, n), dt).at[free, free].set(1.0)
    qdd_offset = jnp.zeros(nv, dt)
    if fixed_upper_body:
        qdd_offset = qdd_offset.at[n_q:].set(jnp.broadcast_to(jnp.asarray(upper_acc, dt), (nv - n_q,)))
    if toe_off is not None:  # a lifted foot is never on its toe (its zero-wrench rows would lose rank)
        toe_off = jnp.asarray(toe_off, dt) * (jnp.asarray(contact_mask) > 0.5).astype(dt)
    share = jnp.eye(N_FORCES, dtype=dt) if toe_off is None else force_share(toe_off)
    force_map = jnp.zeros((N_FORCES, n), dt).at[:, n_q:n_f].set(FORCE_SCALE_N * share)

    # dynamics (seed 001 eq. 1): M qdd + h - passive - J_c^T (mask f) = S^T tau
    h_eff = plant.bias - plant.passive
    jc = plant.contact_jac.reshape(N_FORCES, nv) * corner_mask(contact_mask)[:, None].astype(dt)  # heels: force_map
    dyn = plant.mass @ qdd_map - jc.T @ force_map  # (nv, n)
    dyn0 = plant.mass @ qdd_offset + h_eff
    tau_map, tau_offset = dyn[N_BASE:], dyn0[N_BASE:]

    c_qdd, c_f, c_rhs = contact_equalities(plant, contact_mask, toe_off)
    c_rows = c_qdd @ qdd_map + c_f @ force_map
    c_rhs = c_rhs - c_qdd @ qdd_offset
    stance = jnp.repeat(jnp.asarray(contact_mask), 6) > 0.5
    c_scale = jnp.where(stance, 1.0, FORCE_SCALE_N).astype(dt)  # stance rows in SI, lifted ones in N
    if contact_slack_weight is not None:  # stance rows: J qdd - e = -Jdot qdot
        c_rows = c_rows.at[:, n_f:].set(-jnp.diag(stance.astype(dt)))
    A = jnp.concatenate([dyn[:N_BASE] / FORCE_SCALE_N, c_rows / c_scale[:, None]])
    b = jnp.concatenate([-dyn0[:N_BASE] / FORCE_SCALE_N, c_rhs / c_scale])
    eq_scale = jnp.concatenate([jnp.full(N_BASE, FORCE_SCALE_N, dt), c_scale])

    tmin = jnp.broadcast_to(jnp.asarray(tau_min_nm, dt), (nu,))
    tmax = jnp.broadcast_to(jnp.asarray(tau_max_nm, dt), (nu,))
    fr, fr_rhs = friction_rows(plant.sole_rot, contact_mask, friction_coeff, min_normal_force_n, n_faces, toe_off)
    G = jnp.concatenate([tau_map / TORQUE_SCALE_NM, -tau_map / TORQUE_SCALE_NM, fr @ force_map / FORCE_SCALE_N])
    h = jnp.concatenate([(tmax - tau_offset) / TORQUE_SCALE_NM, (tau_offset - tmin) / TORQUE_SCALE_NM,
                         fr_rhs / FORCE_SCALE_N])
    ineq_scale = jnp.concatenate([jnp.full(2 * nu, TORQUE_SCALE_NM, dt), jnp.full(fr.shape[0], FORCE_SCALE_N, dt)])
    if qdd_bounds is not None:  # lo <= qdd_j <= hi on the actuated unknowns
        act = free[N_BASE:]
        lo, hi = (jnp.broadcast_to(jnp.asarray(a, dt), (nu,))[act - N_BASE] for a in qdd_bounds)
        rows = qdd_map[act] / ACC_SCALE
        G = jnp.concatenate([G, rows, -rows])
        h = jnp.concatenate([h, hi / ACC_SCALE, -lo / ACC_SCALE])
        ineq_scale = jnp.concatenate([ineq_scale, jnp.full(2 * len(act), ACC_SCALE, dt)])

    Q = hessian_eps * jnp.eye(n, dtype=dt)
    if contact_slack_weight is not None:
        Q = Q.at[n_f:, n_f:].add(2.0 * jnp.asarray(contact_slack_weight, dt) * jnp.eye(N_SLACK, dtype=dt))
    q = jnp.zeros(n, dt)
    for task in tasks:
        rows, target = _task_rows(task, qdd_map, qdd_offset, force_map)
        rows, target, w = (jnp.asarray(a, dt) for a in (rows, target, task.weight))
        Q = Q + 2.0 * (rows.T * w) @ rows
        q = q - 2.0 * rows.T @ (w * target)
    return QP(Q, q, A, b, G, h, qdd_map, qdd_offset, force_map, tau_map, tau_offset, eq_scale, ineq_scale)


def export_qp(qp: QP) -> dict[str, np.ndarray]:
    """``{P, q, A, b, G, h}`` as float64 NumPy arrays, qpsolvers' names (``min 1/2 x'Px + q'x``), for a
    reference solver, e.g. ``qpsolvers.solve_qp(**export_qp(qp), solver="proxsuite")``."""
    return dict(P=np.asarray(qp.Q, np.float64), q=np.asarray(qp.q, np.float64), A=np.asarray(qp.A, np.float64),
                b=np.asarray(qp.b, np.float64), G=np.asarray(qp.G, np.float64), h=np.asarray(qp.h, np.float64))
