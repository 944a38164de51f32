"""Closed-loop 3LP: nominal tracking, the seed's push argument, falls, batches, noise, gradients."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp import simulate as S

N_STEPS = 10
PHASES = np.arange(8) / 8
FORCES_N = np.linspace(0.0, 240.0, 13)  # 0.1 s pushes: 0 to 24 N s


def _grid_runner(params, controller):
    spec = S.SimSpec(controller=controller, n_steps=N_STEPS)

    def one(start, force):
        return S.simulate(params, S.Push(start, jnp.asarray(0.1), force, jnp.asarray(0.0)), spec)

    grid = jax.vmap(jax.vmap(one, (None, 0)), (0, None))
    return jax.jit(grid)


@pytest.fixture(scope="module")
def grids(coman):
    starts = jnp.asarray(0.8 + PHASES * 0.4)
    forces = jnp.asarray(FORCES_N)
    return {c: jax.device_get(_grid_runner(coman, c)(starts, forces)) for c in ("time-projection", "dlqr")}


def _max_recovered(result):
    fell = np.asarray(result.fell)
    return np.array([FORCES_N[~f].max() if (~f).any() else 0.0 for f in fell])


def test_undisturbed_walk_follows_the_gait(coman):
    spec = S.SimSpec(controller="time-projection", n_steps=N_STEPS)
    r = jax.jit(lambda: S.simulate(coman, S.NO_PUSH, spec, speed_mps=0.1))()
    assert not bool(r.fell)
    assert float(jnp.max(jnp.abs(r.step_error))) < 1e-9
    np.testing.assert_allclose(np.diff(np.asarray(r.footsteps_m[:, 0])), 0.04, atol=1e-9)  # v T per step
    np.testing.assert_allclose(np.abs(np.diff(np.asarray(r.footsteps_m[:, 1]))), float(S.make_plan(coman, spec, 0.1).gait.step_width_m), atol=1e-9)
    assert int(r.steps_to_recover) == 0


def test_zero_push_column_never_falls(grids):
    for res in grids.values():
        assert not np.any(np.asarray(res.fell)[:, 0])


def test_time_projection_recovers_what_phase_start_dlqr_does_not(grids):
    """Seed 000: inter-sample pushes need the time-projecting controller."""
    tp, dl = _max_recovered(grids["time-projection"]), _max_recovered(grids["dlqr"])
    assert np.all(tp >= dl)
    late = PHASES >= 0.5
    assert np.all(tp[late] > dl[late])
    assert tp.min() >= 2 * max(dl.min(), 10.0)


def test_recovered_pushes_take_a_few_steps(grids):
    r = grids["time-projection"]
    ok = ~np.asarray(r.fell) & (FORCES_N[None, :] > 0)
    steps = np.asarray(r.steps_to_recover)[ok]
    assert np.all(steps >= 1) and np.median(steps[steps > 0]) <= 5


def test_small_pushes_move_the_footstep_in_proportion(grids):
    """Below saturation the closed loop is linear: twice the push, twice the footstep adjustment."""
    r = grids["time-projection"]
    adjust = np.abs(np.asarray(r.footstep_adjustment_m)).max(axis=-1)  # (phase, force)
    assert np.all(adjust[:, 0] < 1e-9)
    early = PHASES <= 0.5  # late in the phase the hip torque saturates even for small pushes
    np.testing.assert_allclose(adjust[early, 2], 2 * adjust[early, 1], rtol=0.01)
    assert np.all(adjust[:, 1] > 0.005)


def test_a_fall_is_a_result_not_a_crash(coman):
    spec = S.SimSpec(controller="time-projection", n_steps=4)
    r = S.simulate(coman, S.make_push(0.5, 0.1, 2000.0, 0.0), spec)
    assert bool(r.fell) and 0.5 < float(r.fall_time_s) < 1.6
    assert np.all(np.isfinite(np.asarray(r.pelvis_m)))
    assert int(r.steps_to_recover) == -1


def test_vmap_over_robots(coman):
    spec = S.SimSpec(controller="time-projection", n_steps=4)
    heavy = dataclasses.replace(coman, m1=coman.m1 * 1.3)
    push = S.make_push(0.9, 0.1, 60.0, 0.0)
    batch = jax.tree.map(lambda a, b: jnp.stack([a, b]), coman, heavy)
    both = jax.jit(jax.vmap(lambda p: S.simulate(p, push, spec)))(batch)
    single = S.simulate(heavy, push, spec)
    np.testing.assert_allclose(np.asarray(both.pelvis_m[1]), np.asarray(single.pelvis_m), atol=1e-10)
    assert not np.allclose(np.asarray(both.pelvis_m[0]), np.asarray(both.pelvis_m[1]))


def test_noisy_sensing_is_filtered_and_seeded(coman):
    spec = S.SimSpec(controller="time-projection", n_steps=N_STEPS, sensing=True)
    sensing = S.make_sensing(noise_std_m=2e-3, bias_m=[[0.002, 0.002], [0.0, 0.0]])
    run = jax.jit(lambda key, push: S.simulate(coman, push, spec, sensing=sensing, key=key))
    k0, k1 = jax.random.PRNGKey(0), jax.random.PRNGKey(1)
    a, b, c = run(k0, S.NO_PUSH), run(k0, S.NO_PUSH), run(k1, S.NO_PUSH)
    assert not bool(a.fell)
    np.testing.assert_array_equal(np.asarray(a.pelvis_m), np.asarray(b.pelvis_m))
    assert not np.allclose(np.asarray(a.pelvis_m), np.asarray(c.pelvis_m))
    # 4 N s: with the filtered, biased estimate 6 N s lies on the boundary (recovered
    # at 0.9 s and 1.1 s but not at 1.0 s with the authors' DLQR cost).
    pushed = run(k0, S.make_push(1.0, 0.1, 40.0, 0.0))
    assert not bool(pushed.fell)


def test_gradient_through_the_rollout(coman):
    spec = S.SimSpec(controller="time-projection", n_steps=3)

    def final_pelvis(force):
        return S.simulate(coman, S.Push(jnp.asarray(0.5), jnp.asarray(0.1), force, jnp.asarray(0.0)), spec).pelvis_m[-1, 0]

    g = jax.jit(jax.grad(final_pelvis))(30.0)
    eps = 1e-3
    fd = (final_pelvis(30.0 + eps) - final_pelvis(30.0 - eps)) / (2 * eps)
    assert float(g) == pytest.approx(float(fd), rel=1e-5)
    assert float(g) > 0  # a forward push moves the walker forward


@pytest.mark.parametrize(
    "spec,match",
    [(S.SimSpec(controller="mpc"), "controller"), (S.SimSpec(step_time_s=0.401), "whole number"),
     (S.SimSpec(n_steps=0), "n_steps"), (S.SimSpec(dt_s=-0.002), "dt_s")],
)
def test_bad_spec_raises(coman, spec, match):
    with pytest.raises(ValueError, match=match):
        S.simulate(coman, S.NO_PUSH, spec)


@pytest.mark.parametrize("kwargs,match", [(dict(force_n=-5.0), "force_n"), (dict(duration_s=-0.1), "duration_s")])
def test_bad_push_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        S.make_push(**kwargs)
