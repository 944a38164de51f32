import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxlp import control as C, projection as P

T = 0.4


@pytest.fixture(scope="module")
def dlqr(coman):
    return C.constrained_dlqr(coman, T)


def test_riccati_matches_scipy(coman, dlqr):
    red = C.eliminate_landing_constraint(dlqr.emap)
    w = C.default_weights(coman)
    ref = scipy.linalg.solve_discrete_are(np.asarray(red.A), np.asarray(red.B), np.asarray(w.state_matrix()),
                                          np.array([[float(w.torque)]]))
    np.testing.assert_allclose(np.asarray(dlqr.P), ref, rtol=1e-9)


def test_open_loop_unstable_closed_loop_stable(dlqr):
    open_ = np.abs(np.linalg.eigvals(np.asarray(dlqr.emap.A)))
    closed = np.abs(np.linalg.eigvals(np.asarray(C.closed_loop_map(dlqr))))
    assert open_.max() > 1.2
    assert closed.max() < 0.5


def test_correction_lands_the_swing_foot_at_rest(dlqr):
    rng = np.random.default_rng(0)
    for _ in range(5):
        E = jnp.asarray(rng.normal(size=4) * [0.02, 0.02, 0.1, 0.1])
        E_next = dlqr.emap.A @ E - dlqr.emap.B @ (dlqr.K @ E)
        assert abs(float(C.C_HAT @ E_next)) < 1e-10


def test_lateral_gain_is_the_mirror_of_the_sagittal_one(coman, dlqr):
    lat = C.constrained_dlqr(coman, T, lateral=True)
    np.testing.assert_allclose(np.asarray(lat.K), -np.asarray(dlqr.K), rtol=1e-9)


def _unstable_magnitude(params):
    emap = C.step_error_map(params, T)
    return jnp.max(jnp.abs(jnp.linalg.eigvals(emap.A)))


def test_eigenvalue_gradient_wrt_h1(coman):
    f = lambda h1: _unstable_magnitude(dataclasses.replace(coman, h1=h1))  # noqa: E731
    eps = 1e-6
    fd = (f(coman.h1 + eps) - f(coman.h1 - eps)) / (2 * eps)
    # eigvals has a forward-mode derivative: use jvp
    _, tangent = jax.jvp(f, (coman.h1,), (jnp.ones(()),))
    assert float(tangent) == pytest.approx(float(fd), rel=1e-5)
    assert float(fd) < 0  # a longer leg falls slower


@pytest.mark.parametrize("field", ["position", "velocity", "torque"])
def test_gain_gradient_wrt_weight(coman, field):
    w0 = C.default_weights(coman)

    def gain(x):
        w = dataclasses.replace(w0, **{field: x})
        return C.constrained_dlqr(coman, T, w).K[0, 1]

    x0 = getattr(w0, field)
    eps = 1e-5 * x0
    fd = (gain(x0 + eps) - gain(x0 - eps)) / (2 * eps)
    assert float(jax.grad(gain)(x0)) == pytest.approx(float(fd), rel=1e-4)


@pytest.mark.parametrize("t", [0.0, 0.05, 0.13, 0.2, 0.31, 0.38])
def test_time_projection_constant_along_undisturbed_phase(coman, dlqr, t):
    E0 = jnp.array([0.01, 0.005, 0.0, 0.05])
    dU = -dlqr.K @ E0
    w = C.within_phase_map(coman, t)
    e_t = w.A @ E0 + w.B @ dU
    np.testing.assert_allclose(np.asarray(P.time_projection(coman, dlqr, t, e_t)), np.asarray(dU), rtol=1e-8, atol=1e-9)


def test_bad_weights_raise():
    with pytest.raises(ValueError, match="torque"):
        C.make_weights(1.0, 1.0, 0.0)
