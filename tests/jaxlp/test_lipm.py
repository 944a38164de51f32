"""The closed-form LIPM of the footstep planner (seed 001, eq. 3, 9-13) against integration of eq. 3."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxlp import lipm

Z0 = 0.5
TAU = float(np.sqrt(Z0 / 9.81))
STATE = np.array([0.03, -0.05, 0.25, -0.2])
BASE = np.array([0.1, 0.07])


def _integrate(state, base, t_s, tau_s=TAU):
    """Eq. 3 (``p'' = (p - p_base) / tau^2``) by scipy's DOP853 at tight tolerances."""

    def rhs(_, y):
        return np.concatenate([y[2:], (y[:2] - base) / tau_s**2])

    sol = solve_ivp(rhs, (0.0, t_s), state, method="DOP853", rtol=1e-13, atol=1e-14)
    return sol.y[:, -1]


def test_time_constant_and_acceleration():
    assert float(lipm.time_constant_s(Z0)) == pytest.approx(TAU, rel=1e-15)
    assert float(lipm.time_constant_s(Z0, 1.62)) == pytest.approx(np.sqrt(Z0 / 1.62), rel=1e-15)
    acc = np.asarray(lipm.com_acceleration(STATE[:2], BASE, Z0))
    np.testing.assert_allclose(acc, 9.81 / Z0 * (STATE[:2] - BASE), rtol=1e-15)
    np.testing.assert_array_less(0.0, acc * (STATE[:2] - BASE))


@pytest.mark.parametrize("t_s", [0.05, 0.4, 0.9])
def test_closed_form_matches_integration(t_s):
    ref = _integrate(STATE, BASE, t_s)
    np.testing.assert_allclose(np.asarray(lipm.propagate(STATE, BASE, t_s, TAU)), ref, atol=1e-9, rtol=0)
    A, B = lipm.transition(t_s, TAU)
    np.testing.assert_allclose(np.asarray(A @ STATE + B @ BASE), ref, atol=1e-9, rtol=0)


def test_printed_eq10_velocity_coefficient_is_a_typo():
    """Printed: ``v0 (-1/(2h) + tau h/2)``; corrected: ``v0 tau (h - 1/h)/2``. Only the latter integrates eq. 3."""
    t_s = 0.4
    h = np.exp(t_s / TAU)
    p0, v0, pb = STATE[:2], STATE[2:], BASE
    common = pb * (1 - (h + 1 / h) / 2) + p0 * (h + 1 / h) / 2
    printed = common + v0 * (-1 / (2 * h) + TAU * h / 2)
    corrected = common + v0 * TAU * (h - 1 / h) / 2
    ref = _integrate(STATE, BASE, t_s)[:2]
    np.testing.assert_allclose(corrected, ref, atol=1e-9, rtol=0)
    assert np.max(np.abs(printed - ref)) > 1e-2  # centimetres off
    # the velocity row as stated in the module docstring
    v = (p0 - pb) * (h - 1 / h) / (2 * TAU) + v0 * (h + 1 / h) / 2
    np.testing.assert_allclose(v, _integrate(STATE, BASE, t_s)[2:], atol=1e-9, rtol=0)


def test_transitions_compose():
    t1, t2 = 0.13, 0.31
    A1, B1 = lipm.transition(t1, TAU)
    A2, B2 = lipm.transition(t2, TAU)
    A, B = lipm.transition(t1 + t2, TAU)
    np.testing.assert_allclose(np.asarray(A), np.asarray(A2 @ A1), atol=1e-12)
    np.testing.assert_allclose(np.asarray(B), np.asarray(A2 @ B1 + B2), atol=1e-12)
    A0, B0 = lipm.transition(0.0, TAU)
    np.testing.assert_array_equal(np.asarray(A0), np.eye(4))
    np.testing.assert_array_equal(np.asarray(B0), np.zeros((4, 2)))


def test_controllable():
    A, B = lipm.transition(0.4, TAU)
    assert np.linalg.matrix_rank(np.asarray(jnp.concatenate([B, A @ B], axis=1))) == 4
    assert np.max(np.abs(np.linalg.eigvals(np.asarray(A)))) > 5.0  # the unstable pendulum, exp(dt / tau)


def test_gradient_wrt_dt_and_tau_match_central_differences():
    def end(dt, tau):
        A, B = lipm.transition(dt, tau)
        return A @ jnp.asarray(STATE) + B @ jnp.asarray(BASE)

    jac = jax.jit(jax.jacfwd(end, argnums=(0, 1)))(0.4, TAU)
    eps = 1e-6
    for k, (dt, tau) in enumerate([((0.4 + eps, TAU), (0.4 - eps, TAU)), ((0.4, TAU + eps), (0.4, TAU - eps))]):
        fd = (np.asarray(end(*dt)) - np.asarray(end(*tau))) / (2 * eps)
        np.testing.assert_allclose(np.asarray(jac[k]), fd, rtol=1e-7, atol=1e-8)
    # the velocity change over dt is the acceleration of eq. 3 at the end
    np.testing.assert_allclose(np.asarray(jac[0][:2]), np.asarray(end(0.4, TAU))[2:], rtol=1e-12)


def test_batched_and_dtype_following():
    rng = np.random.default_rng(0)
    states, bases, times = rng.normal(size=(8, 4)) * 0.1, rng.normal(size=(8, 2)) * 0.1, rng.uniform(0.1, 0.5, 8)
    batched = jax.vmap(lipm.propagate, in_axes=(0, 0, 0, None))(states, bases, times, TAU)
    for k in range(8):
        one = lipm.propagate(states[k], bases[k], times[k], TAU)
        np.testing.assert_allclose(np.asarray(batched[k]), np.asarray(one), rtol=1e-14, atol=1e-15)
    A32, B32 = lipm.transition(jnp.float32(0.4), jnp.float32(TAU))
    assert A32.dtype == B32.dtype == jnp.float32
    q32 = lipm.propagate(jnp.asarray(STATE, jnp.float32), jnp.asarray(BASE, jnp.float32), 0.4, TAU)
    assert q32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(q32), _integrate(STATE, BASE, 0.4), rtol=1e-5, atol=1e-6)
    assert lipm.transition(0.4, TAU).A.dtype == jnp.float64


def test_validation():
    with pytest.raises(ValueError, match=r"tau_s must be finite and positive, got -0.2"):
        lipm.transition(0.4, -0.2)
    with pytest.raises(ValueError, match=r"z0_m must be finite and positive, got 0.0"):
        lipm.time_constant_s(0.0)
