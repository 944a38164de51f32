"""Task builders, PD laws and the MuJoCo reference plant of the whole-body QP, against independent physics.

No QP is solved here (cheap): the orientation error against SciPy's rotation-vector map, the momentum-rate
task against the CoM dynamics (linear momentum = m v_com), the null-space task's projector property, and
the reference plant's ``J qacc + Jdot qdot`` against MuJoCo's own body accelerations (mj_rnePostConstraint,
mj_objectAcceleration) and its momentum against mj_subtreeVel.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mjx_coman
from mjx_coman import wbc
from mjx_coman.wbc import reference as ref


@pytest.fixture(scope="module", autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def model():
    return mjx_coman.load_model()


@pytest.fixture(scope="module")
def states(model):
    return ref.standing_plants(model, 3, seed=11, speed_scale=0.5)


def test_orientation_error_is_the_rotation_vector_of_r_des_r_transpose():
    rng = np.random.default_rng(0)
    angles = np.concatenate([[1e-9, 1e-5, 0.3], rng.uniform(0.0, 3.1, 20)])
    for ang in angles:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        rot = Rotation.random(random_state=rng)
        rot_des = Rotation.from_rotvec(ang * axis) * rot
        got = np.asarray(wbc.orientation_error(jnp.asarray(rot_des.as_matrix()), jnp.asarray(rot.as_matrix())))
        np.testing.assert_allclose(got, ang * axis, rtol=1e-7, atol=1e-12)


def test_orientation_error_is_smooth_at_zero():
    """Its Jacobian in the rotation vector at zero error is the identity (no NaN from the log map)."""
    rot = jnp.asarray(Rotation.from_rotvec([0.2, -0.4, 0.1]).as_matrix())

    def err(v):
        th = jnp.sqrt(jnp.sum(v * v) + 1e-300)
        k = wbc.contacts.skew(v / th)
        r = jnp.eye(3) + jnp.sin(th) * k + (1 - jnp.cos(th)) * k @ k  # Rodrigues
        return wbc.orientation_error(r @ rot, rot)

    jac = jax.jacfwd(err)(jnp.array([1e-9, 0.0, 0.0]))
    np.testing.assert_allclose(np.asarray(jac), np.eye(3), atol=1e-6)
    assert np.isfinite(np.asarray(jax.grad(lambda r: wbc.orientation_error(r, rot).sum())(rot))).all()


def test_momentum_rate_task_in_x_y_is_the_com_task_times_the_mass(states):
    """Seed 004 eq. 8 with linear momentum ``m v_com``: rows ``m J_com[:2]``, target ``m (a - Jdot qdot)``."""
    _, _, p = states[0]
    mass = p.mass[0, 0]
    a = np.array([0.3, -0.2, 0.5])
    mom = wbc.momentum_rate_task(p.cmm, p.cmm_bias, np.concatenate([mass * a, np.zeros(3)]), 2.0)
    com = wbc.com_task(p, a, 2.0)
    np.testing.assert_allclose(mom.qdd_jac, mass * com.qdd_jac[:2], atol=1e-10)
    np.testing.assert_allclose(mom.target, mass * com.target[:2], atol=1e-6)
    assert mom.qdd_jac.shape == (2, 29) and np.all(mom.weight == 2.0)


def test_null_space_task_acts_only_outside_the_task_jacobian(states):
    _, _, p = states[0]
    jac = np.concatenate([p.com_jac, p.pelvis_jac[3:], p.sole_jac.reshape(12, -1)])
    t = wbc.null_space_task(jac, np.ones(29), 1.0)
    proj = np.asarray(t.qdd_jac)
    np.testing.assert_allclose(proj @ jac.T, 0.0, atol=1e-10)
    np.testing.assert_allclose(proj @ proj, proj, atol=1e-10)
    assert np.linalg.matrix_rank(proj, tol=1e-8) == 29 - np.linalg.matrix_rank(jac)


def test_reference_plant_accelerations_match_mujoco_rne(model, states):
    """``J qacc + Jdot qdot`` (finite-difference Jdot) of the sole, pelvis and torso sites for a random
    ``qacc`` equals MuJoCo's site acceleration from ``cacc``; the momentum ``A qdot`` equals mj_subtreeVel's."""
    rng = np.random.default_rng(5)
    sites = {n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n) for n in ("r_sole", "l_sole", "pelvis", "torso")}
    d = mujoco.MjData(model)
    for qpos, qvel, p in states:
        assert np.max(np.abs(p.sole_jac.reshape(12, -1) @ qvel)) < 1e-12  # feet still
        assert np.max(np.abs(p.contact_pos[..., 2])) < 1e-10  # corners on the floor
        qacc = rng.normal(0.0, 1.0, model.nv)
        d.qpos[:], d.qvel[:] = qpos, qvel
        mujoco.mj_forward(model, d)
        d.qacc[:] = qacc
        mujoco.mj_rnePostConstraint(model, d)
        ours = {"r_sole": (p.sole_jac[0], p.sole_bias_acc[0]), "l_sole": (p.sole_jac[1], p.sole_bias_acc[1]),
                "pelvis": (p.pelvis_jac, p.pelvis_bias_acc), "torso": (p.torso_jac, p.torso_bias_acc)}
        for name, (jac, bias) in ours.items():
            acc = np.zeros(6)
            mujoco.mj_objectAcceleration(model, d, mujoco.mjtObj.mjOBJ_SITE, sites[name], acc, 0)
            mine = jac @ qacc + bias
            np.testing.assert_allclose(mine[3:], acc[:3], atol=1e-6, err_msg=name)  # angular
            # MuJoCo's RNE starts from the world accelerating at -gravity
            np.testing.assert_allclose(mine[:3], acc[3:] + model.opt.gravity, atol=1e-6, err_msg=name)  # linear
        assert np.max(np.abs(p.sole_bias_acc)) > 1e-3  # the velocities are not trivial
        mujoco.mj_subtreeVel(model, d)
        mass = model.body_subtreemass[1]
        np.testing.assert_allclose(p.cmm @ qvel, np.concatenate([mass * d.subtree_linvel[1], d.subtree_angmom[1]]),
                                   atol=1e-10)
        np.testing.assert_allclose(p.com_jac @ qvel, d.subtree_linvel[1], atol=1e-12)


def test_null_space_task_stays_finite_and_exact_at_a_straight_knee(model, states):
    """Seed 004 eq. 10 at the singularity it is used at: both knees at 0 rad (straight), the task Jacobian of
    straight-leg (x-y momentum, pelvis orientation, a swing foot). The SVD pseudo-inverse with its cut-off keeps
    the projector finite, idempotent and orthogonal to every task row."""
    qpos, qvel, _ = states[0]
    qpos = qpos.copy()
    for name in ("RKneeSag", "LKneeSag"):
        qpos[model.jnt_qposadr[model.joint(name).id]] = 0.0
    p = ref.plant_at(model, qpos, np.zeros_like(qvel))
    jac = np.concatenate([p.cmm[:2], p.pelvis_jac[3:], p.sole_jac[1]])
    t = wbc.null_space_task(jac, np.ones(29), 1.0)
    proj = np.asarray(t.qdd_jac)
    assert np.all(np.isfinite(proj)) and np.all(np.isfinite(np.asarray(t.target)))
    np.testing.assert_allclose(proj @ jac.T, 0.0, atol=1e-9)
    np.testing.assert_allclose(proj @ proj, proj, atol=1e-9)
    # the same in float32, as the rollouts run it
    t32 = wbc.null_space_task(jnp.asarray(jac, jnp.float32), jnp.ones(29, jnp.float32), 1.0)
    assert np.all(np.isfinite(np.asarray(t32.qdd_jac)))
    np.testing.assert_allclose(np.asarray(t32.qdd_jac) @ jac.T, 0.0, atol=1e-5 * np.abs(jac).max())  # float32 round-off
