"""The derivative of a short footstep-mpc walk with respect to an MPC weight (seed 001, eq. 16), forward mode
through the planner, the whole-body QP and the physics, against central differences (slow: a compiled walk of
its own; ``python -m pytest -m slow``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman import rollout as ro

SECONDS = 0.9  # the start (0.6 s) and most of step 0
PROBE = "mpc_com_step_weight"
RTOL = 0.05


def _record(state):
    return state.telemetry.next_footstep_m


@pytest.mark.slow
def test_gradient_of_a_short_walk_wrt_an_mpc_weight_matches_central_differences():
    ctrl, cfg = controllers.load("footstep-mpc")
    env = ro.plant_env_params(ctrl.gait(cfg).plant)
    spec, save = ro.WalkSpec(seconds=SECONDS), ro.SaveAt(_record, every=10)
    joystick, key = controllers.joystick(0.2), jax.random.PRNGKey(0)
    w0 = float(getattr(cfg, PROBE))
    h = 0.01 * w0  # 1 % (at 5 % the two differed by 8 %)

    def cost(w):
        res = ro.walk(ctrl, cfg.replace(**{PROBE: w}), env, ro.no_push(), key, spec, joystick, save)
        late = res.time_s > cfg.start_s + 0.05  # the planned footsteps of step 0
        return jnp.sum(jnp.where(late[:, None], res.saved, 0.0)) / jnp.sum(late), res.fell

    one = lambda w: jax.jvp(cost, (w,), (jnp.ones_like(w),))  # noqa: E731
    (c, fell), (dc, _) = jax.jit(jax.vmap(one))(jnp.asarray([w0, w0 + h, w0 - h], cfg.com_ref_m.dtype))
    c, dc = np.asarray(c), np.asarray(dc)
    assert not np.any(np.asarray(fell))
    fd = (c[1] - c[2]) / (2 * h)
    assert np.isfinite(dc[0]) and abs(fd) > 1e-6, fd  # the weight moves the planned footsteps
    assert abs(dc[0] - fd) <= RTOL * abs(fd), (dc[0], fd)
