import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp import control as C, gait as G, projection as P
from jaxlp.dynamics import N_AUG, flow

T = 0.4


@pytest.fixture(scope="module")
def setup(coman):
    ctrl = C.constrained_dlqr(coman, T)
    return ctrl, P.gain_table(coman, ctrl, T, 40)


@pytest.mark.parametrize("t", [0.0, 0.1, 0.25, 0.35])
def test_footstep_gain_matches_simulated_adjustment(coman, setup, t):
    """Run the corrected 3LP from t to T with a perturbed state: the landing moves by gain @ e."""
    ctrl, _ = setup
    g = G.periodic_gait(coman, T, 0.1, 0.1272)
    e = jnp.array([0.004, -0.003, 0.02, 0.03])

    def landing(err):
        q_nom = G.nominal_state(coman, g, t)[0]
        q = q_nom + C.M_HAT @ err
        dU = P.time_projection(coman, ctrl, t, err)
        z = jnp.zeros(N_AUG).at[:6].set(q)
        z = z.at[6].set(g.u[0, 0] + t * g.u[0, 1] + dU[0] + t * dU[1]).at[7].set(g.u[0, 1] + dU[1]).at[11].set(1.0)
        qT = flow(coman, T - t, False) @ z
        return qT[0] - qT[1]

    change = landing(e) - landing(jnp.zeros(4))
    assert float(change) == pytest.approx(float(P.footstep_gain(coman, ctrl, t, T) @ e), rel=1e-8, abs=1e-12)


def test_table_samples_equal_direct_gains(coman, setup):
    ctrl, tab = setup
    for i in (0, 7, 39):
        t = float(tab.phase[i]) * T
        np.testing.assert_allclose(np.asarray(tab.footstep[i]), np.asarray(P.footstep_gain(coman, ctrl, t, T)), rtol=1e-10)
        np.testing.assert_allclose(np.asarray(tab.hip_torque[i]), np.asarray(P.hip_torque_gain(coman, ctrl, t)), rtol=1e-10)


def test_interpolation_between_samples(coman, setup):
    ctrl, tab = setup
    mid = (float(tab.phase[10]) + float(tab.phase[11])) / 2
    got = P.interpolate(tab, mid).footstep
    np.testing.assert_allclose(np.asarray(got), np.asarray((tab.footstep[10] + tab.footstep[11]) / 2), rtol=1e-12)
    exact = P.footstep_gain(coman, ctrl, mid * T, T)
    np.testing.assert_allclose(np.asarray(got), np.asarray(exact), rtol=2e-2, atol=1e-3)
    # held beyond the last sample
    np.testing.assert_allclose(np.asarray(P.interpolate(tab, 1.0).footstep), np.asarray(tab.footstep[-1]))


def test_pelvis_gain_shrinks_over_the_phase(setup):
    """Figure 13 B: the earlier the error, the more the footstep must move for it."""
    _, tab = setup
    pelvis = np.asarray(tab.footstep[:, 1])
    assert pelvis[0] > 1.5 and np.all(np.diff(pelvis[: int(0.8 * len(pelvis))]) < 0)


def test_table_is_differentiable_wrt_step_time(coman):
    def f(step_time):
        ctrl = C.constrained_dlqr(coman, step_time)
        return P.footstep_gain(coman, ctrl, 0.1, step_time)[1]

    eps = 1e-6
    fd = (f(T + eps) - f(T - eps)) / (2 * eps)
    assert float(jax.grad(f)(T)) == pytest.approx(float(fd), rel=1e-4)
