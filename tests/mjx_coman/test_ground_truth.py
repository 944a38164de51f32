"""Tests of mjx_coman.ground_truth: the verdict on synthetic touchdown logs, and the truth of a real walk."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from mjx_coman import ground_truth as gt
from mjx_coman import load_model
from mjx_coman.kinematics import FOOT_POINT_OFFSET_M

JUDGE = gt.Judge()


def _log(times, feet, com_xy, yaw=0.0, n=40):
    """A touchdown log from lists (NaN-padded to n rows)."""
    k = len(times)
    pad = lambda a, shape, fill=np.nan: np.concatenate([np.asarray(a, float).reshape(k, *shape),  # noqa: E731
                                                       np.full((n - k, *shape), fill)])
    com = np.concatenate([np.asarray(com_xy, float), np.full((k, 1), 0.5)], axis=1)
    return gt.Touchdowns(count=jnp.asarray(k, jnp.int32), time_s=jnp.asarray(pad(times, ())),
                         foot=jnp.asarray(pad(feet, (), -1).astype(np.int32)), com_m=jnp.asarray(pad(com, (3,))),
                         foot_m=jnp.asarray(pad(np.zeros((k, 3)), (3,))), other_foot_m=jnp.asarray(pad(np.zeros((k, 3)), (3,))),
                         pelvis_m=jnp.asarray(pad(np.zeros((k, 3)), (3,))), yaw_rad=jnp.asarray(pad(np.full(k, yaw), ())))


def _gait(velocities, sway=0.02, T=0.4, yaw=0.0):
    """A walk whose k-th step moves the CoM by velocities[k] T forward (heading frame) and sways at +-sway m/s laterally."""
    times, feet, com = [0.4], [0], [[0.0, 0.0]]
    c, s = np.cos(yaw), np.sin(yaw)
    for k, v in enumerate(velocities):
        foot = (k + 1) % 2  # left, right, left, ...
        lat = sway if foot == 0 else -sway
        x, y = com[-1]
        com.append([x + (c * v - s * lat) * T, y + (s * v + c * lat) * T])
        times.append(times[-1] + T)
        feet.append(foot)
    return _log(times, feet, com, yaw)


def test_step_velocities_are_heading_frame_and_mirrored():
    log = _gait([0.1] * 6, yaw=0.7)
    v = np.asarray(gt.step_velocities(log))
    assert np.all(np.isnan(v[0])) and np.all(np.isnan(v[7:]))
    np.testing.assert_allclose(v[1:7, 0], 0.1, atol=1e-6)
    np.testing.assert_allclose(v[1:7, 1], 0.02, atol=1e-6)  # +-0.02 m/s, mirrored to one sign


def test_a_walk_that_settles_counts_the_touchdowns_after_the_push():
    # steady at 0.07, pushed during the step ending at touchdown 4 (t = 2.0 s), back within 5 cm/s at touchdown 7
    v = [0.07] * 3 + [0.4, 0.25, 0.15, 0.1, 0.09] + [0.07] * 6
    log = _gait(v)
    out = gt.verdict(log, push_end_s=1.9, pushed=True, fell=False, judge=JUDGE)
    # touchdowns after the push: 4 (2.0 s) ... ; step velocity within 0.05 of the final 0.07 from touchdown 7 on
    assert int(out.steps_to_recover) == 4
    np.testing.assert_allclose(out.cycle_velocity_mps, [0.07, 0.02], atol=1e-6)
    assert float(out.mean_speed_mps) == pytest.approx(np.mean(v[7:]), abs=1e-6)  # touchdowns 7 to 14


@pytest.mark.parametrize("velocities, pushed, fell, expected", [
    ([0.07] * 10, False, False, 0),  # unpushed
    ([0.07] * 10, False, True, -1),  # unpushed but fell
    ([0.07] * 3 + [0.4] * 3 + [0.07] * 6, True, True, -1),  # fell
    ([0.07] * 3 + [0.4, 0.3, 0.2, 0.1, 0.07], True, False, -1),  # still moving when the walk ends: too soon
    ([0.07] * 3 + [0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6], True, False, -1),  # never settles
])
def test_the_verdict_of_walks_that_did_not_recover(velocities, pushed, fell, expected):
    out = gt.verdict(_gait(velocities), push_end_s=1.9, pushed=pushed, fell=fell, judge=JUDGE)
    assert int(out.steps_to_recover) == expected


def test_judge_rejects_bad_thresholds():
    for kw in (dict(contact_n=0.0), dict(min_air_s=float("nan")), dict(confirm_steps=0), dict(cycle_steps=1.5)):
        with pytest.raises(ValueError, match=next(iter(kw))):
            gt.Judge(**kw).validate()


def test_com_and_foot_points_are_mujocos():
    """The CoM the judge reads from mjx.Data equals MuJoCo C's ``subtree_com`` of the world body (the
    mass-weighted body CoMs), and its foot points are the foot bodies' origins moved by the foot-point offset."""
    from mujoco import mjx

    m = load_model()
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    d.qpos[7:] = rng.uniform(-0.3, 0.3, m.nq - 7)
    d.qpos[:3] = (0.1, -0.2, 0.6)
    mujoco.mj_forward(m, d)
    mx = mjx.put_model(m)
    dx = jax.jit(lambda q: mjx.com_pos(mx, mjx.kinematics(mx, mjx.make_data(mx).replace(qpos=q))))(d.qpos)
    np.testing.assert_allclose(np.asarray(gt.com_m(dx)), d.subtree_com[0], atol=1e-5)
    np.testing.assert_allclose(d.subtree_com[0], (m.body_mass[:, None] * d.xipos).sum(0) / m.body_mass.sum(),
                               atol=1e-9)
    for j, body in enumerate(("LFoot", "RFoot")):
        np.testing.assert_allclose(np.asarray(gt.foot_points_world(dx))[j],
                                   d.body(body).xpos + d.body(body).xmat.reshape(3, 3) @ np.asarray(FOOT_POINT_OFFSET_M),
                                   atol=1e-5)
    assert float(gt.tilt_rad(dx)) == pytest.approx(np.arccos(d.body("Waist").xmat[8]), abs=1e-5)


def test_touchdowns_of_a_real_walk_follow_the_controllers_clock(family_walks):
    """Ground truth and the controller agree: after the start-up phase the feet land every T = 0.4 s,
    alternating, within 0.1 s of the time-projection controller's phase changes."""
    rows, res = family_walks("time-projection")[:2]
    i = next(i for i, (n, p, _, d) in enumerate(rows) if n == "time-projection" and p is None and d == 0.0)
    log = jax.tree_util.tree_map(lambda x: x[i], res.log)
    k = int(log.count)
    t, foot = np.asarray(log.time_s[:k]), np.asarray(log.foot[:k])
    walking = t > 0.6
    ends = 0.4 * np.arange(2, 7)  # walking step j ends at (j + 2) T
    for end, side in zip(ends, [0, 1, 0, 1, 0]):  # step 0 swings the left foot
        near = walking & (np.abs(t - end) < 0.1)
        assert near.sum() == 1 and foot[near][0] == side, (end, t, foot)
    # every logged touchdown happened with that foot loaded by the walk's weight share
    assert np.all(np.isfinite(np.asarray(log.com_m[:k])))


def test_foot_loads_separate_stance_from_swing(family_walks):
    """The loads the judge thresholds are the feet's true normal forces: together they carry the weight in the
    start-up phase, and a swing foot carries less than ``contact_n`` in mid-swing while its stance foot carries it."""
    rows, res = family_walks("time-projection")[:2]
    i = next(i for i, (n, p, _, d) in enumerate(rows) if n == "time-projection" and p is None and d == 0.0)
    t = np.asarray(res.time_s[i])
    f = np.asarray(res.saved["readings"].foot_normal_force_n[i])  # (right, left): MJX contact forces, no noise
    startup = (t > 0.05) & (t < 0.3)
    weight = 283.4  # N, COMAN's 28.9 kg
    np.testing.assert_allclose(f[startup].sum(1), weight, rtol=0.15)
    mid_swing = np.abs(t - (0.4 + 0.8) / 2) < 0.05  # walking step 0: the left foot swings
    assert np.all(f[mid_swing, 1] < JUDGE.contact_n) and np.all(f[mid_swing, 0] > 200.0)
