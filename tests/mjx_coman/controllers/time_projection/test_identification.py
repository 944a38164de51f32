"""Dead-zone and knee-deflection identification (seed 000, Figures 7 and 9, eq. 21 and 27)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.time_projection import identification as idn


@pytest.mark.parametrize("mean,std", [((0.0, 0.0, 0.0, 0.0), (1e-3, 2e-3, 1e-2, 2e-2)),
                                      ((5e-3, -2e-3, 0.01, -0.02), (3e-3, 1e-3, 4e-2, 1e-2))])
def test_fit_deadzones_recovers_a_known_gaussian(mean, std):
    n = 20000
    rng = np.random.default_rng(1)
    e = np.asarray(mean) + np.asarray(std) * rng.standard_normal((n, 4))
    # outliers (e.g. a fall at the end) are masked out and must not matter
    e[-100:] = 10.0
    mask = np.arange(n) < n - 100
    fit = idn.fit_deadzones(e, mask)
    assert int(fit.n_samples) == n - 100
    # sample std of n Gaussian draws: relative error ~ 1/sqrt(2n) ~ 0.5 %; allow 3 %
    np.testing.assert_allclose(fit.std, std, rtol=0.03)
    assert np.all(np.abs(np.asarray(fit.mean) - mean) < 4 * np.asarray(std) / np.sqrt(n))  # 4 standard errors
    np.testing.assert_allclose(fit.thresholds, fit.std)


def test_fit_deadzones_skips_non_finite_samples_and_floors_thresholds():
    e = np.zeros((50, 4))
    e[:, 0] = np.linspace(-1.0, 1.0, 50)
    e[10, 2] = np.nan
    fit = idn.fit_deadzones(e)
    assert int(fit.n_samples) == 49
    assert np.all(np.isfinite(fit.std))
    assert np.all(np.asarray(fit.thresholds) >= idn.MIN_THRESHOLD)  # constant components: floor, not zero
    assert float(fit.thresholds[0]) == pytest.approx(np.std(np.delete(e[:, 0], 10), ddof=1), rel=1e-5)


def test_fit_deadzones_vmaps_over_walks_and_fits_both_axes():
    rng = np.random.default_rng(2)
    std = np.array([[1e-3, 2e-3, 3e-2, 4e-2], [5e-3, 6e-3, 7e-2, 8e-2]])  # sagittal, lateral
    e = std * rng.standard_normal((3, 4000, 2, 4))  # 3 walks
    fits = jax.jit(jax.vmap(idn.fit_deadzones))(jnp.asarray(e))
    assert fits.std.shape == (3, 2, 4)
    np.testing.assert_allclose(fits.std, np.broadcast_to(std, (3, 2, 4)), rtol=0.05)


def test_fit_deadzones_rejects_a_wrong_shape():
    with pytest.raises(ValueError, match="4 components"):
        idn.fit_deadzones(np.zeros((10, 3)))


def test_error_sample_mask_at_phase_changes():
    t = np.arange(12) * 0.1
    k = np.repeat(np.arange(4), 3)
    every = idn.error_sample_mask(t, k, settle_s=0.25)
    assert every.tolist() == [False] * 3 + [True] * 9
    firsts = idn.error_sample_mask(t, k, settle_s=0.25, at_phase_change=True)
    assert np.flatnonzero(firsts).tolist() == [3, 6, 9]
    valid = np.arange(12) < 8
    assert np.flatnonzero(idn.error_sample_mask(t, k, 0.0, valid, at_phase_change=True)).tolist() == [0, 3, 6]


@pytest.mark.parametrize("mu", [(0.03, 0.015), (0.02, 0.02)])
def test_fit_knee_deflection_recovers_the_slope_through_the_origin(mu):
    # in-place walking: loads alternate between single (1) and double (~0.5) support, swing ~0
    rng = np.random.default_rng(3)
    n = 5000
    phase = (np.arange(n) % 200) / 200.0
    load_l = np.clip(np.where(phase < 0.5, 1.0, 0.0) + 0.05 * rng.standard_normal(n), 0, None)
    load = np.stack([load_l, np.clip(1.0 - load_l, 0, None)], axis=1)
    defl = np.asarray(mu) * load + 1e-3 * rng.standard_normal((n, 2))
    fit = idn.fit_knee_deflection(defl, load)
    np.testing.assert_allclose(fit.mu_rad, mu, atol=2e-4)
    np.testing.assert_allclose(fit.residual_std_rad, 1e-3, rtol=0.05)
    np.testing.assert_allclose(fit.full_support_mean_rad, mu, rtol=0.05)  # loads near 1
    assert float(fit.mu_left_rad) == pytest.approx(mu[0], abs=2e-4)


def test_knee_samples_order_left_right():
    link = np.zeros(23)
    motor = np.zeros(23)
    link[idn.LEFT_KNEE], motor[idn.LEFT_KNEE] = 0.42, 0.40
    link[idn.RIGHT_KNEE], motor[idn.RIGHT_KNEE] = 0.41, 0.40
    defl, load = idn.knee_samples(link, motor, np.array([100.0, 300.0]), 400.0)  # sensor order (right, left)
    np.testing.assert_allclose(defl, [0.02, 0.01], atol=1e-7)
    np.testing.assert_allclose(load, [0.75, 0.25])


def test_knee_deflection_of_standing_matches_moment_over_stiffness(stand_run, env_params):
    """Physics check on 1 s of crouched standing: deflection = (ground + lower-leg weight moment) / k.

    Each foot carries half the weight, so the fitted mu (deflection at full
    support) is twice the standing deflection, and equals twice the static
    moment over the spring stiffness.
    """
    _, rec = stand_run
    late = slice(250, None)  # after settling
    w = float(idn.total_weight_n(env_params.model))
    assert w == pytest.approx(28.89 * 9.81, rel=0.01)
    defl, load = idn.knee_samples(rec["q_rad"][late], rec["motor_rad"][late], rec["normal_n"][late], w)
    np.testing.assert_allclose(np.mean(load, axis=0), 0.5, atol=0.03)
    fit = idn.fit_knee_deflection(defl, load)
    moment = jax.vmap(idn.knee_load_moment_nm)(rec["q_rad"][late], rec["ft_l"][late], rec["ft_r"][late],
                                               rec["root_quat"][late])
    k = float(env_params.actuator.spring_stiffness_nm_per_rad[idn.LEFT_KNEE])
    predicted = np.mean(np.asarray(moment), axis=0) / k
    np.testing.assert_allclose(np.mean(np.asarray(defl), axis=0), predicted, rtol=0.05)
    np.testing.assert_allclose(fit.mu_rad, predicted / np.mean(np.asarray(load), axis=0), rtol=0.06)
    # the ground reaction alone over-predicts: the shank and foot weigh 2.8 kg ahead of the knee
    no_weight = jax.vmap(idn.knee_load_moment_nm)(rec["q_rad"][late], rec["ft_l"][late], rec["ft_r"][late])
    assert np.all(np.mean(np.asarray(no_weight), axis=0) / k > 1.2 * predicted)


def test_phase_index_from_sign_counts_the_flips():
    d = np.array([1, 1, -1, -1, -1, 1, 1, -1])
    assert idn.phase_index_from_sign(d).tolist() == [0, 0, 1, 1, 1, 2, 2, 3]


def test_identify_from_a_recorded_walk_leaves_out_the_start_and_the_fall():
    """A fake recorded walk: errors are known Gaussians, the walk is frozen after a fall at 3 s."""
    from types import SimpleNamespace

    rng = np.random.default_rng(4)
    n, dt = 2000, 0.002  # 4 s, every tick
    std = np.array([2e-3, 3e-3, 2e-2, 3e-2])
    err = std * rng.standard_normal((n, 4))
    err[:500] += 1.0  # the start from standing (up to 1 s; settle_s = 1.001 s)
    t = (np.arange(n) + 1) * dt
    fall = 3.0
    err[t >= fall] = 5.0  # after the fall
    t_rec = np.minimum(t, fall - dt)  # the recorded time stops at the fall
    d = np.where((t // 0.4) % 2 == 0, 1.0, -1.0)
    load = np.stack([(d > 0) * 0.0 + (d < 0) * 1.0, (d > 0) * 1.0], axis=1)
    defl = 0.03 * load
    rec = SimpleNamespace(time_s=t_rec, fall_time_s=np.float32(fall),
                          saved=SimpleNamespace(d=d, error=err, knee_deflection_rad=defl, foot_force_n=load * 250.0))
    fit = idn.identify_deadzones(rec, settle_s=1.001)
    assert int(fit.n_samples) == 999  # 1.002 s ... 2.998 s
    np.testing.assert_allclose(fit.thresholds, std, rtol=0.08)
    at_change = idn.identify_deadzones(rec, settle_s=1.001, at_phase_change=True)
    assert int(at_change.n_samples) == 5  # phase starts at 1.2, 1.6, 2.0, 2.4, 2.8 s
    knee = idn.identify_knee_deflection(rec, 250.0, settle_s=1.001)
    np.testing.assert_allclose(knee.mu_rad, 0.03, rtol=1e-5)
    with pytest.raises(ValueError, match="settle_s"):
        idn.identify_deadzones(rec, settle_s=-1.0)


@pytest.mark.slow
def test_identify_on_the_open_loop_in_place_walk():
    """Seed Figures 7 and 9 on the simulated robot: 8 s of the open-loop in-place gait, identified once."""
    from mjx_coman.rollout import walking_env_params
    from mjx_coman.seed000 import open_loop_walk

    env = walking_env_params()
    walk = jax.tree_util.tree_map(np.asarray, open_loop_walk(env, seconds=8.0))
    assert not walk.fell and walk.touchdowns >= 18
    dz = idn.identify_deadzones(walk, settle_s=1.6)
    th = np.asarray(dz.thresholds)
    assert int(dz.n_samples) == 3201
    assert np.all((th[:2] > 5e-4) & (th[:2] < 0.03))  # positions: mm to cm of spread
    assert np.all((th[2:] > 5e-3) & (th[2:] < 0.3))  # velocities, m/s
    knee = idn.identify_knee_deflection(walk, idn.total_weight_n(env.model), settle_s=1.6)
    mu = np.asarray(knee.mu_rad)
    # the loaded knee yields (link ahead of motor) by a spring-sized angle: 390 N m/rad, ~10 N m
    assert np.all((mu > 0.005) & (mu < 0.06))
    assert abs(mu[0] - mu[1]) < 0.2 * mu.mean()  # a symmetric robot
    # the slope through the origin agrees with the seed's histogram mean at full support
    np.testing.assert_allclose(knee.full_support_mean_rad, mu, rtol=0.15)
    assert np.all(np.asarray(knee.residual_std_rad) < 0.3 * mu)
