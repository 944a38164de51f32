"""The leg state machine of seed 004 (Fig. 5): the privileged knee angle of each leg over the gait.

States, per leg: ``STRAIGHTEN`` (from touchdown, the privileged knee goes linearly from its angle at touchdown
to straight over ``straighten_s``), ``STRAIGHT`` (the rest of stance), ``COLLAPSE`` (from ``collapse_fraction``
of the other leg's swing, and through the transfer, so the leg can leave the ground), ``BENT`` (from lift-off:
the knee escapes the straight singularity), ``EXTEND`` (from ``extend_fraction`` of its swing: straight again,
ready to land). Timing is the controller's fixed step clock; a new step is the touchdown of the leg that swung.
Pure: the state is :class:`LegState` in the controller's state.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

STRAIGHTEN, STRAIGHT, COLLAPSE, BENT, EXTEND = 0, 1, 2, 3, 4
NAMES = ("straighten", "straight", "collapse", "bent", "extend")


class LegState(NamedTuple):
    """Per leg (right, left): state (int32), the time it entered ``STRAIGHTEN`` and its knee angle then."""

    mode: jax.Array
    since_s: jax.Array
    knee0_rad: jax.Array


def init(knee_rad, dtype) -> LegState:
    """Both legs straightening from the crouched stance at time 0 (the start's double support)."""
    return LegState(jnp.full(2, STRAIGHTEN, jnp.int32), jnp.zeros(2, dtype), jnp.full(2, knee_rad, dtype))


def update(legs: LegState, config, *, single, new, stance, t_in, time_s, knee_rad) -> LegState:
    """The next state of each leg (module docstring).

    Args:
        single: after the start; new: a touchdown (the first tick of a step).
        stance: 0 (right) or 1 (left); t_in: time into the step, s; time_s: the clock.
        knee_rad: (2,) the measured knee angles (the start of ``STRAIGHTEN``).
    """
    c = config
    swing_t = t_in - c.transfer_s
    is_stance = jnp.arange(2) == stance
    # the stance leg: straighten at touchdown, straight after straighten_s, collapse late in the other's swing
    stance_mode = jnp.where(legs.mode == STRAIGHTEN,
                            jnp.where(time_s - legs.since_s >= c.straighten_s, STRAIGHT, STRAIGHTEN), legs.mode)
    stance_mode = jnp.where((swing_t >= c.collapse_fraction * c.swing_s) & (stance_mode == STRAIGHT), COLLAPSE,
                            stance_mode)
    # the swing leg: collapsed through the transfer, bent from lift-off, extended late in its swing
    swing_mode = jnp.where(swing_t < 0, COLLAPSE, jnp.where(swing_t < c.extend_fraction * c.swing_s, BENT, EXTEND))
    mode = jnp.where(single, jnp.where(is_stance, stance_mode, swing_mode), stance_mode)
    touchdown = single & new & is_stance
    mode = jnp.where(touchdown, STRAIGHTEN, mode).astype(jnp.int32)
    since = jnp.where(touchdown, time_s, legs.since_s)
    knee0 = jnp.where(touchdown, knee_rad.astype(legs.knee0_rad.dtype), legs.knee0_rad)
    return LegState(mode, since, knee0)


def privileged_knee_rad(legs: LegState, config, time_s) -> jax.Array:
    """(2,) the privileged knee angle of each leg in its state."""
    c = config
    s = jnp.clip((time_s - legs.since_s) / jnp.maximum(c.straighten_s, 1e-6), 0.0, 1.0)
    straighten = legs.knee0_rad + s * (c.straight_knee_rad - legs.knee0_rad)
    table = jnp.stack([jnp.broadcast_to(v, (2,)) for v in (straighten, c.straight_knee_rad, c.collapse_knee_rad,
                                                           c.bent_knee_rad, c.straight_knee_rad)])
    return jnp.take_along_axis(table, legs.mode[None, :], axis=0)[0]
