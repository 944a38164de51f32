"""Reference footsteps and the footstep MPC of seed 001, sec. IV (eq. 14-16).

Reference plan (eq. 14-15), ``R(a) = [cos a, sin a]``, ``s = +1`` in right and ``-1`` in left support,
``d`` half the inter-foot distance::

    theta[0] = heading,  p_des[0] = stance foot,  m[0] = p_des[0] + d R(theta[0] + s pi/2)
    theta[i] = theta[i-1] + w dt
    m[i]     = m[i-1] + vx dt R(theta[i-1]) + vy dt R(theta[i-1] + pi/2)
    p_des[i] = m[i] + d R(theta[i] - s (-1)^i pi/2)
    v[i]     = vx R(theta[i]) + vy R(theta[i] + pi/2)

Three departures from the printed text. (1) The stray ``+ theta`` in the line of ``m[i]`` is dropped (it
adds an angle to a position). (2) ``p_des[i]`` uses ``theta[i]`` where the paper prints ``theta[0]``, so
that when turning the feet stay beside the turning path (perpendicular to its heading); the two agree
when not turning. (3) The paper's ``dx = 2 vx dt``, ``dy = 2 vy dt`` are replaced by ``vx dt``, ``vy dt``.
With the paper's factor the cost of eq. 16 cannot vanish on a steady gait: a zero ``Q_q`` term for all
``i`` gives ``q_p[i+2] - q_p[i] = 2 (m[i+1] - m[i])``, a zero ``Q_dq`` term gives ``q_p[i+2] - q_p[i] =
dt (v[i] + v[i+1])``; these agree only if the midpoint advances ``v dt`` per step (the CoM's step average
sits at the stance foot, beside ``m[i]``, and moves at ``v``). With ``2 v dt`` the footsteps would ask for
twice the commanded walking speed. With ``v dt`` the periodic LIPM gait on the reference footsteps makes
every term zero and the MPC returns the reference plan (``tests/jaxlp/test_footsteps.py``).

MPC (eq. 16), ``N`` future steps: ``q[0]`` is the measured CoM state ``[x, y, vx, vy]``, ``p_base[0]``
the current stance foot (fixed), ``q[1] = A(t_rem) q[0] + B(t_rem) p_base[0]`` with the time ``t_rem``
left in the current phase (eq. 12), ``q[i+1] = A q[i] + B p_base[i]`` for ``i >= 1`` with the full step
time (eq. 13). The unknowns are ``p_base[1..N]``; the cost is::

    sum_{i=1..N}   Q_q  |q_p[i+1] + q_p[i] - 2 m[i]|^2 + Q_dq |q_p[i+1] - q_p[i] - dt v[i]|^2
                 + Q_p  |p_base[i] - p_des[i]|^2
  + sum_{i=0..N-1} Q_dp |(p_base[i+1] - p_base[i]) - (p_des[i+1] - p_des[i])|^2

The states are affine in the footsteps: the residuals are condensed to ``r(x) = r0 + J x`` (``J`` by
``jax.jacfwd``, exact for an affine map), a QP with Hessian ``H = sum_k Q_k J_k^T J_k``. Its unknowns
``x`` are the divergent components ``xi = p + tau v`` at the ends of the steps, one-to-one with the
footsteps (:func:`footstep_qp`): in the footsteps themselves ``H`` is ill conditioned (~1e7). The
friction bound of sec. IV (the CoM no farther than ``|mu z0|`` from its stance foot) is imposed per axis
at both ends of every planned step:
``|q_p[i] - p_base[i]| <= bound`` and ``|q_p[i+1] - p_base[i]| <= bound``, ``i = 1..N`` (8 N rows).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import qpax

from jaxlp.lipm import transition
from jaxlp.params import _check_nonnegative, _check_positive

SOLVERS = ("closed-form", "qpax")
# per dtype: qpax's tolerance and iteration cap, and the KKT tolerance (relative) that marks a solve ok
# (measured: float64 agrees with proxsuite to 1e-12 after 15 iterations; its flag never trips at 1e-10)
QPAX_OPTIONS = {"float64": dict(solver_tol=1e-10, max_iter=20, kkt=1e-8),
                "float32": dict(solver_tol=1e-4, max_iter=20, kkt=1e-3)}


def _unit(angle_rad) -> jax.Array:
    """``R(a) = [cos a, sin a]`` along a new last axis."""
    return jnp.stack([jnp.cos(angle_rad), jnp.sin(angle_rad)], axis=-1)


class ReferencePlan(NamedTuple):
    """The reference of seed 001, eq. 14-15, indices ``0..N``."""

    footsteps_m: jax.Array  # (N+1, 2) p_des, p_des[0] = the stance foot
    midpoints_m: jax.Array  # (N+1, 2) m
    heading_rad: jax.Array  # (N+1,) theta
    com_vel_mps: jax.Array  # (N+1, 2) v


def reference_plan(stance_xy, heading_rad, support_sign, forward_mps, lateral_mps, turn_rad_per_s,
                   step_time_s, half_width_m, n_steps: int) -> ReferencePlan:
    """Reference footsteps, midpoints, headings and CoM velocities (seed 001, eq. 14-15; module docstring).

    ``support_sign`` is +1 in right support, -1 in left; the velocities are in the robot's frame; the
    midpoint advances ``(vx, vy) dt`` per step (not the printed ``2 v dt``) and ``p_des[i]`` sits at
    ``d`` from ``m[i]`` perpendicular to ``theta[i]`` (printed: ``theta[0]``). ``n_steps`` is static.
    """
    if not isinstance(n_steps, int) or n_steps < 1:
        raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}")
    _check_positive("step_time_s", step_time_s)
    _check_nonnegative("half_width_m", half_width_m)
    dtype = jnp.result_type(stance_xy, heading_rad, forward_mps, lateral_mps, turn_rad_per_s, step_time_s,
                            half_width_m, float)
    stance = jnp.asarray(stance_xy, dtype)
    i = jnp.arange(n_steps + 1)
    theta = (heading_rad + i.astype(dtype) * (turn_rad_per_s * step_time_s)).astype(dtype)
    stride = step_time_s * (forward_mps * _unit(theta[:-1]) + lateral_mps * _unit(theta[:-1] + jnp.pi / 2))
    m0 = stance + half_width_m * _unit(theta[0] + support_sign * jnp.pi / 2)
    mid = jnp.concatenate([m0[None], m0 + jnp.cumsum(stride, axis=0)]).astype(dtype)
    alternate = jnp.where(i % 2 == 0, 1.0, -1.0).astype(dtype)  # (-1)^i
    feet = mid + half_width_m * _unit(theta - support_sign * alternate * jnp.pi / 2)
    feet = feet.astype(dtype).at[0].set(stance)
    vel = forward_mps * _unit(theta) + lateral_mps * _unit(theta + jnp.pi / 2)
    return ReferencePlan(footsteps_m=feet, midpoints_m=mid, heading_rad=theta, com_vel_mps=vel.astype(dtype))


class MPCWeights(NamedTuple):
    """Scalar weights of eq. 16, 1/m^2 (tunable, differentiable leaves)."""

    com_midpoint: jax.Array  # Q_q
    com_step: jax.Array  # Q_dq
    footstep: jax.Array  # Q_p
    footstep_step: jax.Array  # Q_dp


def default_weights() -> MPCWeights:
    """``Q_q = 1, Q_dq = 10, Q_p = 1, Q_dp = 10`` (the paper weights Q_dq and Q_dp higher); weakly typed.

    Replanned every step, the LIPM then contracts to the periodic gait by 0.44 per step (dt = 0.4 s,
    tau = 0.23 s, N = 5). Measured: a high ``Q_dp`` is what stabilizes; with all weights 1 a mode is
    neutral (1.0) and with ``Q_q = 10`` and the rest 1 the closed loop diverges (1.7 per step).
    """
    return MPCWeights(*(jnp.asarray(w) for w in (1.0, 10.0, 1.0, 10.0)))


class CostTerms(NamedTuple):
    """The unweighted sums of squares of eq. 16, m^2, named as :class:`MPCWeights`."""

    com_midpoint: jax.Array
    com_step: jax.Array
    footstep: jax.Array
    footstep_step: jax.Array


def predict_states(com_state, stance_xy, remaining_s, footsteps_m, step_time_s, tau_s) -> jax.Array:
    """``q[1..N+1]`` (N+1, 4) from ``q[0] = com_state`` and ``p_base[1..N] = footsteps_m`` (seed 001, eq. 12-13)."""
    first, step = transition(remaining_s, tau_s), transition(step_time_s, tau_s)
    q1 = first.A @ com_state + first.B @ stance_xy

    def body(q, p):
        q_next = step.A @ q + step.B @ p
        return q_next, q_next

    _, rest = jax.lax.scan(body, q1, footsteps_m)
    return jnp.concatenate([q1[None], rest])


def _dcm_trajectory(com_state, stance_xy, remaining_s, dcm_m, step_time_s, tau_s):
    """Footsteps ``p_base[1..N]`` and states ``q[1..N+1]`` for the DCMs ``xi[2..N+1]`` (eq. 12-13).

    Eq. 13 in ``xi = p + tau v`` and ``sigma = p - tau v`` per axis: over a step on ``p_base``,
    ``xi' = p_base + h (xi - p_base)`` and ``sigma' = p_base + (sigma - p_base) / h``, ``h = exp(dt / tau)``.
    Given ``xi'``, ``p_base = (h xi - xi') / (h - 1)``; only the contracting ``sigma`` is propagated.
    """
    first = transition(remaining_s, tau_s)
    q1 = first.A @ com_state + first.B @ stance_xy
    tau = jnp.asarray(tau_s)
    growth = jnp.exp(step_time_s / tau)
    xi = jnp.concatenate([(q1[:2] + tau * q1[2:])[None], dcm_m])
    feet = (growth * xi[:-1] - xi[1:]) / (growth - 1.0)

    def body(sigma, p):
        sigma_next = p + (sigma - p) / growth
        return sigma_next, sigma_next

    sigma1 = q1[:2] - tau * q1[2:]
    _, sigma = jax.lax.scan(body, sigma1, feet)
    sigma = jnp.concatenate([sigma1[None], sigma])
    return feet, jnp.concatenate([0.5 * (xi + sigma), 0.5 * (xi - sigma) / tau], axis=1)


def _residuals(states, footsteps_m, stance_xy, plan: ReferencePlan, step_time_s) -> CostTerms:
    """The four residual stacks of eq. 16 (module docstring) for ``q[1..N+1]`` and ``p_base[1..N]``."""
    pos = states[:, :2]
    feet = jnp.concatenate([jnp.asarray(stance_xy)[None], footsteps_m])
    return CostTerms(
        com_midpoint=pos[1:] + pos[:-1] - 2.0 * plan.midpoints_m[1:],
        com_step=pos[1:] - pos[:-1] - step_time_s * plan.com_vel_mps[1:],
        footstep=footsteps_m - plan.footsteps_m[1:],
        footstep_step=jnp.diff(feet, axis=0) - jnp.diff(plan.footsteps_m, axis=0),
    )


def cost_terms(com_state, stance_xy, remaining_s, footsteps_m, plan: ReferencePlan, step_time_s, tau_s) -> CostTerms:
    """Each term of seed 001, eq. 16 for the footsteps ``p_base[1..N]``; the cost is ``sum_k Q_k term_k``."""
    states = predict_states(com_state, stance_xy, remaining_s, footsteps_m, step_time_s, tau_s)
    return CostTerms(*(jnp.sum(r**2) for r in _residuals(states, footsteps_m, stance_xy, plan, step_time_s)))


class FootstepQP(NamedTuple):
    """Eq. 16 as ``min 1/2 x'Hx + g'x  s.t.  Gx <= h`` in the DCMs ``x = vec(xi[2..N+1])``.

    The footsteps are ``vec(p_base[1..N]) = F x + f``; the cost of eq. 16 is ``x'Hx + 2 g'x + c``.
    """

    H: jax.Array  # (2N, 2N)
    g: jax.Array  # (2N,)
    c: jax.Array  # () the cost at x = 0
    G: jax.Array  # (8N, 2N) the friction bound rows (module docstring)
    h: jax.Array  # (8N,)
    F: jax.Array  # (2N, 2N)
    f: jax.Array  # (2N,)


def footstep_qp(com_state, stance_xy, remaining_s, plan: ReferencePlan, weights: MPCWeights, step_time_s, tau_s,
                max_com_offset_m=None) -> FootstepQP:
    """Condense seed 001, eq. 16 into a QP (module docstring); ``None`` bound: no rows (``G`` (0, 2N)).

    The unknowns are the divergent components ``xi = p + tau v`` at the ends of the planned steps, not
    the footsteps: the states then follow from a contracting recursion (``_dcm_trajectory``) instead of
    one that grows as ``exp(N dt / tau)``, and ``H`` stays well conditioned (measured at dt = 0.4 s,
    tau = 0.23 s, N = 5: cond 36 against 1.2e7 in the footsteps; the latter cost float32 3 mm).
    """
    n = plan.footsteps_m.shape[0] - 1
    dtype = jnp.result_type(com_state, stance_xy, plan.footsteps_m, float)
    x0 = jnp.zeros(2 * n, dtype)

    def affine(x):  # residuals, footsteps and CoM-minus-stance-foot offsets at both ends of steps 1..N
        feet, states = _dcm_trajectory(com_state, stance_xy, remaining_s, x.reshape(n, 2), step_time_s, tau_s)
        pos = states[:, :2]
        offsets = jnp.concatenate([(pos[:-1] - feet).ravel(), (pos[1:] - feet).ravel()])
        return _residuals(states, feet, stance_xy, plan, step_time_s), feet.ravel(), offsets

    (r0, f, o0), (J, F, O) = affine(x0), jax.jacfwd(affine)(x0)
    J = [Jk.reshape(-1, 2 * n) for Jk in J]
    H = sum(w * Jk.T @ Jk for w, Jk in zip(weights, J))
    g = sum(w * Jk.T @ rk.ravel() for w, Jk, rk in zip(weights, J, r0))
    c = sum(w * jnp.sum(rk**2) for w, rk in zip(weights, r0))
    if max_com_offset_m is None:
        G, h = jnp.zeros((0, 2 * n), dtype), jnp.zeros((0,), dtype)
    else:
        G, h = jnp.concatenate([O, -O]), jnp.concatenate([max_com_offset_m - o0, max_com_offset_m + o0])
    return FootstepQP(*(jnp.asarray(a, dtype) for a in (H, g, c, G, h, F, f)))


class MPCSolution(NamedTuple):
    """The planned footsteps and the predicted CoM states."""

    footsteps_m: jax.Array  # (N, 2) p_base[1..N]; p_base[1] is the next footstep
    states: jax.Array  # (N+1, 4) q[1..N+1]
    cost: jax.Array  # () eq. 16 at the solution
    ok: jax.Array  # bool: finite (and, for qpax, KKT conditions met)
    iterations: jax.Array  # int32: qpax's iterations, 0 for the closed form


def _per_problem(fn):
    """``fn`` looped over a vmapped batch on CPU, a plain vmap elsewhere: jaxlib's batched CPU LAPACK
    kernels can deadlock a small thread pool (see ``mjx_coman.wbc.batching``)."""
    if jax.default_backend() != "cpu":
        return fn
    return jax.custom_batching.sequential_vmap(fn)


@jax.custom_jvp
def _solve(H, b):
    """``H^-1 b`` (one problem at a time on CPU), differentiable in both modes."""
    return _per_problem(jnp.linalg.solve)(H, b)


@_solve.defjvp
def _solve_jvp(primals, tangents):
    (H, b), (dH, db) = primals, tangents
    x = _solve(H, b)
    H_inv = _per_problem(jnp.linalg.inv)(H)  # primal only: the tangent is a product, transposable
    return x, H_inv @ (db - dH @ x)


def _qpax_default(options):
    def solve(Q, q, A, b, G, h):
        return qpax.solve_qp(Q, q, A, b, G, h, solver_tol=options["solver_tol"], max_iter=options["max_iter"])

    return _per_problem(solve)


def plan_footsteps(com_state, stance_xy, remaining_s, plan: ReferencePlan, weights: MPCWeights, step_time_s, tau_s,
                   *, max_com_offset_m=None, solver: str = "closed-form",
                   qp_solver: Callable | None = None) -> MPCSolution:
    """The footsteps ``p_base[1..N]`` of seed 001, eq. 16 (module docstring) from the measured CoM state.

    Args:
        com_state: ``q[0] = [x, y, vx, vy]`` now, m and m/s.
        stance_xy: the current stance foot ``p_base[0]``.
        remaining_s: time left in the current phase (eq. 12).
        plan: :func:`reference_plan` from this stance foot; ``N`` is its length minus one.
        weights: :class:`MPCWeights`.
        step_time_s, tau_s: the phase duration and the pendulum's time constant.
        max_com_offset_m: the friction bound ``|mu z0|``; used by ``"qpax"`` only (required there).
        solver: ``"closed-form"``, the equality-only problem by one linear solve (the bound ignored), or
            ``"qpax"``, the QP with the bound (static).
        qp_solver: for ``"qpax"``, a function ``(Q, q, A, b, G, h) -> (x, s, z, y, converged, iterations)``
            for ``min 1/2 x'Qx + q'x, Ax = b, Gx <= h`` (the :class:`FootstepQP` in the DCMs ``x``); it
            gets an empty equality block (``A`` of shape ``(0, 2N)``, which qpax 0.1.4 accepts). ``None``: ``qpax.solve_qp`` with :data:`QPAX_OPTIONS`, looped over a vmapped
            batch on CPU; it has no reverse-mode derivative. For derivatives pass a solver with one, e.g.
            ``lambda *qp: mjx_coman.wbc.solver.qpax_solve(*qp, tol, max_iter)`` (jaxlp does not import it).

    Returns:
        An :class:`MPCSolution`; ``footsteps_m[0]`` is the next footstep.
    """
    n = plan.footsteps_m.shape[0] - 1
    if n < 1:
        raise ValueError(f"the plan must have n_steps >= 1, got {n}")
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
    _check_positive("step_time_s", step_time_s)
    _check_positive("tau_s", tau_s)
    _check_nonnegative("remaining_s", remaining_s)
    if solver == "qpax":
        if max_com_offset_m is None:
            raise ValueError("solver 'qpax' needs max_com_offset_m (the friction bound |mu z0|), got None")
        _check_positive("max_com_offset_m", max_com_offset_m)
    bound = max_com_offset_m if solver == "qpax" else None
    qp = footstep_qp(com_state, stance_xy, remaining_s, plan, weights, step_time_s, tau_s, bound)
    dtype = qp.H.dtype
    if solver == "closed-form":
        x = _solve(qp.H, -qp.g)
        ok = jnp.all(jnp.isfinite(x))
        iterations = jnp.zeros((), jnp.int32)
    else:
        options = QPAX_OPTIONS["float64" if dtype == jnp.float64 else "float32"]
        solve = _qpax_default(options) if qp_solver is None else qp_solver
        x, _, z, _, converged, iterations = solve(qp.H, qp.g, jnp.zeros((0, 2 * n), dtype), jnp.zeros((0,), dtype),
                                                  qp.G, qp.h)
        iterations = jnp.asarray(iterations).astype(jnp.int32)
        ok = _kkt_ok(qp, jax.lax.stop_gradient(x), jax.lax.stop_gradient(z), options["kkt"], converged)
    feet, states = _dcm_trajectory(com_state, stance_xy, remaining_s, x.reshape(n, 2), step_time_s, tau_s)
    res = _residuals(states, feet, stance_xy, plan, step_time_s)
    cost = sum(w * jnp.sum(r**2) for w, r in zip(weights, res))  # not x'Hx + 2g'x + c: that cancels to ~1e-9
    return MPCSolution(footsteps_m=feet, states=states, cost=cost, ok=ok, iterations=iterations)


def _kkt_ok(qp: FootstepQP, x, z, tol, converged) -> jax.Array:
    """Finite, feasible and (qpax's flag or) relative stationarity and complementarity below ``tol``."""
    grad = qp.H @ x + qp.g
    scale = 1.0 + jnp.max(jnp.abs(qp.H @ x)) + jnp.max(jnp.abs(qp.g))
    stationarity = jnp.max(jnp.abs(grad + qp.G.T @ z)) / scale
    slack = qp.h - qp.G @ x
    complementarity = jnp.max(jnp.minimum(jnp.maximum(slack, 0.0), jnp.maximum(z, 0.0)))
    feasible = jnp.min(slack) > -tol
    finite = jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(z))
    kkt = (jnp.asarray(converged) > 0) | ((stationarity < tol) & (complementarity < tol))
    return finite & feasible & kkt
