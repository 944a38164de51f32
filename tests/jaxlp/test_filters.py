import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp import filters as F


@pytest.mark.parametrize("a", [0.001, 0.01, 0.2])
def test_deadzone_attenuates_64_percent_at_threshold(a):
    y = float(F.smooth_deadzone(a, a))
    assert 1.0 - y / a == pytest.approx(0.639, abs=2e-3)


def test_deadzone_shape():
    a = 0.01
    x = jnp.linspace(-0.2, 0.2, 401)
    y = F.smooth_deadzone(x, a)
    np.testing.assert_allclose(np.asarray(y), -np.asarray(F.smooth_deadzone(-x, a)), atol=1e-15)  # odd
    assert np.all(np.diff(np.asarray(y)) > 0)  # monotone
    # far away: a unit-slope line shifted by a
    assert float(F.smooth_deadzone(10.0, a)) == pytest.approx(10.0 - a, abs=1e-5)
    assert float(jax.grad(F.smooth_deadzone)(0.0, a)) == pytest.approx(0.0, abs=1e-12)  # flat at zero
    # gradient in the threshold against finite differences
    eps = 1e-7
    fd = (F.smooth_deadzone(0.02, a + eps) - F.smooth_deadzone(0.02, a - eps)) / (2 * eps)
    assert float(jax.grad(F.smooth_deadzone, argnums=1)(0.02, a)) == pytest.approx(float(fd), rel=1e-6)


@pytest.mark.parametrize("zeta", [0.05, 0.1, 0.5])
def test_iir_step_response(zeta):
    s = 0.0
    for k in range(1, 21):
        s = F.iir(s, 1.0, zeta)
        assert float(s) == pytest.approx(1.0 - (1.0 - zeta) ** k, rel=1e-12)


def test_velocity_estimate_of_a_ramp():
    dt, v = 0.002, 0.3
    state = F.filter_init((2,), window=30)
    for k in range(400):
        state, pos, vel = F.filter_step(state, jnp.array([v * k * dt, -v * k * dt]), 0.1, dt)
    # the IIR lags a ramp by a constant, so the differenced velocity is exact in steady state
    np.testing.assert_allclose(np.asarray(vel), [v, -v], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(pos), np.array([v, -v]) * (399 * dt - dt * (1 - 0.1) / 0.1), rtol=1e-6)


def test_moving_average_window():
    state = F.filter_init((1,), window=4)
    obs = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    for k, o in enumerate(obs):
        state, _, vel = F.filter_step(state, jnp.array([o]), 1.0, 1.0)
    assert float(vel[0]) == pytest.approx(0.25)  # one unit jump averaged over 4 samples


def test_swap_map_of_relative_coordinates():
    s1, s2 = 0.04, 0.02  # swing 4 cm ahead of the stance foot, pelvis 2 cm
    new = np.asarray(jnp.array([s1, s2]) @ F.SWAP_RELATIVE.T)
    np.testing.assert_allclose(new, [-0.04, -0.02])  # old stance now 4 cm behind, pelvis 2 cm behind


@pytest.mark.parametrize("adjust,expected", [(0.05, 0.05), (0.5, 0.35 * 0.5242), (-0.3, -0.35 * 0.5242)])
def test_footstep_truncation_and_attack_angle(adjust, expected):
    h1 = 0.5242
    assert float(F.footstep_to_attack_angle(adjust, h1)) == pytest.approx(expected / h1, rel=1e-12)
    assert float(F.footstep_to_attack_angle(adjust, h1, 0.3)) == pytest.approx(max(-0.3, min(0.3, adjust)) / h1)


@pytest.mark.parametrize("kwargs,match", [(dict(zeta=0.0), "zeta"), (dict(zeta=1.5), "zeta"),
                                           (dict(deadzone=(0.0, 1, 1, 1)), "deadzone"),
                                           (dict(deadzone=(1, 1)), "deadzone")])
def test_bad_filter_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        F.make_filter_params(**kwargs)


def test_bad_window():
    with pytest.raises(ValueError, match="window"):
        F.filter_init((2,), window=0)


@pytest.mark.parametrize("window", [4.0, 7.0])
def test_real_valued_window_is_the_moving_average_at_whole_numbers(window):
    """A window of w samples in a longer ring buffer averages exactly the w newest velocity samples."""
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(20, 1))
    plain, wide = F.filter_init((1,), window=int(window)), F.filter_init((1,), window=12)
    for o in obs:
        plain, _, v_plain = F.filter_step(plain, jnp.asarray(o), 0.3, 0.002)
        wide, _, v_wide = F.filter_step(wide, jnp.asarray(o), 0.3, 0.002, window_samples=window)
        np.testing.assert_allclose(np.asarray(v_wide), np.asarray(v_plain), rtol=1e-12, atol=1e-12)


def test_fractional_window_interpolates_and_has_a_gradient():
    obs = jnp.asarray(np.random.default_rng(1).normal(size=(20, 1)))

    def vel(w):
        state = F.filter_init((1,), window=12)
        for o in obs:
            state, _, v = F.filter_step(state, o, 0.3, 0.002, window_samples=w)
        return v[0]

    v4, v5, v45 = float(vel(4.0)), float(vel(5.0)), float(vel(4.5))
    sum4, sum5 = 4 * v4, 5 * v5  # sums of the 4 and 5 newest samples
    assert v45 == pytest.approx((sum4 + 0.5 * (sum5 - sum4)) / 4.5, rel=1e-12)
    eps = 1e-6
    assert float(jax.grad(vel)(4.3)) == pytest.approx((float(vel(4.3 + eps)) - float(vel(4.3 - eps))) / (2 * eps), rel=1e-6)
