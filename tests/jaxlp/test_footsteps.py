"""The reference footsteps and the footstep MPC of seed 001, sec. IV (eq. 14-16)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import qpsolvers

from jaxlp import footsteps as F, lipm

T, Z0, D, V, N = 0.4, 0.5, 0.07, 0.2, 5  # step time s, CoM height m, half width m, speed m/s, horizon
TAU = float(np.sqrt(Z0 / 9.81))
W = F.default_weights()
plan_jit = jax.jit(F.plan_footsteps, static_argnames=("solver", "qp_solver"))
ref_jit = jax.jit(F.reference_plan, static_argnames=("n_steps",))
qp_jit, cost_jit, predict_jit = jax.jit(F.footstep_qp), jax.jit(F.cost_terms), jax.jit(F.predict_states)


def _plan(turn=0.0, stance=(0.0, 0.0), heading=0.0, sign=1.0, forward=V, lateral=0.0, n=N):
    return ref_jit(jnp.asarray(stance), heading, sign, forward, lateral, turn, T, D, n_steps=n)


def _unit(a):
    return np.array([np.cos(a), np.sin(a)])


def _periodic_state(plan):
    """The start-of-step state of the straight periodic gait on the reference footsteps: the fixed point
    of the 2-step map, ``q[2] = q[0] + (p_des[2] - p_des[0], 0)``."""
    A, B = (np.asarray(a) for a in lipm.transition(T, TAU))
    p = np.asarray(plan.footsteps_m)
    shift = np.concatenate([p[2] - p[0], np.zeros(2)])
    return np.linalg.solve(A @ A - np.eye(4), shift - A @ B @ p[0] - B @ p[1])


# -- reference plan (eq. 14-15) ---------------------------------------------------------------------------


@pytest.mark.parametrize("heading, sign", [(0.0, 1.0), (0.7, -1.0)])
def test_straight_reference_alternates_sides_and_advances_v_dt(heading, sign):
    plan = _plan(stance=(0.3, -0.2), heading=heading, sign=sign)
    fwd, left = _unit(heading), _unit(heading + np.pi / 2)
    rel = np.asarray(plan.footsteps_m) - np.array([0.3, -0.2])
    along, across = rel @ fwd, rel @ left
    np.testing.assert_allclose(along, V * T * np.arange(N + 1), atol=1e-15)
    # right support (s = +1): the next foot is the left one, 2d to the left; then back
    np.testing.assert_allclose(across, sign * 2 * D * (np.arange(N + 1) % 2), atol=1e-15)
    mid = np.asarray(plan.midpoints_m) - np.array([0.3, -0.2])
    np.testing.assert_allclose(mid @ left, sign * D * np.ones(N + 1), atol=1e-15)
    np.testing.assert_allclose(np.asarray(plan.heading_rad), heading * np.ones(N + 1), atol=1e-15)
    np.testing.assert_allclose(np.asarray(plan.com_vel_mps), np.tile(V * fwd, (N + 1, 1)), atol=1e-15)


def test_turning_reference_keeps_feet_beside_the_path():
    w = 0.3
    plan = _plan(turn=w, heading=0.2)
    theta, mid, feet = (np.asarray(a) for a in (plan.heading_rad, plan.midpoints_m, plan.footsteps_m))
    np.testing.assert_allclose(np.diff(theta), w * T, atol=1e-15)
    # the midpoint advances v dt along the previous heading (the printed "+ theta" dropped)
    np.testing.assert_allclose(np.diff(mid, axis=0), V * T * np.stack([_unit(a) for a in theta[:-1]]), atol=1e-15)
    off = feet - mid
    np.testing.assert_allclose(np.linalg.norm(off, axis=1), D, atol=1e-15)
    np.testing.assert_allclose(np.einsum("ij,ij->i", off, np.stack([_unit(a) for a in theta])), 0.0, atol=1e-15)
    # the printed theta[0] leaves the later feet off the perpendicular of the path
    printed = mid + D * np.stack([_unit(theta[0] - (-1.0) ** i * np.pi / 2) for i in range(N + 1)])
    assert np.linalg.norm(printed[N] - feet[N]) > 0.02
    np.testing.assert_allclose(np.asarray(plan.com_vel_mps), V * np.stack([_unit(a) for a in theta]), atol=1e-15)
    straight = _plan(heading=0.2)
    printed0 = np.asarray(straight.midpoints_m) + D * np.stack([_unit(0.2 - (-1.0) ** i * np.pi / 2)
                                                               for i in range(N + 1)])
    np.testing.assert_allclose(printed0, np.asarray(straight.footsteps_m), atol=1e-15)


def _free_com_residual(plan):
    """The least ``Q_q`` and ``Q_dq`` residual of eq. 16 over free CoM positions ``q_p[1..N+1]`` (no dynamics)."""
    m, v = np.asarray(plan.midpoints_m)[1:], np.asarray(plan.com_vel_mps)[1:]
    rows = np.zeros((2 * N, N + 1))
    for i in range(N):
        rows[i, [i, i + 1]] = 1.0, 1.0  # q_p[i+1] + q_p[i] = 2 m[i]
        rows[N + i, [i, i + 1]] = -1.0, 1.0  # q_p[i+1] - q_p[i] = dt v[i]
    rhs = np.concatenate([2 * m, T * v])
    sol = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    return np.linalg.norm(rows @ sol - rhs)


def test_the_printed_double_stride_is_inconsistent_with_the_cost():
    """With ``dx = 2 v dt`` no CoM path zeroes the CoM terms of eq. 16, and the feet ask for 2 v."""
    assert _free_com_residual(_plan()) < 1e-12
    doubled = _plan(forward=2 * V)._replace(com_vel_mps=_plan().com_vel_mps)
    assert _free_com_residual(doubled) > 0.05
    assert float(doubled.footsteps_m[2, 0] - doubled.footsteps_m[0, 0]) / (2 * T) == pytest.approx(2 * V)


# -- the MPC (eq. 16) ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("elapsed_s", [0.0, 0.15])
def test_steady_gait_has_zero_cost_and_the_mpc_returns_the_reference(elapsed_s):
    plan = _plan()
    stance = plan.footsteps_m[0]
    q = np.asarray(lipm.propagate(_periodic_state(plan), stance, elapsed_s, TAU))
    terms = cost_jit(q, stance, T - elapsed_s, plan.footsteps_m[1:], plan, T, TAU)
    for name, value in terms._asdict().items():
        assert np.sqrt(float(value)) < 1e-9, name
    sol = plan_jit(q, stance, T - elapsed_s, plan, W, T, TAU)
    np.testing.assert_allclose(np.asarray(sol.footsteps_m), np.asarray(plan.footsteps_m[1:]), atol=1e-9)
    assert bool(sol.ok) and abs(float(sol.cost)) < 1e-16
    # the periodic gait: CoM at the midline at each switch, the sagittal swing symmetric about the foot
    np.testing.assert_allclose(np.asarray(sol.states[:, 1]), D, atol=1e-9)
    np.testing.assert_allclose(np.asarray(sol.states[1:, 0] - sol.footsteps_m[:, 0]), V * T / 2, atol=1e-9)


def test_the_qp_is_eq16_in_the_dcm_coordinates():
    """The condensed QP's cost and footsteps agree with eq. 16 evaluated through A, B (eq. 12-13)."""
    plan = _plan(turn=0.3)
    q = np.array([0.02, 0.05, 0.3, -0.1])
    qp = qp_jit(q, plan.footsteps_m[0], 0.25, plan, W, T, TAU, 0.15)
    assert np.linalg.cond(np.asarray(qp.H)) < 1e3
    for x in np.random.default_rng(1).normal(size=(3, 2 * N)) * 0.3:
        feet = (qp.F @ x + qp.f).reshape(N, 2)
        terms = cost_jit(q, plan.footsteps_m[0], 0.25, feet, plan, T, TAU)
        cost = sum(w * t for w, t in zip(W, terms))
        assert float(x @ qp.H @ x + 2 * qp.g @ x + qp.c) == pytest.approx(float(cost), rel=1e-10)
        states = predict_jit(q, plan.footsteps_m[0], 0.25, feet, T, TAU)
        pos = np.asarray(states[:, :2])
        offsets = np.concatenate([(pos[:-1] - feet).ravel(), (pos[1:] - feet).ravel()])
        np.testing.assert_allclose(np.asarray(qp.G @ x - qp.h), np.concatenate([offsets, -offsets]) - 0.15, atol=1e-12)


def _pushed(kick):
    plan = _plan()
    return plan, _periodic_state(plan) + np.array([0.0, 0.0, *kick])


def test_qpax_equals_the_closed_form_when_the_bound_is_inactive():
    for kick in [(0.1, 0.0), (0.0, -0.2), (-0.1, 0.05)]:
        plan, q = _pushed(kick)
        a = plan_jit(q, plan.footsteps_m[0], T, plan, W, T, TAU)
        b = plan_jit(q, plan.footsteps_m[0], T, plan, W, T, TAU, max_com_offset_m=0.15, solver="qpax")
        assert bool(b.ok) and int(b.iterations) > 0
        np.testing.assert_allclose(np.asarray(b.footsteps_m), np.asarray(a.footsteps_m), atol=1e-6)
        assert float(b.cost) == pytest.approx(float(a.cost), rel=1e-6)


@pytest.mark.parametrize("bound, kick", [(0.12, (0.0, 0.1)), (0.12, (0.15, 0.15)), (0.15, (0.2, 0.0))])
def test_qpax_matches_proxsuite_and_the_kkt_conditions_when_the_bound_binds(bound, kick):
    plan, q = _pushed(kick)
    sol = plan_jit(q, plan.footsteps_m[0], T, plan, W, T, TAU, max_com_offset_m=bound, solver="qpax")
    free = plan_jit(q, plan.footsteps_m[0], T, plan, W, T, TAU)
    qp = qp_jit(q, plan.footsteps_m[0], T, plan, W, T, TAU, bound)
    H, g, G, h = (np.asarray(a) for a in (qp.H, qp.g, qp.G, qp.h))
    ref = qpsolvers.solve_qp(H, g, G, h, solver="proxqp", eps_abs=1e-12, eps_rel=0.0)
    x = np.linalg.solve(np.asarray(qp.F), np.asarray(sol.footsteps_m).ravel() - np.asarray(qp.f))
    assert bool(sol.ok)
    np.testing.assert_allclose(x, ref, atol=1e-6)
    assert np.max(np.abs(np.asarray(sol.footsteps_m - free.footsteps_m))) > 0.01  # the bound changed the plan
    assert float(sol.cost) > float(free.cost)
    # KKT: feasible, and the gradient is a non-negative combination of the active rows' normals
    slack = h - G @ x
    assert slack.min() > -1e-9
    active = slack < 1e-7
    assert active.any()
    z, *_ = np.linalg.lstsq(G[active].T, -(H @ x + g), rcond=None)
    assert z.min() > 0.0
    np.testing.assert_allclose(H @ x + g + G[active].T @ z, 0.0, atol=1e-7)
    states, feet = np.asarray(sol.states), np.asarray(sol.footsteps_m)
    assert np.abs(states[1:, :2] - feet).max() <= bound + 1e-9 and np.abs(states[:-1, :2] - feet).max() <= bound + 1e-9


def test_a_push_moves_the_first_footstep_in_its_direction():
    plan, q0 = _pushed((0.0, 0.0))
    base = np.asarray(plan_jit(q0, plan.footsteps_m[0], 0.2, plan, W, T, TAU).footsteps_m[0])
    for axis in (0, 1):
        for sign in (1.0, -1.0):
            q = q0.copy()
            q[2 + axis] += sign * 0.2
            step = np.asarray(plan_jit(q, plan.footsteps_m[0], 0.2, plan, W, T, TAU).footsteps_m[0])
            assert sign * (step - base)[axis] > 0.02
            assert abs((step - base)[1 - axis]) < 0.5 * abs((step - base)[axis])


@jax.jit
def _closed_loop_step(state, stance, heading, sign, turn):
    plan = F.reference_plan(stance, heading, sign, V, 0.0, turn, T, D, N)
    foot = F.plan_footsteps(state, stance, T, plan, W, T, TAU).footsteps_m[0]
    return lipm.propagate(state, stance, T, TAU), foot


def _walk(state, turn, steps):
    stance, heading, sign, out = jnp.zeros(2), 0.0, 1.0, []
    for _ in range(steps):
        state, foot = _closed_loop_step(state, stance, heading, sign, turn)
        out.append((np.asarray(state), np.asarray(foot), heading))
        stance, heading, sign = foot, heading + turn * T, -sign
    return out


def _local(state, foot, heading, k):
    """The state relative to its stance foot in the heading frame, mirrored on every other step."""
    c, s = np.cos(heading), np.sin(heading)
    rot = np.array([[c, s], [-s, c]])
    return np.concatenate([rot @ (state[:2] - foot), rot @ state[2:]]) * np.array([1, (-1) ** k, 1, (-1) ** k])


def _feet_local(walk, turn):
    """Each footstep relative to the previous one in the heading frame of the previous step."""
    prev, out = np.zeros(2), []
    for _, foot, heading in walk:
        c, s = np.cos(heading), np.sin(heading)
        out.append(np.array([[c, s], [-s, c]]) @ (foot - prev))
        prev = foot
    return np.array(out)


def test_closed_loop_converges_to_the_reference_gait():
    """Replanning from the measured state each step, a pushed LIPM returns to the periodic gait (relative
    to its feet: the reference is replanned from the stance foot, so a push may shift the path)."""
    nominal = _periodic_state(_plan())
    walk = _walk(nominal + np.array([0.02, -0.01, 0.15, 0.1]), 0.0, 11)
    local = np.array([_local(st, ft, hd, k) for k, (st, ft, hd) in enumerate(walk)])
    error = np.abs(local - _local(nominal, np.zeros(2), 0.0, 1)).max(axis=1)
    assert error[0] > 0.1
    assert error[5] < 0.02 and error[10] < 1e-3
    assert np.all(error[4:] / error[3:-1] < 0.6)  # contracting, 0.44 per step with the default weights
    steps = _feet_local(walk, 0.0)
    assert np.abs(steps[0] - [V * T, 2 * D]).max() > 0.1  # the push made a first correction
    np.testing.assert_allclose(np.abs(steps[5:]), np.tile([V * T, 2 * D], (6, 1)), atol=0.01)
    np.testing.assert_allclose(np.abs(steps[10]), [V * T, 2 * D], atol=3e-4)


def test_closed_loop_converges_while_turning():
    turn = 0.3
    walk = _walk(np.array([-0.03, 0.09, 0.35, -0.05]), turn, 17)
    local = np.array([_local(st, ft, hd + turn * T, k) for k, (st, ft, hd) in enumerate(walk)])
    assert np.abs(local[3] - local[1]).max() > 1e-2
    np.testing.assert_allclose(local[16], local[14], atol=2e-5)  # a two-step gait in the turning frame
    np.testing.assert_allclose(local[15], local[13], atol=2e-5)
    steps = _feet_local(walk, turn)
    assert np.mean(steps[-2:, 0]) == pytest.approx(V * T, rel=0.02)  # the commanded speed on average
    np.testing.assert_allclose(np.abs(steps[-2:, 1]), 2 * D, rtol=0.02)
    outer = steps[-2:][steps[-2:, 1] < 0, 0]  # turning left, the right foot is the outer one
    inner = steps[-2:][steps[-2:, 1] > 0, 0]
    assert outer[0] > inner[0] + 0.01  # and takes the longer step (seed 001, sec. V.A)


def test_vmap_of_64_problems_equals_the_loop():
    rng = np.random.default_rng(2)
    plan = _plan(turn=0.2)
    states = _periodic_state(_plan()) + rng.normal(size=(64, 4)) * np.array([0.01, 0.01, 0.1, 0.1])
    remaining = rng.uniform(0.05, T, 64)
    for solver, extra in (("closed-form", {}), ("qpax", {"max_com_offset_m": 0.15})):
        batched = jax.jit(jax.vmap(lambda q, r: F.plan_footsteps(q, plan.footsteps_m[0], r, plan, W, T, TAU,
                                                                 solver=solver, **extra)))(states, remaining)
        for k in range(0, 64, 7 if solver == "qpax" else 1):
            one = plan_jit(states[k], plan.footsteps_m[0], float(remaining[k]), plan, W, T, TAU, solver=solver, **extra)
            np.testing.assert_allclose(np.asarray(batched.footsteps_m[k]), np.asarray(one.footsteps_m), atol=1e-12)
            assert bool(batched.ok[k]) == bool(one.ok)


def test_gradient_of_the_first_footstep_wrt_a_weight():
    plan, q = _pushed((0.2, -0.1))

    def first(w_com_step, w_footstep):
        w = W._replace(com_step=w_com_step, footstep=w_footstep)
        return F.plan_footsteps(q, plan.footsteps_m[0], 0.3, plan, w, T, TAU).footsteps_m[0]

    jac = jax.jit(jax.jacrev(first, argnums=(0, 1)))(10.0, 1.0)
    first = jax.jit(first)
    eps = 1e-5
    for k, (plus, minus) in enumerate([((10.0 + eps, 1.0), (10.0 - eps, 1.0)), ((10.0, 1.0 + eps), (10.0, 1.0 - eps))]):
        fd = (np.asarray(first(*plus)) - np.asarray(first(*minus))) / (2 * eps)
        assert np.abs(fd).max() > 1e-4
        np.testing.assert_allclose(np.asarray(jac[k]), fd, rtol=1e-6, atol=1e-10)


def test_float32_follows_and_agrees_with_float64():
    plan, q = _pushed((0.15, -0.1))
    ref = plan_jit(q, plan.footsteps_m[0], 0.3, plan, W, T, TAU)
    plan32 = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32), plan)
    sol = plan_jit(jnp.asarray(q, jnp.float32), plan32.footsteps_m[0], 0.3, plan32, W, T, TAU)
    assert sol.footsteps_m.dtype == sol.states.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(sol.footsteps_m), np.asarray(ref.footsteps_m), atol=2e-6)


def test_validation():
    plan = _plan()
    q = _periodic_state(plan)
    with pytest.raises(ValueError, match="n_steps must be an integer >= 1, got 0"):
        F.reference_plan(jnp.zeros(2), 0.0, 1.0, V, 0.0, 0.0, T, D, 0)
    with pytest.raises(ValueError, match=r"step_time_s must be finite and positive, got 0.0"):
        F.reference_plan(jnp.zeros(2), 0.0, 1.0, V, 0.0, 0.0, 0.0, D, N)
    with pytest.raises(ValueError, match=r"step_time_s must be finite and positive, got -0.4"):
        F.plan_footsteps(q, plan.footsteps_m[0], T, plan, W, -0.4, TAU)
    with pytest.raises(ValueError, match=r"tau_s must be finite and positive, got 0.0"):
        F.plan_footsteps(q, plan.footsteps_m[0], T, plan, W, T, 0.0)
    with pytest.raises(ValueError, match=r"unknown solver 'osqp'"):
        F.plan_footsteps(q, plan.footsteps_m[0], T, plan, W, T, TAU, solver="osqp")
    with pytest.raises(ValueError, match=r"solver 'qpax' needs max_com_offset_m .* got None"):
        F.plan_footsteps(q, plan.footsteps_m[0], T, plan, W, T, TAU, solver="qpax")
