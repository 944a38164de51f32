"""Periodic 3LP gaits (seed 000, eq. 9-10; brief section 4).

A gait is one single-support phase whose end, after the feet swap roles (and
the lateral axis is mirrored), equals its start; both feet are at rest at the
start and at the end. The stance foot sits at the origin of each phase, the
phase sign is ``d = +1`` (swing hip on the +y side).

Per axis the unknowns are the swing-foot and pelvis start positions, the
pelvis start velocity and the hip torque ``u_c + t u_r``; the ankle torque is
zero (compass gait, as in the seed). The sagittal step length is ``v T``. The
lateral step width is either given, or chosen to minimise the lateral hip
torque effort ``integral of u(t)^2`` over the phase (the seed's "minimal hip
torque" choice for the remaining freedom).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.dynamics import N_Q, propagate, transition
from jaxlp.params import ThreeLPParams, _check_positive, _is_concrete

MAX_STEP_LENGTH_RATIO = 0.7  # step length / h1 beyond which the linear model is not trusted
MAX_STEP_WIDTH_RATIO = 1.0  # step width / h1: wider than the hip height is no walking gait
MAX_STEP_TIME_S = 2.0  # a walking step (COMAN 0.4 s, people 0.5-0.7 s); exp(omega T) overflows far beyond


class Gait(NamedTuple):
    """A periodic 3LP gait, per axis (index 0 sagittal, 1 lateral).

    Attributes:
        q0: (2, 6) start state ``[s, p, a, s_dot, p_dot, a_dot]`` per axis, stance foot at 0.
        u: (2, 2) hip torque ``[u_c (N m), u_r (N m/s)]`` per axis.
        step_time_s: phase duration, s.
        speed_mps: mean forward speed, m/s.
        step_width_m: lateral distance between the feet, m.
    """

    q0: jax.Array
    u: jax.Array
    step_time_s: jax.Array
    speed_mps: jax.Array
    step_width_m: jax.Array


def check_feasible(params: ThreeLPParams, step_time_s, speed_mps, step_width_m=None) -> None:
    """Refuse a gait the 3LP cannot design: step time in (0, ``MAX_STEP_TIME_S``], step length at most
    ``MAX_STEP_LENGTH_RATIO`` h1, step width in [0, ``MAX_STEP_WIDTH_RATIO`` h1] (checks on concrete values only).

    Raises:
        ValueError: naming the value and the reason.
    """
    _check_positive("step_time_s", step_time_s)
    if _is_concrete(step_time_s) and np.any(np.asarray(step_time_s, float) > MAX_STEP_TIME_S):
        raise ValueError(f"step_time_s={np.asarray(step_time_s).tolist()} is longer than {MAX_STEP_TIME_S} s: "
                         "no walking gait")
    if step_width_m is not None and _is_concrete(step_width_m):
        w = np.asarray(step_width_m, float)
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"step_width_m must be finite and non-negative, got {w.tolist()}")
        if _is_concrete(params.h1) and np.any(w > MAX_STEP_WIDTH_RATIO * np.asarray(params.h1, float)):
            raise ValueError(f"step_width_m={w.tolist()} is wider than {MAX_STEP_WIDTH_RATIO:g} h1 = "
                             f"{float(np.max(MAX_STEP_WIDTH_RATIO * np.asarray(params.h1, float))):.5g} m: "
                             "infeasible for the 3LP model")
    if _is_concrete(speed_mps) and _is_concrete(step_time_s) and _is_concrete(params.h1):
        v = np.asarray(speed_mps, float)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"speed_mps must be finite, got {v.tolist()}")
        length = np.abs(v) * np.asarray(step_time_s, float)
        limit = MAX_STEP_LENGTH_RATIO * np.asarray(params.h1, float)
        if np.any(length > limit):
            raise ValueError(
                f"speed_mps={v.tolist()} with step_time_s={np.asarray(step_time_s).tolist()} gives a step "
                f"of {length.tolist()} m, longer than {MAX_STEP_LENGTH_RATIO} h1 = {limit.tolist()} m: "
                "infeasible for the 3LP model"
            )


def _periodicity_rows(params: ThreeLPParams, step_time_s, lateral: bool):
    """Linear conditions ``Mrow @ [s0, p0, pd0, u_c, u_r] = rhs`` of periodicity.

    Rows: ``s0 = -sigma s(T)`` (relative swing position mirrored), ``p0 =
    sigma (p(T) - s(T))``, ``pd0 = sigma pd(T)``, ``sd(T) = 0``; ``sigma = -1``
    on the lateral axis (seed 000, eq. 9 with S, M, N, O of eq. 3, 7, 8).
    Also returns the rows of ``s(T)`` for the step-length condition.
    """
    tr = transition(params, step_time_s, lateral)
    sigma = -1.0 if lateral else 1.0
    # q0 = E @ y with y = [s0, p0, pd0]; a0 = sd0 = ad0 = 0
    E = jnp.zeros((N_Q, 3)).at[0, 0].set(1.0).at[1, 1].set(1.0).at[4, 2].set(1.0)
    lin = jnp.concatenate([tr.A @ E, tr.B], axis=1)  # q(T) = lin @ x + C d
    const = tr.C  # times d = +1
    I5 = jnp.eye(5)
    rows = jnp.stack(
        [
            I5[0] + sigma * lin[0],
            I5[1] - sigma * (lin[1] - lin[0]),
            I5[2] - sigma * lin[4],
            lin[3],
        ]
    )
    rhs = jnp.stack(
        [
            -sigma * const[0],
            sigma * (const[1] - const[0]),
            sigma * const[4],
            -const[3],
        ]
    )
    return rows, rhs, lin[0], const[0]


def _state_from(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    q0 = jnp.zeros(N_Q, dtype=x.dtype).at[0].set(x[0]).at[1].set(x[1]).at[4].set(x[2])
    return q0, x[3:5]


def periodic_gait(
    params: ThreeLPParams,
    step_time_s,
    speed_mps,
    step_width_m=None,
) -> Gait:
    """The periodic 3LP gait for a step time and a speed (seed 000, eq. 9).

    Args:
        params: 3LP parameters.
        step_time_s: duration of one single-support phase, s.
        speed_mps: mean forward speed, m/s (step length ``v T``).
        step_width_m: lateral distance between the feet, m; ``None`` chooses the
            width that minimises the lateral hip torque effort.

    Returns:
        The gait, with the stance foot at the origin and ``d = +1``.

    Raises:
        ValueError: a non-positive step time, or a step longer than 0.7 ``h1``.
    """
    check_feasible(params, step_time_s, speed_mps, step_width_m)
    T = jnp.asarray(step_time_s, dtype=jnp.result_type(float))
    v = jnp.asarray(speed_mps, dtype=T.dtype)

    # Sagittal: periodicity plus s(T) = v T.
    rows, rhs, sT_row, sT_const = _periodicity_rows(params, T, lateral=False)
    A = jnp.concatenate([rows, sT_row[None]], axis=0)
    b = jnp.concatenate([rhs, (v * T - sT_const)[None]])
    x_sag = jnp.linalg.solve(A, b)

    rows, rhs, _, _ = _periodicity_rows(params, T, lateral=True)
    if step_width_m is not None:
        W = jnp.asarray(step_width_m, dtype=T.dtype)
        A = jnp.concatenate([rows, jnp.eye(5)[0][None]], axis=0)
        b = jnp.concatenate([rhs, W[None]])
        x_lat = jnp.linalg.solve(A, b)
    else:
        # min integral_0^T (u_c + t u_r)^2 dt subject to periodicity (KKT system).
        H = jnp.zeros((5, 5), dtype=T.dtype)
        H = H.at[3, 3].set(T).at[3, 4].set(T**2 / 2).at[4, 3].set(T**2 / 2).at[4, 4].set(T**3 / 3)
        H = H + 1e-12 * jnp.eye(5)
        kkt = jnp.block([[H, rows.T], [rows, jnp.zeros((4, 4), dtype=T.dtype)]])
        sol = jnp.linalg.solve(kkt, jnp.concatenate([jnp.zeros(5, dtype=T.dtype), rhs]))
        x_lat = sol[:5]
        W = x_lat[0]
    q_sag, u_sag = _state_from(x_sag)
    q_lat, u_lat = _state_from(x_lat)
    return Gait(
        q0=jnp.stack([q_sag, q_lat]),
        u=jnp.stack([u_sag, u_lat]),
        step_time_s=T,
        speed_mps=v,
        step_width_m=W,
    )


def nominal_state(params: ThreeLPParams, gait: Gait, t, d=1.0) -> jax.Array:
    """The nominal state ``q_bar(t)`` of both axes at time ``t`` in a phase (seed 000, eq. 10).

    Args:
        params: 3LP parameters.
        gait: a periodic gait (computed for ``d = +1``).
        t: time since phase start, s.
        d: phase sign; ``-1`` mirrors the lateral axis.

    Returns:
        (2, 6) ``[s, p, a, s_dot, p_dot, a_dot]`` per axis, stance foot at 0.
    """
    sag = propagate(transition(params, t, False), gait.q0[0], gait.u[0], d=1.0)
    lat = propagate(transition(params, t, True), gait.q0[1], gait.u[1], d=1.0)
    return jnp.stack([sag, d * lat])


def nominal_trajectory(params: ThreeLPParams, gait: Gait, n_samples: int = 101) -> tuple[jax.Array, jax.Array]:
    """Samples of ``q_bar(t)`` over a phase: times (n,) and states (n, 2, 6)."""
    ts = jnp.linspace(0.0, 1.0, n_samples) * gait.step_time_s
    qs = jax.vmap(lambda t: nominal_state(params, gait, t))(ts)
    return ts, qs


def hip_torque(gait: Gait, t) -> jax.Array:
    """Nominal swing-hip torque ``u_c + t u_r`` per axis at time ``t`` (N m)."""
    return gait.u[:, 0] + t * gait.u[:, 1]


def lateral_excursion_m(params: ThreeLPParams, gait: Gait, n_samples: int = 201) -> jax.Array:
    """Peak-to-peak lateral pelvis motion over a step (m), relative to the stance foot's line."""
    _, qs = nominal_trajectory(params, gait, n_samples)
    # pelvis lateral position in a fixed frame between the two feet lines
    p = qs[:, 1, 1]
    return jnp.max(p) - jnp.min(p)
