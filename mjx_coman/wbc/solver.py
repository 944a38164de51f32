"""Solving the whole-body QP with qpax, with its diagnostics, a safe fallback and forward and reverse derivatives.

:func:`qpax_solve` runs qpax's explicit predictor-corrector interior point method (``qpax.explicit.pdip``) by
:func:`mjx_coman.wbc.iteration.solve`: qpax's steps, stopped at a KKT tolerance or at the first non-finite step,
keeping the best iterate (float32 breaks down late on some QPs; see that module). It returns the primal and dual
solution with the convergence flag and the iteration count. Its derivative is a ``jax.custom_jvp``: the implicit-function theorem on the KKT conditions at the solution,

    Q dx + A^T dy + G^T dz = -(dQ x + dq + dA^T y + dG^T z),   A dx = db - dA x,
    G dx + ds = dh - dG x,                                      z ds + s dz = 0,

solved with qpax's own KKT factorization (``factorize_kkt``, that of its Newton steps, turned into dense
inverses so that the tangents meet only products) and the steps of its ``solve_kkt_rhs``, with ``s, z``
floored at eps^(3/4) (qpax's sqrt(eps) floor gave derivatives off by up to 3e-5 relative against central
differences; eps^(3/4): 1e-7). A JVP rule gives forward mode (which this project's walks use) and, being
linear in the tangents, reverse mode by transposition, with one solve and no second call for the diagnostics
(``qpax.solve_qp_primal`` returns only ``x``; its ``custom_vjp`` runs ``solve_qp`` and then ``relax_qp`` to a
KKT point relaxed by ``target_kappa = 1e-3`` and differentiates that smoothed problem). Here the derivative is
the exact one of the solution where the active set does not change; it is zeroed where the solve was not
finite.

Precision. The simulator runs float32, and so can the QP: on standing QPs (double and single support,
binding torque and friction rows) qpax's float32 iterates agree with proxsuite's float64 solution to
~1e-5 (scaled unknowns; ~1e-5 N m in torque) within 8-10 iterations, and the KKT measure reaches ~4e-6
(tests/mjx_coman/wbc/test_wbc_float32.py). A QP is solved in its own dtype; ``float64=True`` solves it in
float64 when x64 is enabled (``jax.config.update("jax_enable_x64", True)`` or ``with jax.enable_x64(True):``)
and casts the result back, tolerances following the solving dtype (:data:`TOLERANCES`).

Batching. On CPU every solve and factorization runs as a loop over the batch (jaxlib 0.10.2's batched CPU
LAPACK kernels deadlock a small thread pool: :func:`mjx_coman.wbc.batching.per_problem`); elsewhere a vmap.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
from qpax.explicit.pdip import factorize_kkt

from mjx_coman.wbc import iteration
from mjx_coman.wbc.batching import per_problem
from mjx_coman.wbc.plant import N_BASE, N_CORNERS, N_FEET, Plant
from mjx_coman.wbc.qp import QP, build_qp
from mjx_coman.wbc.tasks import Task

# per solving dtype: the iteration cap; the KKT measure (:func:`kkt_residual`) at which the iteration stops
# (``stop``) and below which a solve is accepted (``kkt``); then the largest equality residual and inequality
# violation of an accepted solve in physical units (N, N m, m/s^2). The measure is relative stationarity, the
# relative duality gap and the primal residual in the QP's scaled rows. Measured on standing QPs: it falls below 1e-9 in <= 10 iterations in float64, to ~1e-5 in
# ~8 in float32. Float32 stalls above that on some walking ticks with a feasible iterate (wbc-stand-sea: 2e-5 N);
# it accepts 5e-2. In footstep-mpc walks single float32 ticks stall with a bound overshot by 4e-3 to 6e-3 N m,
# which ended the walk as a failed solve: float32 accepts 2e-2 N m / N (0.06 % of the 33 N m stall torque; the
# actuator clips to its limits). Likewise one tick of a 0.2 m/s walk failed with a dynamics residual of 1.34e-3 N,
# float32 round-off on ~300 N of contact force: float32 accepts equality residuals up to 1e-2. In straight-leg
# walks (a torque bound active with a multiplier of ~3e3 against the 1e4 stance-slack weight) the best float32
# iterate before a breakdown (mjx_coman.wbc.iteration) leaves up to 0.72 N in the floating-base dynamics rows
# (median 0.02 N over 1320 such ticks of the batched flat study, contact rows <= 2.3e-3, bounds <= 1.0e-2): an
# error of 0.03 m/s^2 in the predicted base acceleration, not in the torques sent; float32 accepts 1 N there
# (``eq_dynamics``, 0.35 % of COMAN's weight). Float32 stops at 1e-5 (about 80 eps): on a 3 s straight-leg walk
# (0.1 m/s, 1500 ticks) a stop at 1e-6 ran all 20 iterations on 83 % of the ticks for a median measure of
# 4.3e-6 (90th percentile 1.6e-5); a stop at 1e-5 took 8.2 iterations on average, for a median of 6.9e-6 and the
# same 90th and 99th percentiles, in half the time per tick.
TOLERANCES = {"float64": dict(max_iter=15, stop=1e-12, kkt=1e-8, eq=1e-6, eq_dynamics=1e-6, ineq=1e-6),
              "float32": dict(max_iter=12, stop=1e-5, kkt=5e-2, eq=1e-2, eq_dynamics=1.0, ineq=2e-2)}


def stop_tol(dtype) -> float:
    """The KKT measure at which the iteration of a QP in ``dtype`` stops (:data:`TOLERANCES`)."""
    return TOLERANCES["float64" if jnp.dtype(dtype) == jnp.float64 else "float32"]["stop"]


class WbcInfo(NamedTuple):
    """Diagnostics of one solve.

    Attributes:
        iterations: interior-point iterations (int32).
        converged: the KKT measure ``kkt_residual`` is below the dtype's acceptance tolerance.
        kkt_residual: :func:`kkt_residual` of the solution: relative stationarity, duality gap, primal residual.
        eq_residual: largest ``|A x - b|`` in physical units (N, N m for the dynamics; m/s^2, rad/s^2 for
            stance feet; N, N m for the zero wrench of a lifted foot).
        ineq_violation: largest ``max(G x - h, 0)`` in physical units (N m for torques, N for forces).
        ok: converged, both residuals below the dtype's tolerances (:data:`TOLERANCES`), all finite.
    """

    iterations: jax.Array
    converged: jax.Array
    kkt_residual: jax.Array
    eq_residual: jax.Array
    ineq_violation: jax.Array
    ok: jax.Array


class WbcSolution(NamedTuple):
    """``qdd`` (nv,), corner ``forces`` (2, 4, 3) world N, ``tau`` (nu,) N m, and :class:`WbcInfo`."""

    qdd: jax.Array
    forces: jax.Array
    tau: jax.Array
    info: WbcInfo


@functools.partial(jax.custom_jvp, nondiff_argnums=(6, 7))
def qpax_solve(Q, q, A, b, G, h, tol: float, max_iter: int):
    """``(x, s, z, y, converged, iterations)`` of qpax's iteration (:func:`mjx_coman.wbc.iteration.solve`, stopped
    at the KKT measure ``tol``; the last two as floats), differentiable in forward and reverse mode by the
    implicit-function theorem (module docstring)."""

    def one(Q, q, A, b, G, h):
        x, s, z, y, conv, iters = iteration.solve(Q, q, A, b, G, h, tol, max_iter)
        return x, s, z, y, jnp.asarray(conv, Q.dtype), jnp.asarray(iters, Q.dtype)

    return per_problem(one)(Q, q, A, b, G, h)


def _kkt_inverses(Q, G, A, s, z):
    """``(z / s, H^-1, F^-1)`` of qpax's reduced KKT system ``H = Q + G' diag(z / s) G``, ``F = A H^-1 A'``
    (qpax's ``factorize_kkt``), as dense inverses so that the tangent solves are plain products."""
    p_inv, l_h, l_f = factorize_kkt(Q, G, A, s, z)
    h_inv = jax.scipy.linalg.cho_solve(l_h, jnp.eye(Q.shape[0], dtype=Q.dtype))
    f_inv = jax.scipy.linalg.cho_solve(l_f, jnp.eye(A.shape[0], dtype=Q.dtype))
    return p_inv, h_inv, f_inv


@qpax_solve.defjvp
def _qpax_solve_jvp(tol, max_iter, primals, tangents):
    Q, q, A, b, G, h = primals
    dQ, dq, dA, db, dG, dh = tangents
    out = qpax_solve(Q, q, A, b, G, h, tol, max_iter)
    x, s, z, y, conv, iters = out
    floor = jnp.finfo(s.dtype).eps ** 0.75  # only keeps z / s finite (measured: qpax's sqrt(eps) biased it)
    s_f, z_f = jnp.maximum(s, floor), jnp.maximum(z, floor)
    Qs, dQs = 0.5 * (Q + Q.T), 0.5 * (dQ + dQ.T)
    # primal-only factorization (a loop on CPU: per_problem); the tangents see only products, which
    # are linear and transpose for reverse mode; the steps are qpax's solve_kkt_rhs with v2 = 0
    p_inv, h_inv, f_inv = per_problem(_kkt_inverses)(Qs, G, A, s_f, z_f)
    v1 = -(dQs @ x + dq + dA.T @ y + dG.T @ z)
    v3, v4 = dh - dG @ x, db - dA @ x
    p1 = v1 + G.T @ (p_inv * v3)
    dy = f_inv @ (A @ (h_inv @ p1) - v4)
    dx = h_inv @ (p1 - A.T @ dy)
    ds = v3 - G @ dx
    dz = -z_f * ds / s_f
    good = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in (x, s, z, h_inv, f_inv)]))
    zero = lambda t: jnp.where(good, t, jnp.zeros_like(t))  # noqa: E731
    return out, (zero(dx), zero(ds), zero(dz), zero(dy), jnp.zeros_like(conv), jnp.zeros_like(iters))


def solve_dtype(dtype, float64: bool):
    """The dtype a QP of ``dtype`` is solved in: float64 if asked for and x64 is enabled."""
    if float64 and jax.config.read("jax_enable_x64"):
        return jnp.dtype(jnp.float64)
    return jnp.dtype(dtype)


kkt_residual = iteration.kkt_measure  # the measure of WbcInfo: relative stationarity, duality gap, primal residual


def solve_qp(qp: QP, *, float64: bool = False, max_iter: int | None = None, retry_iter: int | None = None):
    """Solve an assembled :class:`~mjx_coman.wbc.qp.QP`: ``(x, info)`` with ``x`` in the QP's dtype.

    The iteration (:mod:`mjx_coman.wbc.iteration`) stops where :func:`kkt_residual` is below the solving dtype's
    ``stop`` tolerance or a step turns non-finite, keeping the iterate with the lowest measure; the solve is
    accepted where that measure is below ``kkt`` and the residuals below ``eq_dynamics`` (the 6 floating-base
    rows), ``eq`` (the contact rows) and ``ineq`` (:data:`TOLERANCES`).
    A failed solve (not converged, residuals above tolerance, or not finite) gives ``info.ok = False`` and ``x``
    with non-finite entries set to zero.

    ``retry_iter`` (static, below ``max_iter``): solve the same QP again stopped after ``retry_iter``
    iterations and take that solution where the full solve failed (its iterate can pass the residual tests
    where the best-measure one does not). Both solves run (a vmap selects), so a retry costs its iterations
    on every problem.

    Args:
        float64: solve in float64 when x64 is enabled (static; see :func:`solve_dtype`).
        max_iter: static iteration cap; by default :data:`TOLERANCES` of the solving dtype.
        retry_iter: static iteration cap of the retry, or ``None`` (no retry).

    Raises:
        ValueError: a ``retry_iter`` that is not a whole number in [1, max_iter).
    """
    dtype = qp.Q.dtype
    sdt = solve_dtype(dtype, float64)
    tols = TOLERANCES["float64" if sdt == jnp.float64 else "float32"]
    n_iter = tols["max_iter"] if max_iter is None else max_iter
    if retry_iter is not None and (isinstance(retry_iter, bool) or not isinstance(retry_iter, int)
                                   or not 1 <= retry_iter < n_iter):
        raise ValueError(f"retry_iter={retry_iter!r} must be a whole number in [1, {n_iter})")
    x, info = _solve_once(qp, sdt, tols, n_iter)
    if retry_iter is None:
        return x, info
    x2, info2 = _solve_once(qp, sdt, tols, retry_iter)
    use_first = info.ok | ~info2.ok
    pick = lambda a, b: jnp.where(use_first, a, b)  # noqa: E731
    return pick(x, x2), jax.tree_util.tree_map(pick, info, info2)


def _solve_once(qp: QP, sdt, tols: dict, max_iter: int):
    """One qpax solve of ``qp`` in ``sdt`` and its diagnostics (:func:`solve_qp`)."""
    dtype = qp.Q.dtype
    Q, q, A, b, G, h = (jnp.asarray(a, sdt) for a in (qp.Q, qp.q, qp.A, qp.b, qp.G, qp.h))
    x, _, z, y, conv, iters = qpax_solve(Q, q, A, b, G, h, tols["stop"], max_iter)
    x_, z_, y_ = (jax.lax.stop_gradient(v) for v in (x, z, y))
    kkt = kkt_residual(Q, q, A, b, G, h, x_, z_, y_)
    eq_rows = jnp.abs(qp.eq_scale.astype(sdt) * (A @ x_ - b))
    eq = jnp.max(eq_rows)
    eq_ok = (jnp.max(eq_rows[:N_BASE]) < tols["eq_dynamics"]) & (jnp.max(eq_rows[N_BASE:]) < tols["eq"])
    viol = jnp.maximum(jnp.max(qp.ineq_scale.astype(sdt) * (G @ x_ - h)), 0.0)
    finite = jnp.all(jnp.isfinite(x_)) & jnp.isfinite(kkt)
    converged = ((jax.lax.stop_gradient(conv) > 0.5) | (kkt < tols["kkt"])) & finite
    ok = converged & eq_ok & (viol < tols["ineq"])
    x = jnp.where(jnp.isfinite(x), x, 0.0).astype(dtype)
    inf = jnp.asarray(jnp.inf, sdt)
    info = WbcInfo(jax.lax.stop_gradient(iters).astype(jnp.int32), converged, jnp.where(finite, kkt, inf).astype(dtype),
                   jnp.where(finite, eq, inf).astype(dtype), jnp.where(finite, viol, inf).astype(dtype), ok)
    return x, info


def fallback_torque(plant: Plant, tau_min_nm, tau_max_nm) -> jax.Array:
    """Joint-space gravity and Coriolis compensation ``(h - passive)[6:]`` clipped to the limits."""
    return jnp.clip((plant.bias - plant.passive)[N_BASE:], tau_min_nm, tau_max_nm)


def solve(plant: Plant, tasks: Sequence[Task], contact_mask, tau_min_nm, tau_max_nm, *, float64: bool = False,
          max_iter: int | None = None, retry_iter: int | None = None, **build_kw) -> WbcSolution:
    """Build (:func:`~mjx_coman.wbc.qp.build_qp`, keywords ``build_kw``) and solve one whole-body QP.

    Returns qdd, corner forces and torques of the solution; where ``info.ok`` is False, the fallback:
    ``qdd = 0``, ``forces = 0``, ``tau =`` :func:`fallback_torque` (finite, within the limits).
    """
    qp = build_qp(plant, tasks, contact_mask, tau_min_nm, tau_max_nm, **build_kw)
    x, info = solve_qp(qp, float64=float64, max_iter=max_iter, retry_iter=retry_iter)
    return solution(qp, x, info, fallback_torque(plant, tau_min_nm, tau_max_nm))


def solution(qp: QP, x, info: WbcInfo, fallback_tau) -> WbcSolution:
    """qdd, forces and torques of ``x``, or the fallback (zero qdd and forces, ``fallback_tau``) if not ok."""
    qdd = qp.qdd_map @ x + qp.qdd_offset
    forces = (qp.force_map @ x).reshape(N_FEET, N_CORNERS, 3)
    tau = qp.tau_map @ x + qp.tau_offset
    ok = info.ok
    return WbcSolution(jnp.where(ok, qdd, 0.0), jnp.where(ok, forces, 0.0), jnp.where(ok, tau, fallback_tau), info)
