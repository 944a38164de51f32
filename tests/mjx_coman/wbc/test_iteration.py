"""qpax's interior-point iteration with a stop and a guard (mjx_coman.wbc.iteration): its steps are qpax's, it keeps
the best iterate, and it survives the float32 breakdown of a recorded straight-leg QP that qpax.solve_qp does not.

The recorded QP (data/straight_leg_breakdown_qp.npz): a float32 straight-leg whole-body QP from the batched
``flat`` study at 0.19 m/s, a torque bound active with a multiplier of 3.4e3 against the 1e4 stance-slack weight.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import qpax
import qpsolvers
from qpax.explicit import pdip

from mjx_coman.wbc import iteration

DATA = Path(__file__).parent / "data"


def _load(name, dtype=np.float32):
    d = np.load(DATA / name)
    return [jnp.asarray(d[k], dtype) for k in ("Q", "q", "A", "b", "G", "h")]


def _reference(qp):
    Q, q, A, b, G, h = (np.asarray(a, np.float64) for a in qp)
    return qpsolvers.solve_qp(P=Q, q=q, A=A, b=b, G=G, h=h, solver="proxqp", eps_abs=1e-10, eps_rel=0.0)


def test_float32_breakdown_of_qpax_is_caught_and_the_best_iterate_kept():
    qp = _load("straight_leg_breakdown_qp.npz")
    x_qpax = qpax.solve_qp(*qp, solver_tol=1e-12, max_iter=20)[0]
    assert not np.all(np.isfinite(np.asarray(x_qpax)))  # qpax's own loop: non-finite at 20 iterations
    x, s, z, y, conv, k = jax.jit(iteration.solve, static_argnums=(6, 7))(*qp, 1e-6, 20)
    assert np.all(np.isfinite(np.asarray(x))) and int(k) < 20  # stopped at the first non-finite step
    m = float(iteration.kkt_measure(*qp, x, z, y))
    assert m < 5e-2  # the float32 acceptance tolerance (measured 1.1e-3)
    xr = _reference(qp)
    assert np.max(np.abs(np.asarray(x, np.float64) - xr)) < 0.5  # accelerations up to 58 (measured 0.165)
    Q, q = (np.asarray(a, np.float64) for a in qp[:2])
    cost = lambda v: 0.5 * v @ Q @ v + q @ v  # noqa: E731
    assert abs(cost(np.asarray(x, np.float64)) - cost(xr)) < 1e-3 * abs(cost(xr))


def test_steps_are_qpaxs_and_the_lowest_measure_iterate_is_returned():
    """float64, no stop (tol 0): the result is the lowest-measure one of qpax's own iterates 0..k."""
    with jax.enable_x64(True):
        qp = _load("straight_leg_breakdown_qp.npz", np.float64)
        for k in (1, 3, 6):
            x, _, z, y, conv, n = iteration.solve(*qp, 0.0, k)
            assert int(n) == k and int(conv) == 0
            cands = []
            for j in range(k + 1):
                if j == 0:
                    st = pdip.initialize(pdip.QPData(0.5 * (qp[0] + qp[0].T), *qp[1:]))
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
