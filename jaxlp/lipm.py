"""The linear inverted pendulum of the footstep planner, in closed form.

Seed 001, sec. IV, eq. 3 and 9-13. The CoM moves at the constant height
``z0`` above a point foot ``p_base`` (the stance foot); per horizontal axis
``p'' = (p - p_base) / tau^2`` with ``tau = sqrt(z0 / g)``. The state is
``q = [x, y, vx, vy]`` (m, m/s). Over a time ``dt`` with ``h = exp(dt / tau)``,

    p(dt) = p_base (1 - (h + 1/h)/2) + p0 (h + 1/h)/2 + v0 tau (h - 1/h)/2,
    v(dt) = (p0 - p_base) (h - 1/h) / (2 tau) + v0 (h + 1/h)/2,

that is ``q(dt) = A(dt) q(0) + B(dt) p_base`` (eq. 12-13). Eq. 10 as printed
has ``(-1/h + tau h)/2`` as the coefficient of ``v0``: the factor ``tau`` is
missing on ``1/h`` (dimensionally inconsistent; ``tests/jaxlp/test_lipm.py``
shows that the printed coefficient disagrees with integrating eq. 3).

All functions work elementwise or on single states and follow the input
dtype; batch them with ``jax.vmap``; they are differentiable in every argument.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp.params import _check_positive

GRAVITY_MPS2 = 9.81


def time_constant_s(z0_m, gravity_mps2=GRAVITY_MPS2) -> jax.Array:
    """``tau = sqrt(z0 / g)`` of the pendulum, s (seed 001, eq. 9)."""
    _check_positive("z0_m", z0_m)
    _check_positive("gravity_mps2", gravity_mps2)
    return jnp.sqrt(jnp.asarray(z0_m) / gravity_mps2)


def com_acceleration(com_xy, base_xy, z0_m, gravity_mps2=GRAVITY_MPS2) -> jax.Array:
    """Horizontal CoM acceleration ``g / z0 (p_com - p_base)``, m/s^2 (seed 001, eq. 3)."""
    _check_positive("z0_m", z0_m)
    return gravity_mps2 / jnp.asarray(z0_m) * (jnp.asarray(com_xy) - jnp.asarray(base_xy))


def _hyperbolic(t_s, tau_s):
    """``(cosh(t/tau), sinh(t/tau))``; Python scalars stay weakly typed (the other operands set the dtype)."""
    u = jnp.asarray(t_s) / jnp.asarray(tau_s)
    return jnp.cosh(u), jnp.sinh(u)


def propagate(state, base_xy, t_s, tau_s) -> jax.Array:
    """The state ``[x, y, vx, vy]`` after ``t_s`` on the stance foot ``base_xy`` (seed 001, eq. 9).

    ``p(t) = a e^(-t/tau) + b e^(t/tau) + p_base`` with ``a, b = ((p0 - p_base) -+ tau v0) / 2``,
    written as ``p_base + (p0 - p_base) cosh(t/tau) + tau v0 sinh(t/tau)``.
    """
    _check_positive("tau_s", tau_s)
    c, s = _hyperbolic(t_s, tau_s)
    state, base = jnp.asarray(state), jnp.asarray(base_xy)
    tau = jnp.asarray(tau_s)
    rel, vel = state[:2] - base, state[2:]
    return jnp.concatenate([base + rel * c + tau * vel * s, rel * s / tau + vel * c])


class Transition(NamedTuple):
    """``q(dt) = A q(0) + B p_base`` (seed 001, eq. 12-13)."""

    A: jax.Array  # (4, 4)
    B: jax.Array  # (4, 2)


def transition(dt_s, tau_s) -> Transition:
    """``A(dt)``, ``B(dt)`` of seed 001, eq. 12-13 from eq. 10.

    Seed 001, eq. 10 (corrected: the coefficient of ``v0`` in ``p(dt)`` is ``tau (h - 1/h)/2``;
    printed ``(-1/h + tau h)/2``), with ``(h + 1/h)/2 = cosh(dt/tau)`` and ``(h - 1/h)/2 = sinh(dt/tau)``.
    """
    _check_positive("tau_s", tau_s)
    c, s = _hyperbolic(dt_s, tau_s)
    tau = jnp.asarray(tau_s)
    o, ts, st = jnp.zeros_like(c), tau * s, s / tau

    def matrix(rows):  # stacked, so that weakly typed Python scalars leave the dtype to the state
        return jnp.stack([jnp.stack(row) for row in rows])

    A = matrix([[c, o, ts, o], [o, c, o, ts], [st, o, c, o], [o, st, o, c]])
    B = matrix([[1.0 - c, o], [o, 1.0 - c], [-st, o], [o, -st]])
    return Transition(A=A, B=B)
