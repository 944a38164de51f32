"""jaxlp.icp against closed forms, numerical integration and finite differences (seed 004, eq. 1-4)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp import icp

OMEGA = float(np.sqrt(9.81 / 0.5))
STEP_S, TRANSFER_S = 0.6, 0.2
FEET = np.array([[0.0, -0.08], [0.15, 0.08], [0.30, -0.08], [0.45, 0.08], [0.60, -0.08]])


def _plan(first_switch_s=0.3, transfer_s=TRANSFER_S):
    cmps = icp.step_cmps(jnp.asarray(FEET[0]), jnp.asarray(FEET[1:]), 5)
    return icp.plan(cmps, first_switch_s, STEP_S, OMEGA, transfer_s)


def test_eq4_gives_the_papers_2_7_cm_for_a_1_m_pendulum_and_a_0_75_m_stride():
    assert float(icp.cmp_height_deviation_m(0.75, 1.0)) == pytest.approx(0.0274, abs=5e-4)
    # and it is eq. 3 at the exchange: a rigid leg of length z_nom over a CMP half a stride behind
    l, z_nom = 0.75, 1.0
    z = np.sqrt(z_nom**2 - 0.25 * l**2)
    x, ecmp = 0.0, -0.5 * l
    assert float(icp.cmp_from_ecmp(x, ecmp, z, z_nom) - ecmp) == pytest.approx(float(icp.cmp_height_deviation_m(l, z_nom)))


def test_eq1_eq2_are_the_lip():
    """Integrating xdd = omega^2 (x - r) from (x0, v0), the ICP of eq. 1 follows eq. 2 in closed form."""
    x0, v0, r, t = 0.02, 0.3, -0.01, 0.4
    xi0 = icp.capture_point(x0, v0, OMEGA)
    ts = np.linspace(0.0, t, 4001)
    sol = _rk4(lambda s: np.array([s[1], OMEGA**2 * (s[0] - r)]), np.array([x0, v0]), ts)
    xi_t = r + np.exp(OMEGA * t) * (xi0 - r)
    assert float(icp.capture_point(sol[-1, 0], sol[-1, 1], OMEGA)) == pytest.approx(float(xi_t), rel=1e-8)
    assert float(icp.lip_com_acceleration(x0, r, OMEGA)) == pytest.approx(OMEGA**2 * (x0 - r))


def _rk4(f, y0, ts):
    ys = [np.asarray(y0, float)]
    for a, b in zip(ts[:-1], ts[1:]):
        h, y = b - a, ys[-1]
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        ys.append(y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    return np.array(ys)


def test_the_plan_ends_at_the_final_capture_point_and_obeys_eq2_outside_the_transfers():
    p = _plan()
    end = 0.3 + STEP_S * 4
    xi, xid, r = icp.reference(p, end)
    np.testing.assert_allclose(xi, 0.5 * (FEET[-1] + FEET[-2]), atol=1e-12)
    np.testing.assert_allclose(xid, 0.0, atol=1e-12)
    for t, foot in ((0.05, 0), (0.7, 1), (1.35, 2), (1.9, 3)):  # mid-segment: the CMP is that foot's
        xi, xid, r = icp.reference(p, t)
        np.testing.assert_allclose(r, FEET[foot], atol=1e-12)
        np.testing.assert_allclose(xid, OMEGA * (xi - FEET[foot]), atol=1e-12)


def test_the_reference_is_c1_and_integrates_its_own_cmp():
    """xi is continuous with a continuous rate through every window edge, and integrating eq. 2 with the
    reference CMP from xi(0) reproduces xi(t)."""
    p = _plan()
    ref = jax.jit(lambda t: icp.reference(p, t))
    eps = 1e-7
    for s in np.asarray(p.switch_s):
        for edge in (s - 0.5 * TRANSFER_S, s + 0.5 * TRANSFER_S):
            lo, hi = ref(edge - eps), ref(edge + eps)
            np.testing.assert_allclose(lo[0], hi[0], atol=1e-6)
            np.testing.assert_allclose(lo[1], hi[1], atol=1e-4)
    ts = np.linspace(0.0, 2.0, 20001)
    xi = np.asarray(ref(0.0)[0])
    for a, b in zip(ts[:-1], ts[1:]):  # Heun on xid = omega (xi - r(t)); r from the plan
        h = b - a
        k1 = OMEGA * (xi - np.asarray(ref(a)[2]))
        k2 = OMEGA * (xi + h * k1 - np.asarray(ref(b)[2]))
        xi = xi + 0.5 * h * (k1 + k2)
    np.testing.assert_allclose(xi, ref(2.0)[0], atol=2e-4)


def test_a_past_switch_is_the_same_plan_seen_later():
    """Planning from a time after the first switch (negative first_switch_s) gives the reference of the plan
    made before it, shifted in time: the controller re-plans every tick across a switch."""
    early = _plan(first_switch_s=0.3)
    late = icp.plan(early.cmp_m, -0.05, STEP_S, OMEGA, TRANSFER_S)
    for t in (0.0, 0.02, 0.3, 0.9):
        for a, b in zip(icp.reference(late, t), icp.reference(early, t + 0.35)):
            np.testing.assert_allclose(a, b, atol=1e-12)


def test_the_reference_cmp_moves_between_the_feet_only_during_transfer():
    p = _plan()
    s = float(p.switch_s[0])
    r_mid = np.asarray(icp.reference(p, s)[2])
    assert FEET[0, 0] < r_mid[0] < FEET[1, 0]
    np.testing.assert_allclose(icp.reference(p, s - 0.5 * TRANSFER_S - 1e-3)[2], FEET[0], atol=1e-12)
    np.testing.assert_allclose(icp.reference(p, s + 0.5 * TRANSFER_S + 1e-3)[2], FEET[1], atol=1e-12)


@pytest.mark.parametrize("gain", [1.5, 3.0])
def test_feedback_makes_the_closed_loop_lip_converge(gain):
    """The LIP xdd = omega^2 (x - r_fb) under the feedback CMP: the ICP error decays as exp(-omega (gain - 1) t)."""
    p = _plan()
    ref = jax.jit(lambda t: icp.reference(p, t))
    xi0, xid0, _ = ref(0.0)
    x, v = np.asarray(xi0) + np.array([0.02, -0.01]), np.zeros(2)  # CoM at rest, ICP 2 cm off
    x = x - v / OMEGA
    e0 = np.asarray(icp.capture_point(x, v, OMEGA) - xi0)
    dt, t_end = 5e-4, 0.8
    for k in range(int(t_end / dt)):
        t = k * dt
        xi_r, xid_r, _ = ref(t)
        r = icp.feedback_cmp(icp.capture_point(x, v, OMEGA), xi_r, xid_r, OMEGA, gain)
        a = np.asarray(icp.lip_com_acceleration(x, r, OMEGA))
        v = v + dt * a
        x = x + dt * v
    e = np.asarray(icp.capture_point(x, v, OMEGA) - ref(t_end)[0])
    expected = e0 * np.exp(-OMEGA * (gain - 1) * t_end)
    np.testing.assert_allclose(e, expected, atol=2e-3 * np.abs(e0).max() + 1e-4)
    assert np.linalg.norm(e) < 0.2 * np.linalg.norm(e0)


def test_step_adjustment_is_the_clipped_weighted_error_the_cmp_cannot_null():
    xi, xi_ref = jnp.array([0.05, 0.0]), jnp.array([0.03, 0.01])
    # no CMP range: the whole error grown to touchdown
    delta, r = icp.step_adjustment(xi, xi_ref, OMEGA, 0.2, 0.0, 1.0, 3.0, 0.1)
    np.testing.assert_allclose(r, np.exp(OMEGA * 0.2) * np.array([0.02, -0.01]), rtol=1e-12)
    np.testing.assert_allclose(delta, 0.75 * r, rtol=1e-12)
    # the box-constrained minimum: no feasible offset has a lower cost
    big, e_big = icp.step_adjustment(xi, xi_ref, OMEGA, 0.6, 0.0, 1.0, 3.0, 0.05)
    assert float(big[0]) == pytest.approx(0.05)
    cost = lambda d, e: 1.0 * np.sum(d**2) + 3.0 * np.sum((e - d) ** 2)  # noqa: E731
    grid = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 41), np.linspace(-0.05, 0.05, 41)), -1).reshape(-1, 2)
    assert cost(np.asarray(big), np.asarray(e_big)) <= min(cost(g, np.asarray(e_big)) for g in grid) + 1e-12


@pytest.mark.parametrize("t_rem", [0.05, 0.3, 0.6])
def test_the_residual_is_what_an_icp_with_its_cmp_at_the_margin_keeps_at_touchdown(t_rem):
    """Integrate eq. 2 for the error with the CMP offset pushed to the margin toward it (never past zero)."""
    e0, margin = np.array([0.02, -0.004]), np.array([0.03, 0.01])
    _, r = icp.step_adjustment(jnp.asarray(e0), jnp.zeros(2), OMEGA, t_rem, jnp.asarray(margin), 1.0, 1.0, 1.0)
    n = 20000
    dt, e = t_rem / n, e0.copy()
    for _ in range(n):  # the best the CMP can do: d = clip(e / (1 - exp(-omega t_left)), -m, m) nulls e exactly
        e = e + dt * OMEGA * (e - np.sign(e) * margin)
        e = np.where(np.sign(e) != np.sign(e0), 0.0, e)
    np.testing.assert_allclose(r, e, atol=2e-5)
    if t_rem >= 0.3:  # 4 mm lateral error, 1 cm CMP range: nulled given the time, and no step moves for it
        assert float(r[1]) == 0.0
    else:
        assert float(r[1]) < 0.0


def test_gradient_of_the_closed_loop_error_wrt_the_feedback_gain_matches_central_differences():
    p = _plan()

    def err(gain):
        x, v = jnp.array([0.02, -0.05]), jnp.zeros(2)
        dt = 2e-3

        def body(carry, k):
            x, v = carry
            xi_r, xid_r, _ = icp.reference(p, k * dt)
            r = icp.feedback_cmp(icp.capture_point(x, v, OMEGA), xi_r, xid_r, OMEGA, gain)
            v = v + dt * icp.lip_com_acceleration(x, r, OMEGA)
            return (x + dt * v, v), None

        (x, v), _ = jax.lax.scan(body, (x, v), jnp.arange(200))
        return jnp.sum((icp.capture_point(x, v, OMEGA) - icp.reference(p, 0.4)[0]) ** 2)

    g = float(jax.grad(err)(2.0))
    h = 1e-5
    fd = (float(err(2.0 + h)) - float(err(2.0 - h))) / (2 * h)
    assert np.isfinite(g) and g == pytest.approx(fd, rel=1e-5)


@pytest.mark.parametrize("call, name", [
    (lambda: icp.plan(jnp.zeros((1, 2)), 0.1, 0.6, OMEGA, 0.2), "cmp_m"),
    (lambda: icp.plan(jnp.zeros((3, 2)), 0.1, 0.6, -1.0, 0.2), "omega"),
    (lambda: icp.plan(jnp.zeros((3, 2)), 0.1, 0.6, OMEGA, 0.7), "transfer_s"),
    (lambda: icp.plan(jnp.zeros((3, 2)), float("nan"), 0.6, OMEGA, 0.2), "first_switch_s"),
    (lambda: icp.plan(jnp.zeros((3, 2)), 0.1, 0.6, OMEGA, 0.2, split=1.5), "split"),
    (lambda: icp.cmp_height_deviation_m(2.5, 1.0), "stride_m"),
    (lambda: icp.natural_frequency(0.0), "height_m"),
    (lambda: icp.step_cmps(jnp.zeros(2), jnp.zeros((2, 2)), 5), "n_cmps"),
    (lambda: icp.check_gain(0.8), "gain"),
])
def test_bad_input_is_a_value_error_naming_it(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_an_error_within_the_deadband_moves_no_step_and_beyond_it_by_its_excess():
    xi_ref = jnp.zeros(2)
    d0, r0 = icp.step_adjustment(jnp.array([0.02, -0.02]), xi_ref, OMEGA, 0.3, 0.0, 1.0, 1.0, 1.0, deadband_m=0.03)
    assert np.all(np.asarray(d0) == 0.0) and np.all(np.asarray(r0) == 0.0)
    _, r1 = icp.step_adjustment(jnp.array([0.05, -0.04]), xi_ref, OMEGA, 0.3, 0.0, 1.0, 1.0, 1.0, deadband_m=0.03)
    np.testing.assert_allclose(r1, np.exp(OMEGA * 0.3) * np.array([0.02, -0.01]), rtol=1e-12)
