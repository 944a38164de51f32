"""State-estimation filters of seed 000 ("State Estimation", eq. 26-27).

Relative pelvis-foot positions are low-passed by an IIR filter (eq. 26),
velocities are the differences of the filtered positions averaged over a
window of samples (30 on COMAN), and the errors against the nominal gait pass
through smooth dead-zones (eq. 27) whose thresholds are the spread of the
errors in undisturbed walking. The footstep adjustment is truncated at
0.35 ``h1`` (15 cm on COMAN) and divided by ``h1`` to give an attack angle.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.params import _check_positive, _is_concrete

FOOTSTEP_TRUNCATION_RATIO = 0.35  # of h1: 15 cm on COMAN (seed 000, Figure 13)


def iir(previous, observed, zeta):
    """One tick of ``s = (1 - zeta) s_prev + zeta s_obs`` (seed 000, eq. 26)."""
    return (1.0 - zeta) * previous + zeta * observed


def smooth_deadzone(x, threshold):
    """Smooth dead-zone ``y = x - atan(pi x / (2 a)) 2 a / pi`` (seed 000, eq. 27).

    At ``x = a`` it attenuates the input by about 64 %; far from zero it is a
    unit-slope shift by ``a``; it is smooth everywhere (differentiable in ``a``
    too). ``threshold`` must be positive.
    """
    a = threshold
    return x - jnp.arctan(jnp.pi * x / (2.0 * a)) * 2.0 * a / jnp.pi


def truncate(x, limit):
    """Clip ``x`` to ``[-limit, limit]``."""
    return jnp.clip(x, -limit, limit)


def footstep_to_attack_angle(adjustment_m, h1):
    """Truncate a footstep adjustment at 0.35 ``h1`` and convert it to an attack angle (rad).

    Seed 000, Figure 13: "A truncation of 15 cm ~ 0.35 z is also applied ...
    divided by the 3LP pelvis height z to approximate the equivalent attack
    angle adjustment".
    """
    return truncate(adjustment_m, FOOTSTEP_TRUNCATION_RATIO * h1) / h1


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class FilterParams:
    """Constants of the estimation pipeline (tunable by gradient).

    Attributes:
        zeta: IIR constant per tick (0.1 at 2 ms on COMAN).
        deadzone: (4,) dead-zone thresholds of the errors
            ``[swing position (m), pelvis position (m), swing velocity (m/s),
            pelvis velocity (m/s)]``.
    """

    zeta: jax.Array
    deadzone: jax.Array


def make_filter_params(zeta: float = 0.1, deadzone=(1e-3, 1e-3, 1e-2, 1e-2)) -> FilterParams:
    """Validated filter constants. Raises ``ValueError`` naming a bad value."""
    if _is_concrete(zeta):
        z = float(zeta)
        if not 0.0 < z <= 1.0:
            raise ValueError(f"zeta must lie in (0, 1], got {z}")
    dz = np.asarray(deadzone, float)
    if dz.shape != (4,):
        raise ValueError(f"deadzone must have 4 thresholds, got shape {dz.shape}")
    _check_positive("deadzone", dz)
    return FilterParams(zeta=jnp.asarray(zeta, float), deadzone=jnp.asarray(dz))


class FilterState(NamedTuple):
    """Filter memory for relative positions of shape ``(..., 2)`` (swing, pelvis).

    Attributes:
        position: IIR-filtered relative positions.
        diffs: (window, ..., 2) last velocity samples (filtered differences), a ring buffer.
        index: next slot of the ring buffer.
        started: whether ``position`` holds a measurement yet.
    """

    position: jax.Array
    diffs: jax.Array
    index: jax.Array
    started: jax.Array


def filter_init(shape: tuple[int, ...], window: int = 30, dtype=float) -> FilterState:
    """Empty filter for positions of ``shape`` (last axis 2) and a ``window``-sample average."""
    if window < 1:
        raise ValueError(f"window must be >= 1 sample, got {window}")
    return FilterState(
        position=jnp.zeros(shape, dtype),
        diffs=jnp.zeros((window, *shape), dtype),
        index=jnp.zeros((), jnp.int32),
        started=jnp.zeros((), bool),
    )


def filter_step(state: FilterState, observed, zeta, dt_s) -> tuple[FilterState, jax.Array, jax.Array]:
    """One tick of the position IIR, differencing and moving average.

    Returns:
        The new state, the filtered positions and the averaged velocities.
    """
    prev = jnp.where(state.started, state.position, observed)
    pos = iir(prev, observed, zeta)
    diff = (pos - prev) / dt_s
    diffs = state.diffs.at[state.index].set(diff)
    window = state.diffs.shape[0]
    new = FilterState(position=pos, diffs=diffs, index=(state.index + 1) % window, started=jnp.ones((), bool))
    return new, pos, jnp.mean(diffs, axis=0)


# At a foot swap, relative coordinates (s1 = swing - stance, s2 = pelvis - stance)
# become s1' = -s1 and s2' = s2 - s1; velocities transform alike.
SWAP_RELATIVE = jnp.array([[-1.0, 0.0], [-1.0, 1.0]])


def filter_swap(state: FilterState) -> FilterState:
    """Carry the filter memory through a foot swap, so the swap is no jump for the filter."""
    return state._replace(
        position=state.position @ SWAP_RELATIVE.T,
        diffs=state.diffs @ SWAP_RELATIVE.T,
    )
