"""Pushes on the upper torso: a start, a duration and a world-frame force (arrays; vmappable)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class Push(NamedTuple):
    """A push on the upper torso (arrays; vmappable).

    Attributes:
        start_s: start time from the walk's start, s.
        duration_s: duration, s.
        force_n: (3,) force in the world frame, N.
    """

    start_s: jax.Array
    duration_s: jax.Array
    force_n: jax.Array


def no_push() -> Push:
    """A zero push."""
    return Push(jnp.zeros(()), jnp.zeros(()), jnp.zeros(3))


def make_push(start_s, duration_s=0.1, force_n=None, *, impulse_ns=None, direction_rad=0.0) -> Push:
    """A validated push, from a force vector or an impulse magnitude and heading.

    Args:
        start_s: start time, s (>= 0).
        duration_s: duration, s (> 0).
        force_n: (3,) world-frame force, N; or
        impulse_ns: impulse magnitude ``|F| * duration``, N s (>= 0), applied
            horizontally at ``direction_rad`` (0 forward +x, pi/2 left +y, pi backward).

    Raises:
        ValueError: a negative start, a non-positive duration, a negative
            impulse, a force that is not 3 finite numbers, or both/neither of
            ``force_n`` and ``impulse_ns``.
    """
    if (force_n is None) == (impulse_ns is None):
        raise ValueError("give exactly one of force_n and impulse_ns")
    s, dur = np.asarray(start_s, float), np.asarray(duration_s, float)
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ValueError(f"start_s={s.tolist()} must be finite and non-negative")
    if not np.all(np.isfinite(dur)) or np.any(dur <= 0):
        raise ValueError(f"duration_s={dur.tolist()} must be finite and positive")
    if impulse_ns is not None:
        imp = np.asarray(impulse_ns, float)
        if not np.all(np.isfinite(imp)) or np.any(imp < 0):
            raise ValueError(f"impulse_ns={imp.tolist()} must be finite and non-negative")
        ang = np.asarray(direction_rad, float)
        mag = imp / dur
        force = np.stack([mag * np.cos(ang), mag * np.sin(ang), np.zeros_like(mag * ang)], axis=-1)
    else:
        force = np.asarray(force_n, float)
        if force.shape[-1:] != (3,) or not np.all(np.isfinite(force)):
            raise ValueError(f"force_n={force.tolist()} must be (3,) finite numbers")
    f = jnp.result_type(float)
    return Push(jnp.asarray(s, f), jnp.asarray(dur, f), jnp.asarray(force, f))


def push_force(push: Push, t0, dt):
    """Mean push force over the tick ``[t0, t0 + dt]`` (exact impulse)."""
    overlap = jnp.clip(jnp.minimum(t0 + dt, push.start_s + push.duration_s) - jnp.maximum(t0, push.start_s), 0.0, dt)
    return push.force_n * overlap / dt
