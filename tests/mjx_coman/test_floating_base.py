"""The floating base from the sensors: the anchored soles give back the true base pose and velocity."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from mjx_coman import load_model
from mjx_coman.env import standing_posture
from mjx_coman.floating_base import estimate, sole_site_ids
from mjx_coman.sensors import Readings, quat_to_rpy


def _true_state(rng):
    """A crouched stance, perturbed, moving so that the mean sole velocity is zero (MuJoCo C)."""
    m, d = load_model(), None
    d = mujoco.MjData(m)
    q, root = standing_posture()
    d.qpos[:7], d.qpos[7:] = root, q + rng.normal(0, 0.02, q.shape)
    d.qpos[3:7] = [np.cos(0.05), 0.0, np.sin(0.05), 0.0]  # pitched 0.1 rad
    d.qvel[3:] = rng.normal(0, 0.3, m.nv - 3)
    mujoco.mj_forward(m, d)
    jac = np.zeros((3, m.nv))
    vel = []
    for s in sole_site_ids():
        mujoco.mj_jacSite(m, d, jac, None, int(s))
        vel.append(jac @ d.qvel)
    d.qvel[:3] -= np.mean(vel, axis=0)  # a translation moves every point alike
    mujoco.mj_forward(m, d)
    return m, d


def _readings(d):
    z = jnp.zeros(6)
    quat = jnp.asarray(d.qpos[3:7])
    return Readings(jnp.asarray(d.qpos[7:]), jnp.asarray(d.qpos[7:]), jnp.asarray(d.qvel[6:]), quat, quat_to_rpy(quat),
                    jnp.asarray(d.qvel[3:6]), z, z, jnp.zeros(2), jnp.zeros(2, bool))


@pytest.mark.parametrize("seed", [0, 1])
def test_anchored_soles_give_the_true_base(seed):
    with jax.enable_x64(True):
        m, d = _true_state(np.random.default_rng(seed))
        ids = sole_site_ids()
        anchors = jnp.asarray(d.site_xpos[ids])
        est = jax.jit(estimate)(_readings(d), anchors, jnp.ones(2))
        np.testing.assert_allclose(np.asarray(est.qpos), d.qpos, atol=1e-9)
        np.testing.assert_allclose(np.asarray(est.qvel), d.qvel, atol=1e-9)
        np.testing.assert_allclose(np.asarray(est.data.subtree_com[1]), d.subtree_com[1], atol=1e-9)
        # one foot only: the base follows that foot's anchor (the other sole is wherever the joints put it)
        shifted = anchors.at[1].add(jnp.array([0.05, 0.0, 0.0]))
        one = jax.jit(estimate)(_readings(d), shifted, jnp.array([1.0, 0.0]))
        np.testing.assert_allclose(np.asarray(one.qpos[:3]), d.qpos[:3], atol=1e-9)
