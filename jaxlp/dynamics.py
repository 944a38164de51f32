"""3LP single-support dynamics: balance equations and closed-form transitions.

Per horizontal axis the state is ``x = [s, p, a]`` (swing foot, pelvis, stance
foot) and ``q = [x, x_dot]``. The axis is ``lateral=False`` (sagittal, x) or
``lateral=True`` (y), where the hips sit at ``p +/- d*pw`` (``d = +1/-1`` the
phase sign: the swing hip at ``p + d*pw``). Inputs: the swing-hip torque
``tau`` (pelvis on swing leg, positive about +y so that a negative torque
swings the leg forward), the stance-ankle torque, and a horizontal push on the
torso CoM.

Sign convention: the balance equations use ``tau_m = r_z f_h - r_h f_z`` for
moments on both axes (the +y component in the sagittal plane, the -x one in
the lateral plane) and a leg angle ``(hip - foot)/h1``; the input torques are
reported about +y (sagittal) and +x (lateral), as in the brief's check values.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import expm

from jaxlp.params import ThreeLPParams

# Augmented state of the closed form (seed 000, eq. 4-5): positions, velocities,
# then the inputs that evolve linearly in time.
N_Q = 6  # s, p, a, s_dot, p_dot, a_dot
IDX_TAU, IDX_TAU_RATE, IDX_ANKLE, IDX_ANKLE_RATE, IDX_PUSH, IDX_D = range(6, 12)
N_AUG = 12


class AxisDynamics(NamedTuple):
    """``x_ddot = Cx x + Cu tau + Ca ankle + Cf push + Cd d`` (seed 000, eq. 2)."""

    Cx: jax.Array  # (3, 3)
    Cu: jax.Array  # (3,)
    Ca: jax.Array  # (3,)
    Cf: jax.Array  # (3,)
    Cd: jax.Array  # (3,)


def axis_dynamics(params: ThreeLPParams, lateral: bool) -> AxisDynamics:
    """Solve the 3LP balance equations of one axis (brief section 2).

    The vertical equations decouple and give the vertical joint forces
    (``f1z = m1 g``, ``f2z = m2 g``, ``f3z = -(m1+m2) g``, ``F3z = (m1+2m2) g``);
    the remaining eight horizontal and moment equations are linear in
    ``[p_ddot, s_ddot, f1, f2, f3, F3, t1, t3]`` and are solved numerically,
    one right-hand side per state, input and the phase sign.

    Args:
        params: 3LP parameters.
        lateral: the lateral axis (pelvis-width terms) or the sagittal one.

    Returns:
        The coefficient matrices of seed 000, eq. 2 for this axis.
    """
    m1, m2, h1, h2, h3, I2, g = params.m1, params.m2, params.h1, params.h2, params.h3, params.I2, params.g
    pw = params.pw if lateral else jnp.zeros_like(params.pw)
    k = h2 / h1
    z = jnp.zeros_like(m1)
    one = jnp.ones_like(m1)
    # unknowns: p_dd, s_dd, f1, f2, f3, F3, t1, t3
    lhs = jnp.array(
        [
            [m1, z, -one, z, z, z, z, z],  # torso horizontal
            [z, z, -h3, z, z, z, one, z],  # torso moment (upright)
            [-m2 * (1 - k), -m2 * k, z, one, z, z, z, z],  # swing horizontal
            [-I2 / h1, I2 / h1, z, h2, z, z, z, z],  # swing moment
            [-m2 * (1 - k), z, z, z, one, one, z, z],  # stance horizontal
            [-I2 / h1, z, z, z, h2, -(h1 - h2), z, one],  # stance moment
            [z, z, one, one, one, z, z, z],  # pelvis horizontal
            [z, z, z, z, z, z, one, one],  # pelvis moment
        ]
    )
    g3 = g * (k * (m1 + m2) + (1 - k) * (m1 + 2 * m2))
    # right-hand sides: columns s, p, a, tau, ankle, push, d
    rhs = jnp.array(
        [
            [z, z, z, z, z, one, z],
            [z, z, z, z, z, z, z],
            [z, z, z, z, z, z, z],
            [-k * m2 * g, k * m2 * g, z, -one, z, z, k * m2 * g * pw],
            [z, z, z, z, z, z, z],
            [z, -g3, g3, z, -one, z, pw * g3],
            [z, z, z, z, z, z, z],
            [z, z, z, -one, z, z, pw * g * (m1 + 2 * m2)],
        ]
    )
    sol = jnp.linalg.solve(lhs, rhs)  # (8, 7): rows p_dd, s_dd, ...
    acc = jnp.stack([sol[1], sol[0], jnp.zeros_like(sol[0])])  # rows s_dd, p_dd, a_dd
    # Torques are reported about +y (sagittal) and about +x (lateral); the
    # moment convention above is about -x in the lateral plane.
    torque_sign = -1.0 if lateral else 1.0
    return AxisDynamics(
        Cx=acc[:, 0:3], Cu=torque_sign * acc[:, 3], Ca=torque_sign * acc[:, 4], Cf=acc[:, 5], Cd=acc[:, 6]
    )


def accelerations(
    params: ThreeLPParams, x: jax.Array, tau, ankle, push, d, lateral: bool
) -> jax.Array:
    """``x_ddot`` of one axis for positions ``x = [s, p, a]`` (seed 000, eq. 2)."""
    dyn = axis_dynamics(params, lateral)
    return dyn.Cx @ x + dyn.Cu * tau + dyn.Ca * ankle + dyn.Cf * push + dyn.Cd * d


def generator(params: ThreeLPParams, lateral: bool) -> jax.Array:
    """The 12x12 generator of the augmented linear system of one axis.

    Augmented state: ``q`` (6), hip torque and its rate, ankle torque and its
    rate, push force, phase sign. Torques ramp (``d/dt tau = tau_rate``), the
    push and the sign stay constant, so ``exp(G t)`` is the exact closed form of
    seed 000, eq. 5 for piecewise-linear torques (eq. 4).
    """
    dyn = axis_dynamics(params, lateral)
    G = jnp.zeros((N_AUG, N_AUG), dtype=dyn.Cx.dtype)
    G = G.at[0:3, 3:6].set(jnp.eye(3))
    G = G.at[3:6, 0:3].set(dyn.Cx)
    G = G.at[3:6, IDX_TAU].set(dyn.Cu)
    G = G.at[3:6, IDX_ANKLE].set(dyn.Ca)
    G = G.at[3:6, IDX_PUSH].set(dyn.Cf)
    G = G.at[3:6, IDX_D].set(dyn.Cd)
    G = G.at[IDX_TAU, IDX_TAU_RATE].set(1.0)
    G = G.at[IDX_ANKLE, IDX_ANKLE_RATE].set(1.0)
    return G


def flow(params: ThreeLPParams, t, lateral: bool) -> jax.Array:
    """``exp(G t)``: the augmented state map over a time ``t`` (s)."""
    return expm(generator(params, lateral) * t)


class Transition(NamedTuple):
    """``q(t) = A q(0) + B [u_c, u_r] + Ba [a_c, a_r] + F push + C d`` (seed 000, eq. 5)."""

    A: jax.Array  # (6, 6)
    B: jax.Array  # (6, 2) hip torque constant and rate
    Ba: jax.Array  # (6, 2) ankle torque constant and rate
    F: jax.Array  # (6,) constant push on the torso
    C: jax.Array  # (6,) phase sign


def transition(params: ThreeLPParams, t, lateral: bool) -> Transition:
    """Closed-form transition matrices of one axis at time ``t`` since phase start.

    Implements seed 000, eq. 5 with ``u(t) = u_c + t u_r`` (eq. 4), exactly,
    through one matrix exponential; differentiable in ``params`` and ``t``.
    """
    phi = flow(params, t, lateral)
    top = phi[:N_Q]
    return Transition(
        A=top[:, :N_Q],
        B=top[:, IDX_TAU:IDX_TAU_RATE + 1],
        Ba=top[:, IDX_ANKLE:IDX_ANKLE_RATE + 1],
        F=top[:, IDX_PUSH],
        C=top[:, IDX_D],
    )


def propagate(tr: Transition, q0, u=(0.0, 0.0), d=1.0, ankle=(0.0, 0.0), push=0.0) -> jax.Array:
    """Apply a :class:`Transition` to an initial state and inputs."""
    return tr.A @ q0 + tr.B @ jnp.asarray(u) + tr.Ba @ jnp.asarray(ankle) + tr.F * push + tr.C * d
