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


def test_cost_mass_is_the_robots_nominal_total(coman):
    """The authors' torque cost uses COMAN's 28.5 kg, not the 3LP bodies' m1 + 2 m2 (26.95 kg)."""
    w = C.default_weights(coman)
    assert float(coman.total_mass_kg) == pytest.approx(28.5, abs=1e-12)
    assert float(w.torque) == pytest.approx(1.0 / (28.5 * float(coman.g)) ** 2, rel=1e-12)
    d = C.diagonal_weights(coman)
    assert float(d.torque) == pytest.approx(1.0 / (float(coman.m1 + 2 * coman.m2) * float(coman.g)) ** 2, rel=1e-12)


def test_authors_cost_is_pelvis_to_feet_distances_and_pelvis_speed(coman):
    w = C.default_weights(coman)
    Q = np.asarray(w.state_matrix())
    h1, g = float(coman.h1), float(coman.g)
    rng = np.random.default_rng(1)
    for _ in range(5):
        s_a, p_a, sd, pd = rng.normal(size=4)  # swing and pelvis rel. stance foot, their velocities
        direct = ((p_a - s_a) ** 2 + p_a**2) / h1**2 + pd**2 / (g * h1)
        E = np.array([s_a, p_a, sd, pd])
        assert E @ Q @ E == pytest.approx(direct, rel=1e-12)
    diag = np.asarray(C.diagonal_weights(coman).state_matrix())
    np.testing.assert_allclose(diag, np.diag([1 / h1**2, 1 / h1**2, 1 / (g * h1), 1 / (g * h1)]), rtol=1e-12)


@pytest.mark.parametrize("lateral", [False, True])
def test_exchange_convention_leaves_constrained_map_and_gain_unchanged(coman, lateral):
    """The conventions differ only by terms in the landing swing velocity, which the constraint zeroes."""
    maps = {x: C.step_error_map(coman, T, lateral, exchange=x) for x in C.EXCHANGES}
    assert not np.allclose(np.asarray(maps["authors"].A), np.asarray(maps["relative"].A), atol=1e-3)
    red = {x: C.eliminate_landing_constraint(m) for x, m in maps.items()}
    np.testing.assert_allclose(np.asarray(red["authors"].A), np.asarray(red["relative"].A), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(red["authors"].B), np.asarray(red["relative"].B), rtol=1e-9, atol=1e-12)
    ctrl = {x: C.constrained_dlqr(coman, T, lateral=lateral, exchange=x) for x in C.EXCHANGES}
    np.testing.assert_allclose(np.asarray(ctrl["authors"].K), np.asarray(ctrl["relative"].K), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(C.closed_loop_map(ctrl["authors"])),
                               np.asarray(C.closed_loop_map(ctrl["relative"])), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("robot", ["coman", "human"])
def test_authors_open_loop_map_has_the_translation_eigenvalue(robot):
    from jaxlp.presets import get_params

    params = get_params(robot)
    ev = np.linalg.eigvals(np.asarray(C.step_error_map(params, T).A))
    assert np.min(np.abs(ev - 1.0)) < 1e-9
    assert np.max(np.abs(ev)) > 3.0 if robot == "coman" else np.max(np.abs(ev)) > 1.0
    assert np.max(np.abs(ev.imag[np.abs(ev) > 1.5])) < 1e-9  # the unstable mode is real
    ev_rel = np.linalg.eigvals(np.asarray(C.step_error_map(params, T, exchange="relative").A))
    assert np.min(np.abs(ev_rel - 1.0)) > 1e-3


def test_unknown_exchange_and_cost_form_raise(coman):
    with pytest.raises(ValueError, match="'swap'"):
        C.step_error_map(coman, T, exchange="swap")
    with pytest.raises(ValueError, match="'full'"):
        C.make_weights(1.0, 1.0, 1.0, form="full")


@pytest.mark.parametrize("field", ["h1", "m2", "other_mass_kg"])
def test_gain_gradient_wrt_params(coman, field):
    """``d K / d param`` of the authors' DLQR against central differences."""
    def gain(x):
        return C.constrained_dlqr(dataclasses.replace(coman, **{field: x}), T).K[0, 1]

    x0 = getattr(coman, field)
    eps = 1e-6 * max(abs(float(x0)), 1.0)
    fd = (gain(x0 + eps) - gain(x0 - eps)) / (2 * eps)
    assert abs(float(fd)) > 1e-6
    assert float(jax.grad(gain)(x0)) == pytest.approx(float(fd), rel=1e-4)
