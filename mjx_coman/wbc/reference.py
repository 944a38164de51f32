"""Reference plants from MuJoCo's C functions, and random feasible standing states (NumPy, host side).

For tests and benchmarks of the whole-body QP, independent of the JAX dynamics: ``M`` from
``mj_fullM``, ``h`` from ``qfrc_bias``, Jacobians from ``mj_jac`` / ``mj_jacSite`` / ``mj_jacSubtreeCom``,
the centroidal momentum matrix summed over bodies from ``mj_jacBodyCom`` and the inertias, and every
``Jdot qdot`` as the central difference ``(J(q+) - J(q-)) qdot / 2 dt`` along
``q(+-dt) = mj_integratePos(q, +-qdot dt)`` (error O(dt^2), ~1e-9 at dt = 1e-5 s for the speeds used).
"""

from __future__ import annotations

import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_coman.wbc import tasks as T
from mjx_coman.wbc.plant import Plant

FOOT_BODIES = ("RFoot", "LFoot")
SOLE_SITES = ("r_sole", "l_sole")
CORNERS_LOCAL_M = np.array([[0.12, 0.04, -0.09], [0.12, -0.04, -0.09],
                            [-0.06, 0.04, -0.09], [-0.06, -0.04, -0.09]])  # lowest points of the spheres
FD_STEP_S = 1e-5


def _ids(m):
    body = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)  # noqa: E731
    site = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n)  # noqa: E731
    return dict(feet=[body(n) for n in FOOT_BODIES], soles=[site(n) for n in SOLE_SITES],
                torso=site("torso"), pelvis=site("pelvis"))


def _site_jac(m, d, site):
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jp, jr, site)
    return np.concatenate([jp, jr])


def _kinematic_terms(m, d, ids):
    """Every Jacobian of the plant at ``d.qpos`` (kinematics and CoM already computed)."""
    nv = m.nv
    out = {}
    cj, cp = np.zeros((2, 4, 3, nv)), np.zeros((2, 4, 3))
    for i, b in enumerate(ids["feet"]):
        for c, local in enumerate(CORNERS_LOCAL_M):
            p = d.xpos[b] + d.xmat[b].reshape(3, 3) @ local
            jr = np.zeros((3, nv))
            mujoco.mj_jac(m, d, cj[i, c], jr, p, b)
            cp[i, c] = p
    out.update(contact_jac=cj, contact_pos=cp)
    out["sole_jac"] = np.stack([_site_jac(m, d, s) for s in ids["soles"]])
    out["sole_rot"] = np.stack([d.site_xmat[s].reshape(3, 3) for s in ids["soles"]])
    for name in ("torso", "pelvis"):
        out[f"{name}_jac"] = _site_jac(m, d, ids[name])
        out[f"{name}_rot"] = d.site_xmat[ids[name]].reshape(3, 3).copy()
    jc = np.zeros((3, nv))
    mujoco.mj_jacSubtreeCom(m, d, jc, 1)
    out["com_jac"], out["com"] = jc, d.subtree_com[1].copy()
    # centroidal momentum matrix: sum over bodies of [m_b J_b; I_b J_w,b + m_b (c_b - c) x J_b]
    cmm = np.zeros((6, nv))
    for b in range(1, m.nbody):
        jp, jr = np.zeros((3, nv)), np.zeros((3, nv))
        mujoco.mj_jacBodyCom(m, d, jp, jr, b)
        rot = d.ximat[b].reshape(3, 3)
        inertia = rot @ np.diag(m.body_inertia[b]) @ rot.T
        r = d.xipos[b] - out["com"]
        cmm[:3] += m.body_mass[b] * jp
        cmm[3:] += inertia @ jr + m.body_mass[b] * np.cross(r, jp.T).T
    out["cmm"] = cmm
    return out


JAC_BIAS = dict(contact_jac="contact_bias_acc", sole_jac="sole_bias_acc", torso_jac="torso_bias_acc",
                pelvis_jac="pelvis_bias_acc", com_jac="com_bias_acc", cmm="cmm_bias")


def plant_at(model: mujoco.MjModel, qpos, qvel) -> Plant:
    """The :class:`~mjx_coman.wbc.plant.Plant` of one state from MuJoCo's C functions (float64 NumPy)."""
    ids = _ids(model)
    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, d)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, d, mass)
    out = _kinematic_terms(model, d, ids)
    out.update(mass=mass, bias=d.qfrc_bias.copy(), passive=d.qfrc_passive.copy(), com_vel=out["com_jac"] @ qvel)
    jd = {}
    for sign in (1.0, -1.0):
        q = np.array(qpos, dtype=float)
        mujoco.mj_integratePos(model, q, np.asarray(qvel, float), sign * FD_STEP_S)
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        for k, v in _kinematic_terms(model, d, ids).items():
            if k in JAC_BIAS:
                jd[k] = jd.get(k, 0.0) + sign * v
    for k, name in JAC_BIAS.items():
        out[name] = jd[k] @ np.asarray(qvel, float) / (2 * FD_STEP_S)
    return Plant(**{f: np.asarray(out[f]) for f in Plant._fields})


def _flat_feet_rows(m, d, ids):
    """Residual (10,) and Jacobian (10, nv) of: each sole at z = 0 with its normal vertical."""
    res, rows = [], []
    for s in ids["soles"]:
        jac = _site_jac(m, d, s)
        z_axis = d.site_xmat[s].reshape(3, 3)[:, 2]
        tilt = np.cross(z_axis, [0.0, 0.0, 1.0])  # rotation (world) that makes the normal vertical
        res += [-d.site_xpos[s][2], tilt[0], tilt[1]]
        rows += [jac[2], jac[3], jac[4]]
    return np.array(res), np.array(rows)


def standing_state(model: mujoco.MjModel, rng: np.random.Generator, joint_noise_rad: float = 0.05,
                   speed_scale: float = 0.1):
    """``(qpos, qvel)``: the standing posture with random joint offsets (uniform, +-``joint_noise_rad``),
    base and leg joints then corrected (Gauss-Newton, minimum norm) so that both soles lie flat on the floor,
    and random velocities (normal, ``speed_scale`` rad/s or m/s) projected so that the soles do not move.

    Raises:
        ValueError: the feet could not be put flat (residual above 1e-10).
    """
    from mjx_coman.env import standing_posture

    q_ref, root = standing_posture()
    d = mujoco.MjData(model)
    ids = _ids(model)
    qpos = np.concatenate([root, q_ref + rng.uniform(-joint_noise_rad, joint_noise_rad, q_ref.shape)])
    qpos[:2] += rng.uniform(-0.05, 0.05, 2)
    cols = np.arange(6 + 12)  # base and legs move to flatten the feet
    for _ in range(30):
        d.qpos[:] = qpos
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        res, rows = _flat_feet_rows(model, d, ids)
        if np.max(np.abs(res)) < 1e-12:
            break
        dq = np.zeros(model.nv)
        dq[cols] = np.linalg.lstsq(rows[:, cols], res, rcond=None)[0]
        mujoco.mj_integratePos(model, qpos, dq, 1.0)
    if np.max(np.abs(res)) > 1e-10:
        raise ValueError(f"feet not flat after Gauss-Newton: residual {np.max(np.abs(res))}")
    feet = np.concatenate([_site_jac(model, d, s) for s in ids["soles"]])
    qvel = rng.normal(0.0, speed_scale, model.nv)
    qvel -= np.linalg.pinv(feet) @ (feet @ qvel)
    return qpos, qvel


def standing_plants(model: mujoco.MjModel, n: int, seed: int = 0, **kw) -> list[tuple[np.ndarray, np.ndarray, Plant]]:
    """``n`` random standing states ``(qpos, qvel, plant)`` (see :func:`standing_state`)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        qpos, qvel = standing_state(model, rng, **kw)
        out.append((qpos, qvel, plant_at(model, qpos, qvel)))
    return out


def stack_plants(plants) -> Plant:
    """Stack unbatched plants on a leading axis."""
    return Plant(*(np.stack(x) for x in zip(*plants)))


def standing_tasks(plant: Plant, qpos, qvel, q_ref_rad, com_des_m, contact_mask=(1.0, 1.0), com_weight=10.0):
    """The soft tasks of a standing balance tick, as the tests and the benchmark use them (pure, JAX).

    CoM PD towards ``com_des_m`` (kp 30 /s^2, kd 11 /s, weight ``com_weight``), pelvis and torso upright
    (kp 100, kd 20, weight 1), swing feet held still (weight 10 each, off for a stance foot), joint posture
    towards ``q_ref_rad`` (kp 100, kd 20, weight 0.1) and small regularizations of qdd (1e-3) and forces
    (1e-5 /N^2, plus a force distribution 1e-5 /N^2).
    """
    qpos, qvel = jnp.asarray(qpos), jnp.asarray(qvel)
    nv = qvel.shape[0]
    up = jnp.eye(3, dtype=qvel.dtype)
    com_acc = T.position_pd(com_des_m, plant.com, 0.0, plant.com_vel, 30.0, 11.0)
    pelvis_acc = T.orientation_pd(up, plant.pelvis_rot, 0.0, plant.pelvis_jac[3:] @ qvel, 100.0, 20.0)
    torso_acc = T.orientation_pd(up, plant.torso_rot, 0.0, plant.torso_jac[3:] @ qvel, 100.0, 20.0)
    mask = jnp.asarray(contact_mask, qvel.dtype)
    feet = [T.foot_task(plant, i, -20.0 * (plant.sole_jac[i] @ qvel), 10.0 * (1.0 - mask[i])) for i in range(2)]
    return [T.com_task(plant, com_acc, com_weight),
            T.pelvis_orientation_task(plant, pelvis_acc, 1.0),
            T.torso_orientation_task(plant, torso_acc, 1.0),
            *feet,
            T.posture_task(qpos[7:], qvel[6:], q_ref_rad, 100.0, 20.0, 0.1),
            T.qdd_regularization(1e-3, nv),
            T.force_regularization(1e-5),
            T.force_distribution_task(plant.contact_pos, plant.com, 1e-5)]
