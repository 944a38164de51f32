"""Whole-body dynamics terms on ``mjx.Data`` for a whole-body QP (seed 001, eq. 1-2; seed 004, eq. 5).

Seed 001, eq. 1: ``M qacc + h = tau + J_C^T lambda``, ``xacc = J qacc + Jdot qvel``;
seed 004, eq. 5: the momentum rate ``A qacc + Adot qvel``. Here: ``M``, ``h``,
Jacobians of points, frames, sites and the CoM with their ``Jdot qvel``, the
centroidal momentum matrix ``A`` with ``Adot qvel``, and :func:`terms`, all of
them for COMAN's feet, soles, torso and pelvis in one call.

Conventions (MuJoCo's): ``qvel`` = (base linear velocity, world frame; base
angular velocity, base frame; 23 hinge rates); Jacobian rows in world axes,
linear first. ``data`` must have had ``mjx.kinematics`` and ``mjx.com_pos`` run
on its ``qpos``; velocity terms run ``mjx.com_vel`` on ``data.qvel`` themselves,
:func:`terms` once for all. After ``mjx.step`` those fields belong to the state
before the step: run :func:`prepare` first.

MJX functions used: ``mjx.kinematics``, ``mjx.com_pos``, ``mjx.com_vel`` (``cdof``,
``cdof_dot``, ``cvel``, ``cinert``, ``subtree_com``), ``mjx.crb`` + ``mjx.full_m``
(mass matrix, armature included), ``mjx.rne`` (``qfrc_bias``), ``mjx.passive``
(``qfrc_passive``). On top of them, with static tree tables (not the per-call
tree scan of ``mjx.support.jac``), ``c`` the robot CoM where MJX's com-based
vectors live:

* point Jacobian (``mj_jac``): column ``j`` = ``cdof_lin_j + cdof_ang_j x (p - c)``
  if dof ``j`` moves the body, else 0;
* body accelerations at ``qacc = 0``, no gravity: ``a_b = sum_{j moves b}
  cdof_dot_j qvel_j`` (Featherstone's ``v x S qdot`` recursion, summed). MJX's
  ``cdof_dot`` of the free joint's rotation takes the velocity before that
  rotation: not ``d/dt cdof``, but the same sum (``v x v = 0``), so the bias
  terms are the exact ``d/dt[J(q(t))] qvel`` along ``qacc = 0``;
* point acceleration ``a_p = a_lin + a_ang x (p - c) + w x v_p``;
* ``A``: column ``j`` = composite inertia of dof ``j``'s subtree times ``cdof_j``;
  ``Adot qvel = sum_b (I_b a_b + v_b x* I_b v_b)`` (Newton-Euler, no gravity).

The robot is the tree rooted at body 1 (:data:`ROOT_BODY`; 0 is the world).
Passive forces (springs, dampers) are not in :func:`bias_forces`: add
:func:`passive_forces` (zero for COMAN, computed all the same).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

ROOT_BODY = 1  # the robot's root body (Waist, free joint); body 0 is the world
FEET = ("r", "l")  # foot index 0 = right, 1 = left
CORNERS = ("upper_left", "upper_right", "lower_left", "lower_right")  # upper = toe side (+x)
SOLE_SITES = ("r_sole", "l_sole")
TORSO_SITE = "torso"
PELVIS_SITE = "pelvis"


# --- static tree tables and checks ---------------------------------------------------------------------


def _ancestors(model) -> np.ndarray:
    """(nbody, nbody) bool ``[b, a]``: body ``a`` is ``b`` or an ancestor of ``b`` (its transpose: subtrees)."""
    parent = np.asarray(model.body_parentid)
    anc = np.eye(model.nbody, dtype=bool)
    for b in range(1, model.nbody):
        a = b
        while a != 0:
            a = parent[a]
            anc[b, a] = True
    return anc


def _dof_mask(model) -> np.ndarray:
    """(nbody, nv) bool: dof ``j`` moves body ``b`` (its body is ``b`` or an ancestor of ``b``)."""
    return _ancestors(model)[:, np.asarray(model.dof_bodyid)]


def _robot_mask(model) -> np.ndarray:
    """(nbody,) bool: the body belongs to the tree rooted at :data:`ROOT_BODY`."""
    if model.nbody <= ROOT_BODY or model.body_parentid[ROOT_BODY] != 0:
        raise ValueError(f"model has no root body {ROOT_BODY} attached to the world (nbody={model.nbody})")
    return np.asarray(model.body_rootid) == ROOT_BODY


def _check_id(value, count: int, what: str):
    """Raise ``ValueError`` for a concrete id outside ``[0, count)`` (traced ids pass unchecked)."""
    if not isinstance(value, jax.core.Tracer):
        v = np.asarray(value)
        if v.ndim != 0 or not np.issubdtype(v.dtype, np.integer) or not 0 <= int(v) < count:
            raise ValueError(f"{what} must be an integer in [0, {count}), got {value!r}")


def _check_point(point, what: str) -> jax.Array:
    p = jnp.asarray(point)
    if p.shape != (3,):
        raise ValueError(f"{what} must have shape (3,), got shape {p.shape}")
    return p


def _name_id(model, obj, name: str) -> int:
    i = mjx.name2id(model, obj, name)
    if i < 0:
        raise ValueError(f"model has no {obj.name[6:].lower()} named {name!r}")
    return i


# --- state preparation, mass matrix, bias and passive forces --------------------------------------------


def prepare(model: mjx.Model, data: mjx.Data) -> mjx.Data:
    """Run what this module needs from ``data.qpos``/``data.qvel``: kinematics, (tendons,) com_pos, com_vel."""
    d = mjx.kinematics(model, data)
    if model.ntendon:
        d = mjx.tendon(model, d)
    d = mjx.com_pos(model, d)
    return mjx.com_vel(model, d)


def mass_matrix(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(nv, nv) joint-space inertia ``M(q)`` (seed 001, eq. 1), armature included; ``mjx.crb`` + ``mjx.full_m``.

    Needs ``mjx.kinematics`` and ``mjx.com_pos`` on ``data``.
    """
    return mjx.full_m(model, mjx.crb(model, data))


def bias_forces(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(nv,) ``h(q, qvel)``: Coriolis, centrifugal and gravity (seed 001, eq. 1; MuJoCo's ``qfrc_bias``).

    Passive forces are NOT included (see :func:`passive_forces`); ``M qacc + h -
    qfrc_passive = tau + J^T f``. Needs ``mjx.kinematics`` and ``mjx.com_pos``;
    runs ``mjx.com_vel`` and ``mjx.rne`` on ``data.qvel``.
    """
    return _bias(model, mjx.com_vel(model, data))


def _bias(model, dv) -> jax.Array:
    return mjx.rne(model, dv).qfrc_bias


def passive_forces(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(nv,) MuJoCo's ``qfrc_passive`` (joint springs and dampers, gravity compensation, fluid), ``mjx.passive``.

    Zero for COMAN (no stiffness, no damping), computed all the same. Needs
    ``mjx.kinematics`` and ``mjx.com_pos`` (and ``mjx.tendon`` for models with tendons).
    """
    return mjx.passive(model, data).qfrc_passive


# --- Jacobians -------------------------------------------------------------------------------------------


def _origin(model, data, body_id) -> jax.Array:
    """The point ``c`` the com-based vectors of the body's tree refer to (its root's subtree CoM)."""
    return data.subtree_com[jnp.asarray(model.body_rootid)[body_id]]


def _jac(model, data, body_id, point_world) -> jax.Array:
    """(6, nv) [jacp; jacr] of a world point attached to a body (``mj_jac``)."""
    mask = jnp.asarray(_dof_mask(model), data.cdof.dtype)[body_id]
    ang, lin = data.cdof[:, :3], data.cdof[:, 3:]
    jacp = lin + jnp.cross(ang, point_world - _origin(model, data, body_id))
    return jnp.concatenate([jacp.T, ang.T]) * mask


def point_jacobian(model: mjx.Model, data: mjx.Data, body_id, point_world) -> jax.Array:
    """(3, nv) linear-velocity Jacobian of a world point moving with ``body_id`` (``mj_jac``'s jacp).

    Needs ``mjx.kinematics`` and ``mjx.com_pos``. ``body_id`` may be traced.
    """
    return frame_jacobian(model, data, body_id, point_world)[:3]


def frame_jacobian(model: mjx.Model, data: mjx.Data, body_id, point_world) -> jax.Array:
    """(6, nv) Jacobian of a frame at a world point on ``body_id``: linear rows, then angular (``mj_jac``).

    Needs ``mjx.kinematics`` and ``mjx.com_pos``. ``body_id`` may be traced.
    """
    _check_id(body_id, model.nbody, "body_id")
    return _jac(model, data, body_id, _check_point(point_world, "point_world"))


def site_jacobian(model: mjx.Model, data: mjx.Data, site_id) -> jax.Array:
    """(6, nv) frame Jacobian of a site (``mj_jacSite``). Needs ``mjx.kinematics`` and ``mjx.com_pos``."""
    _check_id(site_id, model.nsite, "site_id")
    return _jac(model, data, jnp.asarray(model.site_bodyid)[site_id], data.site_xpos[site_id])


# --- bias accelerations Jdot qvel ------------------------------------------------------------------------


def _spatial_bias_acc(model, dv) -> jax.Array:
    """(nbody, 6) com-based body accelerations at ``qacc = 0``, no gravity: ``sum_j cdof_dot_j qvel_j``."""
    mask = jnp.asarray(_dof_mask(model), dv.cdof_dot.dtype)
    return mask @ (dv.cdof_dot * dv.qvel[:, None])


def _frame_acc(model, dv, cacc, body_id, point_world) -> jax.Array:
    """(6,) [point acceleration; angular acceleration] at ``qacc = 0``: ``a_lin + a_ang x r + w x v_p``."""
    r = point_world - _origin(model, dv, body_id)
    w, v = dv.cvel[body_id, :3], dv.cvel[body_id, 3:]
    alpha, a = cacc[body_id, :3], cacc[body_id, 3:]
    v_p = v + jnp.cross(w, r)
    return jnp.concatenate([a + jnp.cross(alpha, r) + jnp.cross(w, v_p), alpha])


def _local_to_world(data, body_id, point_local) -> jax.Array:
    return data.xpos[body_id] + data.xmat[body_id] @ point_local


def frame_bias_acc(model: mjx.Model, data: mjx.Data, body_id, point_local) -> jax.Array:
    """(6,) ``Jdot qvel`` of a frame on ``body_id`` at ``point_local`` (body coordinates): [linear; angular].

    Equals ``d/dt[J(q(t))] qvel`` along ``qacc = 0`` (seed 001, eq. 1). Needs
    ``mjx.kinematics`` and ``mjx.com_pos``; runs ``mjx.com_vel`` on ``data.qvel``.
    """
    _check_id(body_id, model.nbody, "body_id")
    p = _check_point(point_local, "point_local")
    dv = mjx.com_vel(model, data)
    return _frame_acc(model, dv, _spatial_bias_acc(model, dv), body_id, _local_to_world(dv, body_id, p))


def point_bias_acc(model: mjx.Model, data: mjx.Data, body_id, point_local) -> jax.Array:
    """(3,) ``Jdot qvel`` of a point fixed on ``body_id`` (body coordinates); see :func:`frame_bias_acc`."""
    return frame_bias_acc(model, data, body_id, point_local)[:3]


def site_bias_acc(model: mjx.Model, data: mjx.Data, site_id) -> jax.Array:
    """(6,) ``Jdot qvel`` of a site's frame; see :func:`frame_bias_acc`."""
    _check_id(site_id, model.nsite, "site_id")
    dv = mjx.com_vel(model, data)
    body = jnp.asarray(model.site_bodyid)[site_id]
    return _frame_acc(model, dv, _spatial_bias_acc(model, dv), body, dv.site_xpos[site_id])


# --- centre of mass and centroidal momentum --------------------------------------------------------------


def _inertia_times_motion(cinert, motion) -> jax.Array:
    """(..., 6) spatial force [ang; lin] of MuJoCo's 10-vector inertia (about ``c``) times a motion."""
    i = cinert[..., [[0, 3, 4], [3, 1, 5], [4, 5, 2]]]
    mpos, mass = cinert[..., 6:9], cinert[..., 9:10]
    w, v = motion[..., :3], motion[..., 3:]
    ang = jnp.einsum("...ij,...j->...i", i, w) + jnp.cross(mpos, v)
    return jnp.concatenate([ang, mass * v - jnp.cross(mpos, w)], -1)


def _robot_cinert(model, data) -> jax.Array:
    """(nbody, 10) body inertias about the robot CoM, zero outside the robot."""
    return data._impl.cinert * jnp.asarray(_robot_mask(model), data.cdof.dtype)[:, None]


def total_mass_kg(model: mjx.Model) -> jax.Array:
    """Robot mass (sum of ``body_mass`` over the tree of :data:`ROOT_BODY`; follows a replaced ``body_mass``)."""
    return jnp.sum(jnp.asarray(model.body_mass) * _robot_mask(model))


def centroidal_momentum_matrix(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(6, nv) ``A`` (seed 004, eq. 5) with ``A qvel = [m v_com; L_com]``, world axes, about the robot CoM.

    Column ``j`` is the composite inertia of the subtree of dof ``j``'s body
    times ``cdof_j``. Needs ``mjx.kinematics`` and ``mjx.com_pos``.
    """
    cinert = _robot_cinert(model, data)
    crb = jnp.asarray(_ancestors(model).T, cinert.dtype) @ cinert  # composite inertias of the subtrees
    h = _inertia_times_motion(crb[np.asarray(model.dof_bodyid)], data.cdof)  # (nv, 6) [ang; lin]
    return jnp.concatenate([h[:, 3:].T, h[:, :3].T])


def _centroidal_bias(model, dv, cacc) -> jax.Array:
    """(6,) ``Adot qvel = sum_b (I_b a_b + v_b x* I_b v_b)`` at ``qacc = 0``, no gravity; [lin; ang]."""
    cinert = _robot_cinert(model, dv)
    v = dv.cvel
    iv = _inertia_times_motion(cinert, v)
    f = _inertia_times_motion(cinert, cacc)
    f_ang = f[:, :3] + jnp.cross(v[:, :3], iv[:, :3]) + jnp.cross(v[:, 3:], iv[:, 3:])
    f_lin = f[:, 3:] + jnp.cross(v[:, :3], iv[:, 3:])
    return jnp.concatenate([f_lin.sum(0), f_ang.sum(0)])


def centroidal_momentum(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(6,) ``[m v_com; L_com]`` = ``A qvel``. Needs ``mjx.kinematics`` and ``mjx.com_pos``."""
    return centroidal_momentum_matrix(model, data) @ data.qvel


def centroidal_bias(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(6,) ``Adot qvel`` (seed 004, eq. 5: ``hdot = A qacc + Adot qvel``); [linear; angular about the CoM].

    Needs ``mjx.kinematics`` and ``mjx.com_pos``; runs ``mjx.com_vel`` on ``data.qvel``.
    """
    dv = mjx.com_vel(model, data)
    return _centroidal_bias(model, dv, _spatial_bias_acc(model, dv))


def com_position(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(3,) robot CoM (``subtree_com`` of :data:`ROOT_BODY`). Needs ``mjx.com_pos``."""
    _robot_mask(model)
    return data.subtree_com[ROOT_BODY]


def com_jacobian(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(3, nv) CoM Jacobian = linear rows of ``A`` over the mass (``mj_jacSubtreeCom`` of the root)."""
    return centroidal_momentum_matrix(model, data)[:3] / total_mass_kg(model)


def com_velocity(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(3,) CoM velocity ``J_com qvel``. Needs ``mjx.kinematics`` and ``mjx.com_pos``."""
    return com_jacobian(model, data) @ data.qvel


def com_bias_acc(model: mjx.Model, data: mjx.Data) -> jax.Array:
    """(3,) ``J_com_dot qvel`` (CoM acceleration at ``qacc = 0``); runs ``mjx.com_vel`` on ``data.qvel``."""
    return centroidal_bias(model, data)[:3] / total_mass_kg(model)


# --- COMAN's named frames and the bundle -----------------------------------------------------------------


def _contact_geom_ids(model) -> np.ndarray:
    """(2, 4) ids of the foot contact spheres ``{r,l}_foot_<corner>_contact``."""
    return np.array([[_name_id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{f}_foot_{c}_contact") for c in CORNERS]
                     for f in FEET])


def _lowest_points(centre_m, radius_m):
    """Lowest points of spheres in body coordinates: centre minus radius along the body z axis."""
    return centre_m - radius_m[..., None] * (np.arange(3) == 2)


def foot_contact_points_local(mj_model: mujoco.MjModel | None = None) -> dict:
    """Each foot's body and the lowest points of its 4 contact spheres, in foot-body coordinates.

    The lowest point of a sphere is its centre minus its radius along the body
    z axis (the sole plane when the foot is flat).

    Args:
        mj_model: the ``MjModel`` (default: the packaged COMAN model).

    Returns:
        dict with ``body_id`` (2,) int, ``geom_id`` (2, 4) int, ``points_local_m``
        (2, 4, 3) float; foot 0 = right, 1 = left; corners in :data:`CORNERS` order.
    """
    if mj_model is None:
        from mjx_coman import load_model

        mj_model = load_model()
    geoms = _contact_geom_ids(mj_model)
    pts = _lowest_points(np.asarray(mj_model.geom_pos)[geoms], np.asarray(mj_model.geom_size)[geoms, 0])
    return dict(body_id=np.asarray(mj_model.geom_bodyid)[geoms[:, 0]], geom_id=geoms, points_local_m=pts)


class WholeBody(NamedTuple):
    """Everything a whole-body QP needs at one state (world axes; Jacobian rows linear, then angular).

    Feet and soles: index 0 = right, 1 = left; contact corners in :data:`CORNERS`
    order. ``*_bias_acc`` are ``Jdot qvel``; ``bias`` excludes ``passive``.
    """

    mass: jax.Array  # (nv, nv)
    bias: jax.Array  # (nv,)
    passive: jax.Array  # (nv,)
    contact_jac: jax.Array  # (2, 4, 3, nv)
    contact_bias_acc: jax.Array  # (2, 4, 3)
    contact_pos: jax.Array  # (2, 4, 3)
    sole_jac: jax.Array  # (2, 6, nv)
    sole_bias_acc: jax.Array  # (2, 6)
    sole_pos: jax.Array  # (2, 3)
    sole_rot: jax.Array  # (2, 3, 3)
    torso_jac: jax.Array  # (6, nv)
    torso_bias_acc: jax.Array  # (6,)
    torso_pos: jax.Array  # (3,)
    torso_rot: jax.Array  # (3, 3)
    pelvis_jac: jax.Array  # (6, nv)
    pelvis_bias_acc: jax.Array  # (6,)
    pelvis_pos: jax.Array  # (3,)
    pelvis_rot: jax.Array  # (3, 3)
    com: jax.Array  # (3,)
    com_vel: jax.Array  # (3,)
    com_jac: jax.Array  # (3, nv)
    com_bias_acc: jax.Array  # (3,)
    cmm: jax.Array  # (6, nv)
    cmm_bias: jax.Array  # (6,)
    momentum: jax.Array  # (6,) cmm @ qvel = [m v_com; L_com]
    total_mass_kg: jax.Array  # ()

    @staticmethod
    def terms(model: mjx.Model, data: mjx.Data) -> "WholeBody":
        """Same as the module's :func:`terms`."""
        return terms(model, data)


def terms(model: mjx.Model, data: mjx.Data) -> WholeBody:
    """All :class:`WholeBody` terms in one pass (one ``com_vel``, ``crb``, ``rne``, ``passive``).

    Needs ``mjx.kinematics`` and ``mjx.com_pos`` on ``data`` (or run
    :func:`prepare`); uses ``data.qvel``.
    """
    dv = mjx.com_vel(model, data)
    cacc = _spatial_bias_acc(model, dv)

    def frame(body, p):  # (6, nv) Jacobian and (6,) Jdot qvel of a frame at the world point p on body
        return _jac(model, dv, body, p), _frame_acc(model, dv, cacc, body, p)

    geoms = _contact_geom_ids(model)
    feet = np.asarray(model.geom_bodyid)[geoms[:, 0]]
    local = _lowest_points(jnp.asarray(model.geom_pos)[geoms], jnp.asarray(model.geom_size)[geoms, 0])
    contact_pos = jnp.stack([jax.vmap(lambda p, b=b: _local_to_world(dv, b, p))(local[i]) for i, b in enumerate(feet)])
    contact = [jax.vmap(lambda p, b=b: frame(b, p))(contact_pos[i]) for i, b in enumerate(feet)]
    sites = np.array([_name_id(model, mujoco.mjtObj.mjOBJ_SITE, n) for n in (*SOLE_SITES, TORSO_SITE, PELVIS_SITE)])
    site_jac, site_acc = jax.vmap(frame)(jnp.asarray(model.site_bodyid[sites]), dv.site_xpos[sites])
    site_pos, site_rot = dv.site_xpos[sites], dv.site_xmat[sites]
    cmm, cmm_bias = centroidal_momentum_matrix(model, dv), _centroidal_bias(model, dv, cacc)
    mass_kg = total_mass_kg(model)
    return WholeBody(
        mass=mass_matrix(model, dv), bias=_bias(model, dv), passive=passive_forces(model, dv),
        contact_jac=jnp.stack([j[:, :3] for j, _ in contact]),
        contact_bias_acc=jnp.stack([a[:, :3] for _, a in contact]), contact_pos=contact_pos, sole_jac=site_jac[:2], sole_bias_acc=site_acc[:2], sole_pos=site_pos[:2],
        sole_rot=site_rot[:2], torso_jac=site_jac[2], torso_bias_acc=site_acc[2], torso_pos=site_pos[2],
        torso_rot=site_rot[2], pelvis_jac=site_jac[3], pelvis_bias_acc=site_acc[3], pelvis_pos=site_pos[3],
        pelvis_rot=site_rot[3], com=dv.subtree_com[ROOT_BODY], com_vel=cmm[:3] @ dv.qvel / mass_kg,
        com_jac=cmm[:3] / mass_kg, com_bias_acc=cmm_bias[:3] / mass_kg, cmm=cmm, cmm_bias=cmm_bias,
        momentum=cmm @ dv.qvel, total_mass_kg=mass_kg,
    )
