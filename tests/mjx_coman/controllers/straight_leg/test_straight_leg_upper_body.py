"""straight-leg with the upper body in the QP (``fixed_upper_body=false``): the chest orientation task of seed
004 eq. 5 keeps the torso upright while it walks (slow: a compiled walk of its own; ``python -m pytest -m slow``)."""

from __future__ import annotations

import jax
import mujoco
import numpy as np
import pytest

import mjx_coman
from mjx_coman import controllers
from mjx_coman import rollout as ro

TORSO = mujoco.mj_name2id(mjx_coman.load_model(), mujoco.mjtObj.mjOBJ_BODY, "DWYTorso")


def _record(state):
    d = state.env.data
    return dict(torso_up=d.xmat[TORSO].reshape(3, 3)[:, 2], waist=d.qpos[7 + 12:7 + 15])


@pytest.mark.slow
def test_free_upper_body_walks_with_the_chest_upright_and_the_chest_weight_acts():
    ctrl, cfg = controllers.load("straight-leg", {"fixed_upper_body": False})
    env = ro.plant_env_params(ctrl.gait(cfg).plant)
    fn = ro.batched_walk(ctrl, ro.WalkSpec(seconds=4.0), ro.SaveAt(_record, every=10), config_axes=0)
    two = lambda *a: jax.numpy.stack(a)  # noqa: E731
    cfgs = jax.tree_util.tree_map(two, cfg, cfg.replace(chest_weight=0.0 * cfg.chest_weight))
    key = jax.random.PRNGKey(0)
    res = fn(cfgs, env, jax.tree_util.tree_map(two, ro.no_push(), ro.no_push()), two(key, key),
             controllers.joystick(0.15))
    res = jax.tree_util.tree_map(np.asarray, res)
    assert not res.fell.any()
    tilt = np.degrees(np.arccos(np.clip(res.saved["torso_up"][..., 2], -1, 1)))  # (2, records)
    assert tilt[0].max() < 3.0, tilt[0].max()
    assert tilt[0].mean() < tilt[1].mean(), (tilt[0].mean(), tilt[1].mean())  # the chest task is what holds it
