"""Tests of mjx_coman.rollout: walks of the simulated COMAN under a controller, judged on ground truth.

The walks come from the shared family batch (``family_walks`` in conftest: 2.4 s, one compilation
per family); the long ones (10 s walks, speeds, a 64-walk batch) are marked slow.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman import rollout as ro
from mjx_coman.env import batch_axes

STANDING_PELVIS_M = 0.507


def _one(res, i):
    return jax.tree_util.tree_map(lambda x: x[i], res)


def _row(rows, name, pushed: bool, delta=0.0):
    return next(i for i, (n, p, _, d) in enumerate(rows) if n == name and (p is not None) == pushed and d == delta)


@pytest.fixture(scope="module")
def tp(family_walks):
    return family_walks("time-projection")


@pytest.mark.parametrize("name", ["time-projection", "open-loop"])
def test_unpushed_walks_step_in_place_without_falling(tp, name):
    rows, res = tp[0], tp[1]
    r = _one(res, _row(rows, name, False))
    assert not r.fell and not r.nan and r.fall_time_s == np.inf and r.steps_to_recover == 0
    pel = r.saved["pelvis_m"]
    assert pel[:, 2].min() > STANDING_PELVIS_M - 0.03  # no collapse
    assert np.abs(pel[-1, :2] - pel[0, :2]).max() < 0.15  # in place, within 15 cm
    k = int(r.touchdowns)
    assert k >= 5  # the swing feet land every 0.4 s after the start-up phase
    feet = r.log.foot_m[:k]
    assert np.all(np.isfinite(feet)) and np.all(np.isnan(r.log.foot_m[k:]))
    walking = r.log.time_s[:k] > 0.6  # after the start-up phase: left, right, left, ...
    foot = r.log.foot[:k][walking]
    assert np.all(np.diff(foot) != 0) and foot[0] == 0
    np.testing.assert_allclose(feet[:, 2], 0.09, atol=0.015)  # foot points 9 cm above the floor: landed
    lateral = feet[walking, 1]
    assert np.all(np.sign(lateral) == np.where(foot == 0, 1, -1))


def test_the_closed_loop_recovers_a_push_the_open_loop_does_not(tp):
    rows, res = tp[0], tp[1]
    closed, opened = _one(res, _row(rows, "time-projection", True)), _one(res, _row(rows, "open-loop", True))
    push = rows[_row(rows, "open-loop", True)][1]
    assert rows[_row(rows, "time-projection", True)][1] is push  # the same push
    start = float(push.start_s)
    assert not closed.fell
    assert opened.fell and start < opened.fall_time_s <= float(opened.time_s[-1])
    assert closed.max_abs_footstep_adjustment_m > 0.03 and opened.max_abs_footstep_adjustment_m == 0.0
    # it steps backward: the pelvis ends behind where it was pushed
    i_push = int(start / 0.02)
    assert closed.saved["pelvis_m"][-1, 0] < closed.saved["pelvis_m"][i_push, 0]
    assert opened.steps_to_recover == -1


def test_a_blow_up_is_a_recorded_fall_and_stays_finite(tp):
    rows, res = tp[0], tp[1]
    i = next(i for i, (_, p, _, _) in enumerate(rows) if p is not None and float(jnp.abs(p.force_n).max()) > 1e5)
    r = _one(res, i)
    assert r.fell and 1.0 < r.fall_time_s < 1.1 and r.steps_to_recover == -1
    for x in (r.saved["pelvis_m"], r.time_s, r.mean_speed_mps, r.max_abs_footstep_adjustment_m):
        assert np.all(np.isfinite(x))
    frozen = r.time_s > r.fall_time_s + 0.02
    pel = r.saved["pelvis_m"]
    assert np.all(pel[frozen] == pel[frozen][0])  # frozen at the last good state
    assert np.all(r.log.time_s[: int(r.touchdowns)] <= r.fall_time_s)  # nothing logged after the fall


@pytest.mark.parametrize("kwargs, name", [(dict(seconds=0.0), "seconds"), (dict(seconds=float("inf")), "seconds")])
def test_walk_spec_rejects_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ro.WalkSpec(**kwargs).validate()


def test_the_rollout_refuses_a_privileged_controller_unless_allowed(walking_env):
    ctrl, cfg = controllers.load("joint-pd")
    spy = ctrl._replace(name="spy", privileged=True)
    with pytest.raises(ValueError, match="ground truth"):
        ro.walk(spy, cfg, walking_env, ro.no_push(), jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="ground truth"):
        ro.jit_walk(spy)


def test_the_rollout_refuses_another_control_period_and_a_joystick_beyond_the_controller(walking_env):
    import dataclasses

    ctrl, cfg = controllers.load("time-projection")
    slow = dataclasses.replace(walking_env, n_substeps=4)  # a 4 ms control tick
    with pytest.raises(ValueError, match="control period"):
        ro.walk(ctrl, cfg, slow, ro.no_push(), jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="forward_mps"):
        ro.walk(ctrl, cfg, walking_env, ro.no_push(), jax.random.PRNGKey(0), joystick=controllers.joystick(0.5))
    with pytest.raises(ValueError, match="lateral_mps"):
        ro.walk(ctrl, cfg, walking_env, ro.no_push(), jax.random.PRNGKey(0),
                joystick=controllers.joystick(0.0, 0.1))


def test_ticks_round_up_to_whole_records():
    assert ro.n_ticks(ro.WalkSpec(seconds=1.0), 0.002) == 500
    assert ro.n_ticks(ro.WalkSpec(seconds=1.001), 0.002, ro.SaveAt(ro.pelvis_and_com, every=10)) == 510


# --- long runs -------------------------------------------------------------------------------------

def _stack(items):
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *items)


@pytest.mark.slow
def test_ten_seconds_in_place_open_and_closed_loop(walking_env):
    """Seed Figure 14: 10 s of in-place walking (25 phases) open and closed loop without falling."""
    ctrl = controllers.get("time-projection")
    cfgs = _stack([controllers.default_config("time-projection"), controllers.default_config("open-loop")])
    fn = ro.batched_walk(ctrl, ro.WalkSpec(seconds=10.4), config_axes=0)
    res = jax.tree_util.tree_map(np.asarray, fn(cfgs, walking_env, _stack([ro.no_push()] * 2),
                                                jax.random.split(jax.random.PRNGKey(1), 2), controllers.joystick()))
    assert not res.fell.any() and np.all(res.touchdowns >= 25)
    assert np.all(np.abs(res.mean_speed_mps) < 0.1)  # in place it drifts forward at about 0.07 m/s


@pytest.mark.slow
@pytest.mark.parametrize("speed", [0.1, 0.2])
def test_walking_speed_within_a_quarter_of_the_command(walking_env, speed):
    """Seed Figure 19: the same controller walks at the 3LP gait's speed (the speed is the joystick's)."""
    ctrl, cfg = controllers.load("time-projection")
    res = ro.jit_walk(ctrl, ro.WalkSpec(seconds=10.4))(cfg, walking_env, ro.no_push(), jax.random.PRNGKey(2),
                                                         controllers.joystick(speed))
    assert not bool(res.fell)
    assert abs(float(res.mean_speed_mps) - speed) < 0.25 * speed


@pytest.mark.slow
def test_a_batch_of_64_pushed_walks_in_one_vmap(walking_env):
    """64 walks over push phase, impulse and direction, and per-walk spring stiffness, in one vmap on the CPU."""
    import dataclasses

    n = 64
    rng = np.random.default_rng(0)
    phases, imps = rng.uniform(0, 1, n), rng.uniform(0, 6, n)
    dirs = rng.choice([0.0, math.pi], n)
    pushes = _stack([ro.make_push((2 + p) * 0.4, 0.1, impulse_ns=i, direction_rad=d)
                     for p, i, d in zip(phases, imps, dirs)])
    act = walking_env.actuator
    k = act.spring_stiffness_nm_per_rad * rng.uniform(0.9, 1.1, (n, 1)).astype(np.float32)
    batched = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), act)
    batched = dataclasses.replace(batched, spring_stiffness_nm_per_rad=jnp.asarray(k))
    env_b = dataclasses.replace(walking_env, actuator=batched,
                                sensor=jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))),
                                                              walking_env.sensor))
    ctrl, cfg = controllers.load("time-projection")
    fn = ro.batched_walk(ctrl, ro.WalkSpec(seconds=3.2), env_axes=batch_axes(env_b))
    res = jax.tree_util.tree_map(np.asarray, fn(cfg, env_b, pushes, jax.random.split(jax.random.PRNGKey(3), n),
                                                controllers.joystick()))
    assert res.fell.shape == (n,) and np.all(np.isfinite(res.mean_speed_mps))
    assert not res.fell[imps < 1.0].any()  # gentle pushes never topple it


def test_checkpointed_segments_divide_the_walk():
    for total in (1, 7, 150, 250, 5000):
        seg = ro.segment_ticks(total)
        assert total % seg == 0 and seg <= math.isqrt(total)
    assert ro.segment_ticks(250) == 10 and ro.segment_ticks(5000) == 50


def test_solver_iterations_is_static_and_checked(walking_env):
    from mjx_coman.env import solver_iterations

    assert solver_iterations(walking_env, 1).model.opt.iterations == 1
    assert walking_env.model.opt.iterations == 4  # the model's own, untouched
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="iterations"):
            solver_iterations(walking_env, bad)
    with pytest.raises(ValueError, match="checkpoint"):
        ro.WalkSpec(checkpoint=1).validate()


@pytest.mark.slow
def test_reverse_mode_through_a_wbc_stand_rollout_matches_central_differences():
    """jax.grad of a pushed 0.3 s wbc-stand walk's CoM sway with respect to the CoM stiffness, through MJX
    at one solver iteration (no while_loop) and checkpointed ticks: equal to forward mode, and to central
    differences of the same walk (float64; encoders at 40 bits so no quantum step sits inside the
    differences). Slow: the reverse-mode compilation alone takes about 5 minutes on 2 cores."""
    from mjx_coman.env import solver_iterations
    from mjx_coman.sensors import make_sensor_params

    with jax.enable_x64(True):
        ctrl, cfg = controllers.load("wbc-stand", {})
        env = ro.plant_env_params("torque-ideal")
        env = solver_iterations(dataclasses.replace(env, sensor=make_sensor_params(encoder_bits=40)))
        push = ro.make_push(0.02, 0.1, impulse_ns=3.0)
        spec, save = ro.WalkSpec(seconds=0.3, checkpoint=True), ro.SaveAt(ro.pelvis_and_com, every=10)
        key = jax.random.PRNGKey(0)

        def sway(kp):
            r = ro.walk(ctrl.core(), cfg.replace(com_kp_per_s2=kp), env, push, key, spec, None, save)
            x = r.saved["com_m"][:, 0]
            return jnp.mean((x - x[0]) ** 2) * 1e4, r.fell

        kp = cfg.com_kp_per_s2
        value, fell = jax.jit(sway)(kp)
        assert not bool(fell) and float(value) > 1e-3  # the push moves the CoM
        rev = float(jax.jit(jax.grad(lambda k: sway(k)[0]))(kp))
        fwd = float(jax.jit(lambda k: jax.jvp(lambda k: sway(k)[0], (k,), (jnp.ones_like(k),))[1])(kp))
        f = jax.jit(lambda k: sway(k)[0])
        fd = {h: float((f(kp * (1 + h)) - f(kp * (1 - h))) / (2 * h * kp)) for h in (1e-3, 1e-4)}
    assert rev < 0  # stiffer CoM task, less sway
    assert rev == pytest.approx(fwd, rel=1e-6)
    assert any(d == pytest.approx(rev, rel=1e-2) for d in fd.values()), (rev, fd)


class _FailsAfter:
    """A controller that reports a failed solve (``ok`` False, infinite diagnostics in ``extra``) from
    ``fail_s`` on, with the wrapped controller's finite command."""

    privileged = False

    def __init__(self, base, fail_s):
        self.base, self.fail_s = base, fail_s

    def gait(self, config):
        return self.base.gait(config)

    def init(self, config, env_params, key):
        return self.base.init(config, env_params, key)

    def step(self, config, state, obs):
        state, cmd, tel = self.base.step(config, state, obs)
        fail = obs.time_s >= self.fail_s
        return state, cmd, tel._replace(extra=jnp.where(fail, jnp.inf, 0.0), ok=~fail)


def test_a_failed_solve_is_recorded_as_one_not_as_non_finite(walking_env):
    ctrl, config = controllers.load("open-loop")
    env_params = walking_env
    res = jax.jit(lambda: ro.walk(_FailsAfter(ctrl.core(), 0.1), config, env_params, ro.no_push(),
                                  jax.random.PRNGKey(0), ro.WalkSpec(seconds=0.2)))()
    assert bool(res.fell) and bool(res.solve_failed) and not bool(res.nan)
    assert abs(float(res.fall_time_s) - 0.1 - ctrl.gait(config).control_period_s) < 1e-5  # the failing tick's end
