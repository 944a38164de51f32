"""Tests of mjx_coman.walking.rollout: walks of the simulated COMAN from the crouched stance.

The fast tests share one compiled, vmapped 2 s walk (module fixture); the
long ones (10 s walks, speeds, a 64-walk batch) are marked slow.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.env import batch_axes
from mjx_coman.walking import controller as ctl
from mjx_coman.walking import rollout as ro

SHORT_S = 2.4  # start-up phase + 5 walking phases (4 phase changes)
EST_TOL_M = 6e-3  # encoders (12 bit) + IMU noise against the simulator's truth
STANDING_PELVIS_M = 0.507
PUSH_NS = 5.0  # backward impulse that the open loop does not survive at this phase
PUSH_START_S = (1 + 1 + 0.375) * 0.4  # walking phase 1, 3/8 through


def _stack(items):
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *items)


@pytest.fixture(scope="module")
def env_params():
    return ro.walking_env_params()


@pytest.fixture(scope="module")
def short_walks(env_params):
    """Five 2.4 s walks in one vmap: closed/open loop unpushed, closed/open loop pushed, an absurd push."""
    closed = ctl.make_controller_params(env_params, 0.0)
    opened = ctl.make_controller_params(env_params, 0.0, footstep_gain=0.0)
    push = ro.make_push(PUSH_START_S, 0.1, impulse_ns=PUSH_NS, direction_rad=math.pi)
    absurd = ro.make_push(1.0, 0.05, force_n=[3e6, 0.0, 1e6])
    cps = _stack([closed, opened, closed, opened, closed])
    pushes = _stack([ro.no_push(), ro.no_push(), push, push, absurd])
    keys = jax.random.split(jax.random.PRNGKey(7), 5)
    spec = ro.WalkSpec(seconds=SHORT_S, record_every=10)
    res = ro.batched_walk(spec, None, 0)(env_params, cps, pushes, keys)
    return jax.tree_util.tree_map(np.asarray, res)


def _one(res, i):
    return jax.tree_util.tree_map(lambda x: x[i], res)


@pytest.mark.parametrize("i", [0, 1])
def test_unpushed_walks_step_in_place_without_falling(short_walks, i):
    r = _one(short_walks, i)
    assert not r.fell and not r.nan and r.fall_time_s == np.inf
    assert r.steps == 4 and r.steps_to_recover == 0
    assert r.pelvis_m[:, 2].min() > STANDING_PELVIS_M - 0.03  # no collapse
    assert np.abs(r.pelvis_m[-1, :2] - r.pelvis_m[0, :2]).max() < 0.15  # in place, within 15 cm
    feet = r.footsteps_m[:r.steps + 1]
    assert np.all(np.isfinite(feet)) and np.all(np.isnan(r.footsteps_m[r.steps + 1:]))
    # stance feet alternate right (phase 0), left, right, ...; about a step width apart
    np.testing.assert_array_equal(np.sign(feet[:, 1]), [-1, 1, -1, 1, -1])
    assert np.all(np.abs(np.diff(feet[:, 1])) > 0.1) and np.all(np.abs(np.diff(feet[:, 1])) < 0.2)
    np.testing.assert_allclose(feet[:, 2], 0.09, atol=0.015)  # foot points 9 cm above the floor: landed


def test_state_estimate_matches_the_simulator(short_walks):
    for i in (0, 1):
        tr = _one(short_walks, i).trace
        err = np.abs(tr.measured_rel_m - tr.true_rel_m)
        assert err.max() < EST_TOL_M, err.max(axis=0)


def test_closed_loop_recovers_a_push_the_open_loop_does_not(short_walks):
    closed, opened = _one(short_walks, 2), _one(short_walks, 3)
    assert not closed.fell
    assert opened.fell and PUSH_START_S < opened.fall_time_s <= SHORT_S
    assert closed.max_abs_footstep_adjustment_m > 0.03 and opened.max_abs_footstep_adjustment_m == 0.0
    # it steps backward: the pelvis ends behind where it was pushed
    assert closed.pelvis_m[-1, 0] < closed.pelvis_m[int(PUSH_START_S / 0.02), 0]


def test_a_blow_up_is_a_recorded_fall_and_stays_finite(short_walks):
    r = _one(short_walks, 4)
    assert r.fell and 1.0 < r.fall_time_s < 1.1 and r.steps_to_recover == -1
    for x in (r.pelvis_m, r.time_s, r.mean_speed_mps, r.max_abs_footstep_adjustment_m, *r.trace):
        assert np.all(np.isfinite(x))
    frozen = r.time_s > r.fall_time_s + 0.02
    assert np.all(r.pelvis_m[frozen] == r.pelvis_m[frozen][0])  # frozen at the last good state


@pytest.mark.parametrize("kwargs, name", [
    (dict(start_s=-1.0, force_n=[1.0, 0, 0]), "start_s"),
    (dict(start_s=1.0, duration_s=0.0, force_n=[1.0, 0, 0]), "duration_s"),
    (dict(start_s=1.0, impulse_ns=-2.0), "impulse_ns"),
    (dict(start_s=1.0, force_n=[1.0, 0.0]), "force_n"),
    (dict(start_s=1.0, force_n=[float("nan"), 0, 0]), "force_n"),
    (dict(start_s=1.0), "exactly one"),
])
def test_make_push_rejects_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ro.make_push(**kwargs)


def test_make_push_from_impulse():
    p = ro.make_push(2.0, 0.1, impulse_ns=4.0, direction_rad=math.pi / 2)
    np.testing.assert_allclose(p.force_n, [0.0, 40.0, 0.0], atol=1e-5)


@pytest.mark.parametrize("kwargs, name", [
    (dict(controller="closed-loop"), "controller"),
    (dict(seconds=0.0), "seconds"),
    (dict(record_every=0), "record_every"),
    (dict(speed_mps=1.0), "speed_mps"),
    (dict(max_tilt_rad=-1.0), "max_tilt_rad"),
])
def test_walk_spec_rejects_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ro.WalkSpec(**kwargs).validate()


def test_walk_rejects_a_step_time_other_than_the_controllers(env_params):
    cp = ctl.make_controller_params(env_params, 0.0)
    with pytest.raises(ValueError, match="step_time_s"):
        ro.walk(env_params, cp, ro.no_push(), ro.WalkSpec(step_time_s=0.5), jax.random.PRNGKey(0))


def test_walking_env_params_rejects_a_bad_gain():
    with pytest.raises(ValueError, match="ankle_roll_kp"):
        ro.walking_env_params(0.0)


# --- long runs -------------------------------------------------------------------------------------

@pytest.mark.slow
def test_ten_seconds_in_place_open_and_closed_loop(env_params):
    """Seed Figure 14: 10 s of in-place walking (25 phases) open and closed loop without falling."""
    cps = _stack([ctl.make_controller_params(env_params, 0.0),
                  ctl.make_controller_params(env_params, 0.0, footstep_gain=0.0)])
    spec = ro.WalkSpec(seconds=10.4, record_every=50)
    res = jax.tree_util.tree_map(np.asarray, ro.batched_walk(spec, None, 0)(
        env_params, cps, _stack([ro.no_push()] * 2), jax.random.split(jax.random.PRNGKey(1), 2)))
    assert not res.fell.any() and np.all(res.steps == 24)  # 25 walking phases after the start-up one
    assert np.all(np.abs(res.mean_speed_mps) < 0.1)  # in place it drifts forward at about 0.06 m/s


@pytest.mark.slow
@pytest.mark.parametrize("speed", [0.1, 0.2])
def test_walking_speed_within_a_quarter_of_the_command(env_params, speed):
    """Seed Figure 19: the same controller walks at the 3LP gait's speed."""
    cp = ctl.make_controller_params(env_params, speed)
    res = ro.jit_walk(env_params, cp, ro.no_push(), ro.WalkSpec(seconds=10.4, record_every=50),
                      jax.random.PRNGKey(2))
    assert not bool(res.fell)
    assert abs(float(res.mean_speed_mps) - speed) < 0.25 * speed


@pytest.mark.slow
def test_a_batch_of_64_pushed_walks_in_one_vmap(env_params):
    """64 walks over push phase, impulse and direction, and per-walk spring stiffness, in one vmap on the CPU."""
    import dataclasses

    n = 64
    rng = np.random.default_rng(0)
    phases, imps = rng.uniform(0, 1, n), rng.uniform(0, 6, n)
    dirs = rng.choice([0.0, math.pi], n)
    pushes = _stack([ro.make_push((2 + p) * 0.4, 0.1, impulse_ns=i, direction_rad=d)
                     for p, i, d in zip(phases, imps, dirs)])
    act = env_params.actuator
    k = act.spring_stiffness_nm_per_rad * rng.uniform(0.9, 1.1, (n, 1)).astype(np.float32)
    batched = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), act)
    batched = dataclasses.replace(batched, spring_stiffness_nm_per_rad=jnp.asarray(k))
    env_b = dataclasses.replace(env_params, actuator=batched,
                                sensor=jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))),
                                                              env_params.sensor))
    spec = ro.WalkSpec(seconds=3.2, record_every=50)
    res = jax.tree_util.tree_map(np.asarray, ro.batched_walk(spec, batch_axes(env_b))(
        env_b, ctl.make_controller_params(env_params, 0.0), pushes, jax.random.split(jax.random.PRNGKey(3), n)))
    assert res.fell.shape == (n,) and np.all(np.isfinite(res.pelvis_m))
    assert not res.fell[imps < 1.0].any()  # gentle pushes never topple it
