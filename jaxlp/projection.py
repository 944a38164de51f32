"""Continuous time projection and its look-up tables (seed 000, eq. 15-18, Figure 13).

At a time ``t`` of a phase, the measured error ``e(t)`` is projected back to a
virtual phase-start error ``E`` that, with the DLQR correction ``dU = -K E``
applied from the phase start, would have produced ``e(t)``:

    [[A(t), B(t)], [K, I]] [E; dU] = [e(t); 0]        (seed 000, eq. 18)

The correction ``dU = [du_c, du_r]`` is applied from ``t`` on. With no new
disturbance it is the same at every ``t`` of the phase. Being linear in
``e(t)``, it is tabulated over the phase (Figure 13): table A maps the error to
the instantaneous hip torque correction ``du_c + t du_r``; table B maps it to
the adjustment of the final swing-foot position relative to the pelvis, found
by running the corrected 3LP to the end of the phase.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp.control import DLQR, M_ERR, M_HAT, within_phase_map
from jaxlp.dynamics import IDX_TAU, IDX_TAU_RATE, N_Q, flow
from jaxlp.params import ThreeLPParams


def projection_gain(params: ThreeLPParams, ctrl: DLQR, t, lateral: bool = False) -> jax.Array:
    """The (2, 4) matrix ``G(t)`` with ``dU = G(t) e(t)`` (seed 000, eq. 18)."""
    wmap = within_phase_map(params, t, lateral)
    top = jnp.concatenate([wmap.A, wmap.B], axis=1)
    bottom = jnp.concatenate([ctrl.K, jnp.eye(2, dtype=ctrl.K.dtype)], axis=1)
    system = jnp.concatenate([top, bottom], axis=0)  # (6, 6)
    rhs = jnp.concatenate([jnp.eye(4, dtype=ctrl.K.dtype), jnp.zeros((2, 4), dtype=ctrl.K.dtype)], axis=0)
    sol = jnp.linalg.solve(system, rhs)
    return sol[4:6]


def time_projection(params: ThreeLPParams, ctrl: DLQR, t, error, lateral: bool = False) -> jax.Array:
    """The correction ``dU = [du_c (N m), du_r (N m/s)]`` for an error ``e(t)`` (seed 000, eq. 16-18)."""
    return projection_gain(params, ctrl, t, lateral) @ error


def remaining_map(params: ThreeLPParams, t, step_time_s, lateral: bool = False) -> tuple[jax.Array, jax.Array]:
    """Maps of the error and a correction ``dU`` at ``t`` to the state error at the phase end.

    Returns:
        ``(A_rem (6, 4), B_rem (6, 2))``: end-of-phase state deviation (no foot
        swap) from ``e(t)`` and from ``dU`` applied over ``[t, T]`` (the torque
        ramp keeps its clock from the phase start).
    """
    phi = flow(params, step_time_s - t, lateral)
    A_rem = phi[:N_Q, :N_Q] @ M_HAT
    torque_cols = phi[:N_Q, IDX_TAU:IDX_TAU_RATE + 1]  # from [tau(t), tau_rate]
    to_tau = jnp.array([[1.0, t], [0.0, 1.0]], dtype=phi.dtype)  # [du_c, du_r] -> [tau(t), rate]
    return A_rem, torque_cols @ to_tau


FOOT_REL_PELVIS = jnp.array([1.0, -1.0, 0.0, 0.0, 0.0, 0.0])  # s - p


def footstep_gain(params: ThreeLPParams, ctrl: DLQR, t, step_time_s, lateral: bool = False) -> jax.Array:
    """(4,) change of the final swing-foot position relative to the pelvis per unit error at ``t``.

    The error is the current one, the correction the time-projecting one held
    to the phase end (which is what time projection does without new
    disturbances): seed 000, Figure 13 B.
    """
    A_rem, B_rem = remaining_map(params, t, step_time_s, lateral)
    G = projection_gain(params, ctrl, t, lateral)
    return FOOT_REL_PELVIS @ (A_rem + B_rem @ G)


def hip_torque_gain(params: ThreeLPParams, ctrl: DLQR, t, lateral: bool = False) -> jax.Array:
    """(4,) instantaneous hip torque correction ``du_c + t du_r`` per unit error (Figure 13 A)."""
    G = projection_gain(params, ctrl, t, lateral)
    return G[0] + t * G[1]


class GainTable(NamedTuple):
    """Time-projection look-up tables over a phase (seed 000, Figure 13).

    Attributes:
        phase: (n,) phase fractions ``t / T = k / n``, k = 0..n-1 (the phase end,
            where no correction acts any more, is left out).
        projection: (n, 2, 4) ``dU = G e`` per phase sample.
        hip_torque: (n, 4) hip torque correction per unit error (table A), N m per m or per m/s.
        footstep: (n, 4) final swing-foot adjustment per unit error (table B), m per m or per m/s.
    """

    phase: jax.Array
    projection: jax.Array
    hip_torque: jax.Array
    footstep: jax.Array


def gain_table(params: ThreeLPParams, ctrl: DLQR, step_time_s, n_samples: int = 200,
               lateral: bool = False) -> GainTable:
    """Tabulate the time-projection gains at the phases ``k / n_samples`` (``n_samples`` static).

    With ``n_samples`` equal to the control ticks per step, the samples fall
    exactly on the control ticks.
    """
    phase = jnp.arange(n_samples) / n_samples
    ts = phase * step_time_s

    def one(t):
        G = projection_gain(params, ctrl, t, lateral)
        A_rem, B_rem = remaining_map(params, t, step_time_s, lateral)
        foot = FOOT_REL_PELVIS @ (A_rem + B_rem @ G)
        return G, G[0] + t * G[1], foot

    G, hip, foot = jax.vmap(one)(ts)
    return GainTable(phase=phase, projection=G, hip_torque=hip, footstep=foot)


def interpolate(table: GainTable, phase) -> GainTable:
    """Linear interpolation of every table at a phase fraction (held beyond the last sample).

    Returns a :class:`GainTable` whose arrays have lost their sample axis.
    """
    n = table.phase.shape[0]
    x = jnp.clip(phase, 0.0, 1.0) * n
    i0 = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, n - 2)
    w = jnp.clip(x - i0, 0.0, 1.0)

    def lerp(arr):
        return (1.0 - w) * arr[i0] + w * arr[i0 + 1]

    return GainTable(
        phase=jnp.clip(phase, 0.0, 1.0),
        projection=lerp(table.projection),
        hip_torque=lerp(table.hip_torque),
        footstep=lerp(table.footstep),
    )


def footstep_adjustment(table: GainTable, phase, error) -> jax.Array:
    """Final swing-foot adjustment (m) for a filtered error at a phase, from table B."""
    return interpolate(table, phase).footstep @ error


def nominal_error(q, q_nominal) -> jax.Array:
    """The instantaneous error ``e = M (q - q_bar)`` of one axis (seed 000, eq. 15)."""
    return M_ERR @ (q - q_nominal)
