"""The shared step clock (:mod:`mjx_coman.controllers.footstep_mpc.stepping`): held for a late touchdown."""

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman.controllers.footstep_mpc import stepping


def _run(cfg, contact_at_s, seconds):
    """Tick ``held_clock`` from the start; the foot that swung touches down ``contact_at_s`` after each step's
    scheduled end (inf: never). Returns per tick (time, step, t_in, delay, late)."""
    state = stepping.init_walk(cfg)
    out = []
    sched_end = None
    for i in range(int(round(seconds / cfg.dt_s))):
        t = jnp.float32(i * cfg.dt_s)
        k0, t0 = stepping.step_timing(cfg, t - state.delay_s)
        if int(k0) != int(state.step) and int(state.step) >= 0 and sched_end is None:
            sched_end = float(t)
        contact = sched_end is not None and float(t) - sched_end >= contact_at_s - 1e-4
        k, t_in, delay, late = stepping.held_clock(cfg, state, t, jnp.asarray(contact))
        if int(k) != int(state.step):
            sched_end = None
        state = state._replace(step=jnp.where(k >= 0, k, state.step), delay_s=delay, late_s=late)
        out.append((float(t), int(k), float(t_in), float(delay), float(late)))
    return np.array(out)


@pytest.fixture(scope="module")
def cfg():
    return controllers.default_config("straight-leg")


def test_a_late_touchdown_holds_the_clock_until_contact(cfg):
    T, t1 = cfg.step_time_s, cfg.start_s + cfg.step_time_s  # step 0 ends at t1
    r = _run(cfg, 0.03, t1 + 0.2)
    held = r[(r[:, 0] >= t1 - 1e-6) & (r[:, 1] == 0)]
    assert len(held) == 15 and held[:, 4].max() == pytest.approx(0.03, abs=1e-6)  # 15 ticks, 30 ms late
    assert np.all(np.abs(held[:, 2] - (T - cfg.dt_s)) < 1e-5)  # time in the step stays at its end
    after = r[r[:, 1] == 1]
    assert after[0, 0] == pytest.approx(t1 + 0.03, abs=1e-6) and after[0, 2] == pytest.approx(0.0, abs=1e-5)
    assert np.all(after[:, 3] == pytest.approx(0.03, abs=1e-6)) and np.all(after[:, 4] == 0.0)


def test_the_hold_ends_at_late_max_s_without_contact(cfg):
    t1 = cfg.start_s + cfg.step_time_s
    r = _run(cfg, np.inf, t1 + 0.3)
    first = r[r[:, 1] == 1][0]
    assert first[0] == pytest.approx(t1 + float(cfg.late_max_s), abs=1e-6)


def test_without_the_switch_the_clock_is_fixed(cfg):
    for c in (cfg.replace(late_touchdown_on=jnp.float32(0.0)), controllers.default_config("footstep-mpc")):
        t1 = c.start_s + c.step_time_s
        r = _run(c, np.inf, t1 + 0.05)
        assert r[r[:, 1] == 1][0, 0] == pytest.approx(t1, abs=1e-6) and np.all(r[:, 3] == 0.0)
