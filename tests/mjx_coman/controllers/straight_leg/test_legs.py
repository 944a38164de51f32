"""The leg state machine of seed 004 (Fig. 5) over a step, against the timing it is given."""

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman.controllers.straight_leg import legs as lg


@pytest.fixture(scope="module")
def cfg():
    return controllers.default_config("straight-leg")


def _run(cfg, steps=2):
    """Tick the machine through the start and ``steps`` steps; return (time, stance, modes, privileged knees)."""
    dt, T = 0.002, cfg.step_time_s
    legs = lg.init(cfg.knee_rad, jnp.float32)
    out, prev_k = [], -1
    n = int(round((cfg.start_s + steps * T) / dt))
    for i in range(n):
        t = i * dt
        rel = t - cfg.start_s
        k = -1 if rel < 0 else int(np.floor(rel / T + 1e-6))
        t_in = 0.0 if k < 0 else rel - k * T
        stance = 0 if k % 2 == 0 else 1
        legs = lg.update(legs, cfg, single=jnp.asarray(k >= 0), new=jnp.asarray(k >= 0 and k != prev_k),
                         stance=jnp.asarray(stance), t_in=jnp.asarray(t_in, jnp.float32),
                         time_s=jnp.asarray(t, jnp.float32), knee_rad=jnp.asarray([0.3, 0.3], jnp.float32))
        prev_k = k
        out.append((t, k, stance, t_in, np.asarray(legs.mode), np.asarray(lg.privileged_knee_rad(legs, cfg, t))))
    return out


def test_each_leg_goes_through_the_five_states_in_order(cfg):
    rows = _run(cfg)
    for t, k, stance, t_in, mode, knee in rows:
        if k < 0:
            assert set(mode) <= {lg.STRAIGHTEN, lg.STRAIGHT}  # the start: both legs straighten
            continue
        swing_t = t_in - cfg.transfer_s
        s, w = mode[stance], mode[1 - stance]
        e = 0.003  # a tick and a half: float32 clocks may switch a tick either side of a boundary
        if t_in < cfg.straighten_s - e:
            assert s == lg.STRAIGHTEN
        elif cfg.straighten_s + e < t_in and swing_t < cfg.collapse_fraction * cfg.swing_s - e:
            assert s == lg.STRAIGHT
        elif swing_t > cfg.collapse_fraction * cfg.swing_s + e:
            assert s == lg.COLLAPSE
        if swing_t < -e:
            assert w == lg.COLLAPSE  # through the transfer
        elif e < swing_t < cfg.extend_fraction * cfg.swing_s - e:
            assert w == lg.BENT
        elif swing_t > cfg.extend_fraction * cfg.swing_s + e:
            assert w == lg.EXTEND


def test_privileged_knee_of_each_state(cfg):
    rows = _run(cfg)
    by_mode = {}
    for t, k, stance, t_in, mode, knee in rows:
        for leg in (0, 1):
            by_mode.setdefault(int(mode[leg]), []).append(float(knee[leg]))
    assert np.allclose(by_mode[lg.STRAIGHT], float(cfg.straight_knee_rad))
    assert np.allclose(by_mode[lg.EXTEND], float(cfg.straight_knee_rad))
    assert np.allclose(by_mode[lg.BENT], float(cfg.bent_knee_rad))
    assert np.allclose(by_mode[lg.COLLAPSE], float(cfg.collapse_knee_rad))
    straighten = np.asarray(by_mode[lg.STRAIGHTEN])  # between the knee at touchdown (0.3) and straight
    lo, hi = sorted((float(cfg.straight_knee_rad), max(0.3, float(cfg.knee_rad))))
    assert np.all((straighten >= lo - 1e-6) & (straighten <= hi + 1e-6))


def test_straightening_is_linear_from_the_touchdown_knee(cfg):
    rows = _run(cfg, steps=1)
    td = next(i for i, r in enumerate(rows) if r[1] == 0)
    t0 = rows[td][0]
    for t, k, stance, t_in, mode, knee in rows[td:]:
        if mode[0] != lg.STRAIGHTEN:
            break
        s = min((t - t0) / float(cfg.straighten_s), 1.0)
        assert knee[0] == pytest.approx(0.3 + s * (float(cfg.straight_knee_rad) - 0.3), abs=1e-5)
