"""qpax's interior-point iteration with a stop, a guard and a regularized, refined factorization
(mjx_coman.wbc.iteration): its steps are qpax's up to rounding, it keeps the best iterate, and it solves float32 QPs
on which qpax.solve_qp and qpax's plain steps break down.

The recorded QPs: data/straight_leg_breakdown_qp.npz, a float32 straight-leg whole-body QP from the batched ``flat``
study at 0.19 m/s, a torque bound active with a multiplier of 3.4e3 against the 1e4 stance-slack weight;
data/straight_leg_failed_qps.npz, 8 float32 QPs of the batched ``toe-off`` and ``flat`` studies of the straight-leg
family that qpax's plain steps (the iteration before the regularized factorization) failed to solve;
data/zero_row_qp.npz, a float32 bent-knee QP of the batched ``flat`` study with a zero equality row (a toe-off foot's
free pitch without its slack column).
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import qpax
import qpsolvers
from qpax.explicit import pdip

from mjx_coman.wbc import iteration
from mjx_coman.wbc.plant import N_BASE
from mjx_coman.wbc.qp import FORCE_SCALE_N, N_SLACK, TORQUE_SCALE_NM
from mjx_coman.wbc.solver import TOLERANCES

DATA = Path(__file__).parent / "data"
N_ACTUATED = 23  # COMAN's actuated joints: the QP's first 2 x 23 inequality rows are its torque bounds


def _load(name, dtype=np.float32):
    d = np.load(DATA / name)
    return [jnp.asarray(d[k], dtype) for k in ("Q", "q", "A", "b", "G", "h")]


def _reference(qp):
    Q, q, A, b, G, h = (np.asarray(a, np.float64) for a in qp)
    return qpsolvers.solve_qp(P=Q, q=q, A=A, b=b, G=G, h=h, solver="proxqp", eps_abs=1e-10, eps_rel=0.0)


def _cost(qp, x):
    Q, q = (np.asarray(a, np.float64) for a in qp[:2])
    x = np.asarray(x, np.float64)
    return 0.5 * x @ Q @ x + q @ x


def _plain(qp):
    """``iteration.solve`` compiled with qpax's own starting point, factorization and solves (no diagonal shift, no
    refinement): the iteration before the regularized factorization."""
    with pytest.MonkeyPatch.context() as mp:  # traced once while patched; a lambda keeps its own jit cache entry
        mp.setattr(iteration, "_initialize", lambda Q, q, A, b, G, h: pdip.initialize(pdip.QPData(Q, q, A, b, G, h)))
        mp.setattr(iteration, "_factorize_kkt", pdip.factorize_kkt)
        mp.setattr(iteration, "_solve_kkt", lambda Q, G, A, s, z, f, v: pdip.solve_kkt_rhs(G, A, s, z, *f, *v))
        return jax.jit(lambda *a: iteration.solve(*a, 1e-6, 20)).lower(*qp).compile()


def test_float32_breakdown_of_qpax_does_not_happen_and_the_solution_is_proxqps():
    qp = _load("straight_leg_breakdown_qp.npz")
    x_qpax = qpax.solve_qp(*qp, solver_tol=1e-12, max_iter=20)[0]
    assert not np.all(np.isfinite(np.asarray(x_qpax)))  # qpax's own loop: non-finite at 20 iterations
    x, s, z, y, conv, k = jax.jit(iteration.solve, static_argnums=(6, 7))(*qp, 1e-6, 20)
    assert np.all(np.isfinite(np.asarray(x)))
    assert float(iteration.kkt_measure(*qp, x, z, y)) < 1e-3  # before the refined factorization: 1.1e-3
    xr = _reference(qp)
    assert np.max(np.abs(np.asarray(x, np.float64) - xr)) < 0.2  # accelerations up to 58
    assert abs(_cost(qp, x) - _cost(qp, xr)) < 1e-4 * abs(_cost(qp, xr))


def _judge(qp, x):
    """The float32 acceptance of mjx_coman.wbc.solver (:data:`TOLERANCES`) in physical units, rows scaled as build_qp
    scales them (dynamics and lifted-foot rows in N, torque rows in N m, force rows in N; stance rows carry slack)."""
    tol = TOLERANCES["float32"]
    Q, q, A, b, G, h = (np.asarray(a, np.float64) for a in qp)
    x = np.asarray(x, np.float64)
    stance = np.any(A[:, Q.shape[0] - N_SLACK:] != 0, axis=1)
    rows = np.arange(len(b))
    eq = np.abs(np.where((rows < N_BASE) | ~stance, FORCE_SCALE_N, 1.0) * (A @ x - b))
    ineq_scale = np.where(np.arange(len(h)) < 2 * N_ACTUATED, TORQUE_SCALE_NM, FORCE_SCALE_N)
    viol = np.max(ineq_scale * (G @ x - h))
    return eq[:N_BASE].max() < tol["eq_dynamics"] and eq[N_BASE:].max() < tol["eq"] and viol < tol["ineq"]


def test_recorded_failed_float32_qps_are_solved_to_proxqps_cost():
    d = np.load(DATA / "straight_leg_failed_qps.npz")
    qps = [[jnp.asarray(d[k][i]) for k in ("Q", "q", "A", "b", "G", "h")] for i in range(len(d["Q"]))]
    solve = jax.jit(iteration.solve, static_argnums=(6, 7))
    plain = _plain(qps[0])
    plain_ok = []
    for qp in qps:
        x, s, z, y, conv, k = solve(*qp, 1e-6, 20)
        assert float(iteration.kkt_measure(*qp, x, z, y)) < 5e-2 and _judge(qp, x)
        xr = _reference(qp)
        assert abs(_cost(qp, x) - _cost(qp, xr)) < 2e-3 * (1 + abs(_cost(qp, xr)))  # measured <= 9e-4 on 150
        xp, _, zp, yp, _, _ = plain(*qp)
        plain_ok.append(bool(np.all(np.isfinite(np.asarray(xp)))) and _judge(qp, xp)
                        and float(iteration.kkt_measure(*qp, xp, zp, yp)) < 5e-2)
    # each was a failed solve with qpax's plain steps where recorded; run apart, rounding saves one or two (1 of 8)
    assert sum(plain_ok) <= 2


def test_a_zero_equality_row_is_solved_where_qpaxs_starting_point_is_not_finite():
    qp = _load("zero_row_qp.npz")
    zero = np.all(np.asarray(qp[2]) == 0, axis=1)
    assert zero.sum() == 1 and float(np.asarray(qp[3])[zero][0]) == 0.0  # one zero row, consistent (b = 0)
    st = pdip.initialize(pdip.QPData(0.5 * (qp[0] + qp[0].T), *qp[1:]))
    assert not np.all(np.isfinite(np.asarray(st.x)))  # F = A H^-1 A' is singular
    x, s, z, y, conv, k = jax.jit(iteration.solve, static_argnums=(6, 7))(*qp, 1e-6, 20)
    assert np.all(np.isfinite(np.asarray(x))) and _judge(qp, x)
    xr = _reference(qp)
    assert abs(_cost(qp, x) - _cost(qp, xr)) < 1e-5 * (1 + abs(_cost(qp, xr)))  # measured 3e-9


def test_a_problem_without_equality_rows_is_solved():
    """No equality rows (footstep MPC's qpax planner: a 0 x 0 Schur complement): min |x - (2, 2)|^2 over
    x1 + x2 <= 1 and x >= 0 is (0.5, 0.5), as proxsuite says."""
    f = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    qp = (jnp.eye(2, dtype=f) * 2, jnp.asarray([-4.0, -4.0], f), jnp.zeros((0, 2), f), jnp.zeros((0,), f),
          jnp.asarray([[1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]], f), jnp.asarray([1.0, 0.0, 0.0], f))
    x, s, z, y, conv, k = jax.jit(iteration.solve, static_argnums=(6, 7))(*qp, 1e-6, 30)
    assert bool(conv) and y.shape == (0,)
    np.testing.assert_allclose(np.asarray(x), [0.5, 0.5], atol=1e-4)
    np.testing.assert_allclose(np.asarray(x), _reference(qp), atol=1e-4)


def test_steps_are_qpaxs_up_to_rounding_and_the_lowest_measure_iterate_is_returned():
    """float64, no stop (tol 0): the result is the lowest-measure one of qpax's own iterates 0..k (the refined
    factorization changes float64 steps only by rounding)."""
    with jax.enable_x64(True):
        qp = _load("straight_leg_breakdown_qp.npz", np.float64)
        for k in (1, 3, 6):
            x, _, z, y, conv, n = iteration.solve(*qp, 0.0, k)
            assert int(n) == k and int(conv) == 0
            cands = []
            for j in range(k + 1):
                if j == 0:
                    st = iteration._initialize(0.5 * (qp[0] + qp[0].T), *qp[1:])
                    xj, zj, yj = st.x, st.z, st.y
                else:
                    xj, _, zj, yj, _, _ = qpax.solve_qp(*qp, solver_tol=1e-300, max_iter=j)
                cands.append((float(iteration.kkt_measure(*qp, xj, zj, yj)), np.asarray(xj)))
            best = min(cands, key=lambda c: c[0])[1]
            np.testing.assert_allclose(np.asarray(x), best, rtol=1e-10, atol=1e-10)


def test_float64_solution_reaches_the_stop_tolerance_and_agrees_with_proxsuite():
    with jax.enable_x64(True):
        qp = _load("straight_leg_breakdown_qp.npz", np.float64)
        x, s, z, y, conv, k = iteration.solve(*qp, 1e-8, 40)  # qpax's sqrt(eps) floor: ~4e-9 at best here
        assert int(conv) == 1 and int(k) < 40
        assert float(iteration.kkt_measure(*qp, x, z, y)) < 1e-8
        np.testing.assert_allclose(np.asarray(x), _reference(qp), atol=1e-3)  # measured 3e-4 (forces, weight 0.027)


def test_kkt_measure_is_small_only_at_the_solution():
    with jax.enable_x64(True):
        qp = _load("straight_leg_breakdown_qp.npz", np.float64)
        x, s, z, y, _, _ = iteration.solve(*qp, 1e-8, 40)
        assert float(iteration.kkt_measure(*qp, x, z, y)) < 1e-8
        for dx in (1e-2, 1e-1):  # a primal step off the solution: stationarity and the equalities see it
            assert float(iteration.kkt_measure(*qp, x + dx, z, y)) > 1e-5
        assert float(iteration.kkt_measure(*qp, x, z + 1.0, y)) > 1e-5  # multipliers off: stationarity and gap
