import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxlp import dynamics as D
from jaxlp.params import make_params


@pytest.mark.parametrize("lateral", [False, True])
@pytest.mark.parametrize("t", [0.05, 0.2, 0.4])
def test_closed_form_matches_ode_integration(coman, lateral, t):
    rng = np.random.default_rng(3)
    q0 = rng.normal(scale=[0.05, 0.05, 0.0, 0.2, 0.2, 0.0])
    u = np.array([1.5, -4.0])
    ankle = np.array([0.7, 2.0])
    push, d = 12.0, -1.0
    dyn = D.axis_dynamics(coman, lateral)
    Cx, Cu, Ca, Cf, Cd = (np.asarray(a) for a in dyn)

    def rhs(time, y):
        x, v = y[:3], y[3:]
        acc = Cx @ x + Cu * (u[0] + time * u[1]) + Ca * (ankle[0] + time * ankle[1]) + Cf * push + Cd * d
        return np.concatenate([v, acc])

    ref = solve_ivp(rhs, (0.0, t), q0, rtol=1e-11, atol=1e-13).y[:, -1]
    got = D.propagate(D.transition(coman, t, lateral), q0, u, d=d, ankle=ankle, push=push)
    np.testing.assert_allclose(np.asarray(got), ref, atol=1e-9)


def test_stance_foot_stays_put(coman):
    for lateral in (False, True):
        dyn = D.axis_dynamics(coman, lateral)
        assert np.all(np.asarray(dyn.Cx[2]) == 0) and float(dyn.Cu[2]) == 0


def test_light_legs_reduce_to_the_linear_inverted_pendulum():
    """m2 -> 0, I2 -> 0, h3 = 0: the pelvis obeys p_dd = g/h1 (p - a) + F/m1.

    (A massless swing leg can carry no hip torque, so the torque column has no
    LIP limit to compare with.)
    """
    p = make_params(m1=30.0, m2=1e-9, h1=0.8, h2=0.4, h3=0.0, I2=1e-12, pw=0.1)
    dyn = D.axis_dynamics(p, False)
    w2 = 9.81 / 0.8
    np.testing.assert_allclose(np.asarray(dyn.Cx[1]), [0.0, w2, -w2], rtol=1e-6, atol=1e-6)
    assert float(dyn.Cf[1]) == pytest.approx(1.0 / 30.0, rel=1e-6)


def test_sagittal_has_no_width_term_lateral_does(coman):
    assert np.allclose(np.asarray(D.axis_dynamics(coman, False).Cd), 0.0)
    assert not np.allclose(np.asarray(D.axis_dynamics(coman, True).Cd), 0.0)


def test_lateral_mirror_symmetry(coman):
    """Mirroring y -> -y with d -> -d and the torque sign flipped mirrors the motion."""
    q0 = jnp.array([0.12, 0.06, 0.0, 0.0, -0.2, 0.0])
    tr = D.transition(coman, 0.3, True)
    a = D.propagate(tr, q0, (0.8, 0.5), d=1.0, push=3.0)
    b = D.propagate(tr, -q0, (-0.8, -0.5), d=-1.0, push=-3.0)
    np.testing.assert_allclose(np.asarray(a), -np.asarray(b), atol=1e-12)


def test_translation_invariance(coman):
    q0 = jnp.array([-0.04, -0.02, 0.0, 0.0, 0.13, 0.0])
    shift = jnp.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    tr = D.transition(coman, 0.4, False)
    np.testing.assert_allclose(
        np.asarray(D.propagate(tr, q0 + shift, (1.0, 2.0))),
        np.asarray(D.propagate(tr, q0, (1.0, 2.0)) + shift), atol=1e-12)


def test_transition_is_differentiable_in_time_and_params(coman):
    q0 = jnp.array([-0.04, -0.02, 0.0, 0.0, 0.13, 0.0])
    f = lambda t, h1: D.propagate(D.transition(coman.__class__(**{**coman.__dict__, "h1": h1}), t, False), q0)[1]  # noqa: E731
    gt, gh = jax.grad(f, argnums=(0, 1))(0.3, coman.h1)
    eps = 1e-6
    fd_t = (f(0.3 + eps, coman.h1) - f(0.3 - eps, coman.h1)) / (2 * eps)
    fd_h = (f(0.3, coman.h1 + eps) - f(0.3, coman.h1 - eps)) / (2 * eps)
    assert float(gt) == pytest.approx(float(fd_t), rel=1e-6)
    assert float(gh) == pytest.approx(float(fd_h), rel=1e-5)
