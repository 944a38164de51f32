"""Contact rows of the whole-body QP: stance accelerations (hard equalities) and friction pyramids.

Forces are one world-frame 3D force per sole corner (the lowest points of the four contact spheres,
2 feet x 4 corners): the model touches the floor at exactly these points, so the QP's forces are the
model's, and the centre of pressure of a foot, a convex combination of its corners with weights
``f_n,c / sum f_n`` when every corner's normal force is >= 0, lies inside the foot's support rectangle by
construction: unilateral corner forces replace explicit CoP rows (seed 001's "CoP inside feet polygon").

Per foot ``i`` with contact mask ``m_i`` (an array, 1 in stance, 0 lifted; single and double support have
the same static shapes) the six equality rows are

    m_i = 1:  J_sole,i qdd = -Jdot_sole,i qdot          (the sole does not accelerate: 6D, rank 6)
    m_i = 0:  sum_c f_c = 0,  sum_c (p_c - p_mean) x f_c = 0   (the foot's net wrench is zero)

and a lifted foot's forces are also masked out of the dynamics and of the inequality rows, so they
appear only in the zero-wrench rows and the (positive definite) force costs: the solution's lifted-foot
forces are zero. The 6D sole rows are used instead of the 12 corner rows ``J_c qdd + Jdot_c qdot = 0``
because those have rank 6 per flat foot, which would make the equality matrix rank deficient.

Toe-off (seed 004, sec. IV), per foot by ``toe_off`` (an array, 1 for a stance foot rolling onto its toe):
the foot stands on one point, the middle of its front edge. Its heel corners carry no force and its two front
corners one shared force (half each: the generalized force of a single force at their midpoint), by the
map from the QP's force variables to the corner forces (:func:`force_share`); its six rows become

    the toe point (the front corners' midpoint) does not accelerate (3 rows, world),
    roll and yaw of the sole do not accelerate (2 rows, sole frame), pitch is free (a zero row)

so a zero row stands in for the pitch: the stance rows must then carry slack (``contact_slack_weight``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from mjx_coman.wbc.plant import N_CORNERS, N_FEET, N_FORCES, Plant

TOE_CORNERS = (0, 1)  # the sole's front corners in mjx_coman.mjcf.FOOT_CORNERS; 2 and 3 are the heel
_HEEL = (0.0, 0.0, 1.0, 1.0)
MASKED_SLACK_N = 100.0  # right-hand side of a masked inequality row (0 <= this): keeps the slack away from 0


def skew(v) -> jax.Array:
    """``[v]x`` with ``[v]x w = v x w``."""
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack([jnp.stack([z, -v[..., 2], v[..., 1]], -1),
                      jnp.stack([v[..., 2], z, -v[..., 0]], -1),
                      jnp.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def force_corners(toe_off) -> jax.Array:
    """(2, 4): 1 for a corner whose force exists, 0 for a heel corner of a foot in toe-off."""
    return 1.0 - jnp.asarray(toe_off)[:, None] * jnp.asarray(_HEEL, jnp.asarray(toe_off).dtype)


def force_share(toe_off) -> jax.Array:
    """(24, 24): corner forces from the QP's force variables: the identity, except for a foot in toe-off, whose
    heel corners get none and whose second front corner repeats the first's (one force at the toe point)."""
    t = jnp.asarray(toe_off)
    exist = jnp.repeat(force_corners(t).reshape(-1), 3)
    share = jnp.diag(exist)
    for i in range(N_FEET):
        a, b = (i * N_CORNERS + TOE_CORNERS[0]) * 3, (i * N_CORNERS + TOE_CORNERS[1]) * 3
        for k in range(3):
            share = share.at[b + k, b + k].set(1.0 - t[i]).at[b + k, a + k].set(t[i])
    return share


def corner_mask(contact_mask, toe_off=None) -> jax.Array:
    """Per force component (24,): 1 where the component's corner touches (its foot's contact mask, heels of
    feet in toe-off excluded)."""
    m = jnp.asarray(contact_mask)[:, None] * jnp.ones(N_CORNERS, jnp.asarray(contact_mask).dtype)
    if toe_off is not None:
        m = m * force_corners(toe_off)
    return jnp.repeat(m.reshape(-1), 3)


def foot_wrench_rows(contact_pos) -> jax.Array:
    """(2, 6, 24): net force and moment about the corner centroid of each foot's own corner forces."""
    centre = jnp.mean(contact_pos, axis=1, keepdims=True)
    arm = skew(contact_pos - centre)  # (2, 4, 3, 3)
    eye = jnp.broadcast_to(jnp.eye(3), arm.shape)
    per_foot = jnp.concatenate([eye, arm], axis=-2)  # (2, 4, 6, 3)
    per_foot = jnp.moveaxis(per_foot, 2, 1).reshape(N_FEET, 6, N_CORNERS * 3)
    rows = jnp.zeros((N_FEET, 6, N_FORCES), per_foot.dtype)
    for i in range(N_FEET):
        rows = rows.at[i, :, i * N_CORNERS * 3:(i + 1) * N_CORNERS * 3].set(per_foot[i])
    return rows


def stance_rows(plant: Plant, toe_off=None):
    """``(rows (2, 6, nv), bias (2, 6))`` of each foot's stance accelerations ``rows qdd + bias``: the sole
    frame's, or for a foot in toe-off the toe point's (world) and the sole's roll and yaw (sole frame) with a
    zero pitch row (module docstring)."""
    rows, bias = plant.sole_jac, plant.sole_bias_acc
    if toe_off is None:
        return rows, bias
    dt = rows.dtype
    toe_jac = jnp.mean(plant.contact_jac[:, TOE_CORNERS, :, :], axis=1)  # (2, 3, nv)
    toe_bias = jnp.mean(plant.contact_bias_acc[:, TOE_CORNERS, :], axis=1)  # (2, 3)
    to_sole = jnp.swapaxes(plant.sole_rot, -1, -2)
    keep = jnp.asarray([1.0, 0.0, 1.0], dt)  # roll, pitch (free), yaw
    ang = keep[None, :, None] * (to_sole @ plant.sole_jac[:, 3:])
    ang_bias = keep * jnp.einsum("fij,fj->fi", to_sole, plant.sole_bias_acc[:, 3:])
    t = jnp.asarray(toe_off, dt)
    rows = (1.0 - t[:, None, None]) * rows + t[:, None, None] * jnp.concatenate([toe_jac, ang], axis=1)
    bias = (1.0 - t[:, None]) * bias + t[:, None] * jnp.concatenate([toe_bias, ang_bias], axis=1)
    return rows, bias


def contact_equalities(plant: Plant, contact_mask, toe_off=None):
    """``(rows_qdd (12, nv), rows_f (12, 24), rhs (12,))``: stance accelerations (:func:`stance_rows`) or
    zero wrench per foot.

    Units: m/s^2 and rad/s^2 for a stance foot's rows, N and N m for a lifted foot's.
    """
    m = jnp.asarray(contact_mask, plant.sole_jac.dtype)[:, None, None]
    jac, bias = stance_rows(plant, None if toe_off is None else jnp.asarray(toe_off) * jnp.asarray(contact_mask))
    rows_qdd = (m * jac).reshape(N_FEET * 6, -1)
    rows_f = ((1.0 - m) * foot_wrench_rows(plant.contact_pos)).reshape(N_FEET * 6, N_FORCES)
    rhs = (-m[..., 0] * bias).reshape(N_FEET * 6)
    return rows_qdd, rows_f, rhs


def check_n_faces(n_faces: int) -> None:
    """Raise ``ValueError`` for a friction pyramid of fewer than 4 faces."""
    if n_faces < 4:
        raise ValueError(f"n_faces must be >= 4, got {n_faces}")


def friction_rows(sole_rot, contact_mask, friction_coeff, min_normal_force_n, n_faces: int = 4, toe_off=None):
    """``(rows (p, 24), rhs (p,))`` of ``rows f <= rhs``: inscribed friction pyramids and unilateral force.

    Per corner, with the sole's tangents ``t1, t2`` and normal ``n`` (columns of ``sole_rot``), ``n_faces``
    faces ``(cos phi_k t1 + sin phi_k t2) . f <= mu cos(pi / n_faces) n . f`` (a regular pyramid whose
    edges lie on the cone ``|f_t| = mu f_n``: inscribed; for 4 faces ``|f_t1|, |f_t2| <= mu / sqrt 2 f_n``)
    and ``n . f >= f_min``. Rows are per foot, corner, face (then the normal row); units N. A lifted foot's
    rows, and a toe-off foot's heel rows, are zero with right-hand side :data:`MASKED_SLACK_N`.
    """
    check_n_faces(n_faces)
    phi = 2.0 * math.pi * jnp.arange(n_faces) / n_faces
    t1, t2, n = sole_rot[..., :, 0], sole_rot[..., :, 1], sole_rot[..., :, 2]  # (2, 3)
    mu = jnp.asarray(friction_coeff, sole_rot.dtype) * math.cos(math.pi / n_faces)
    faces = (jnp.cos(phi)[None, :, None] * t1[:, None] + jnp.sin(phi)[None, :, None] * t2[:, None]
             - mu * n[:, None])  # (2, K, 3)
    per_corner = jnp.concatenate([faces, -n[:, None]], axis=1)  # (2, K + 1, 3)
    k = n_faces + 1
    rows = jnp.zeros((N_FEET, N_CORNERS, k, N_FORCES), sole_rot.dtype)
    for i in range(N_FEET):
        for c in range(N_CORNERS):
            col = (i * N_CORNERS + c) * 3
            rows = rows.at[i, c, :, col:col + 3].set(per_corner[i])
    fmin = jnp.broadcast_to(jnp.asarray(min_normal_force_n, sole_rot.dtype), (N_FEET, N_CORNERS))
    rhs = jnp.concatenate([jnp.zeros((N_FEET, N_CORNERS, n_faces), sole_rot.dtype), -fmin[..., None]], axis=-1)
    m = corner_mask(jnp.asarray(contact_mask, sole_rot.dtype), toe_off).reshape(N_FEET, N_CORNERS, 3)[..., :1]
    rhs = m * rhs + (1.0 - m) * MASKED_SLACK_N
    rows = m[..., None] * rows
    return rows.reshape(N_FEET * N_CORNERS * k, N_FORCES), rhs.reshape(N_FEET * N_CORNERS * k)
