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


def footstep_to_attack_angle(adjustment_m, h1, limit_m=None):
    """Truncate a footstep adjustment at ``limit_m`` (default 0.35 ``h1``) and convert it to an attack angle (rad).

    Seed 000, Figure 13: "A truncation of 15 cm ~ 0.35 z is also applied ...
    divided by the 3LP pelvis height z to approximate the equivalent attack
    angle adjustment".
    """
    limit = FOOTSTEP_TRUNCATION_RATIO * h1 if limit_m is None else limit_m
    return truncate(adjustment_m, limit) / h1


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class FilterParams:
    """Constants of the estimation pipeline (tunable by gradient).

    Attributes:
        zeta: IIR constant per tick (0.1 at 2 ms on COMAN).
        deadzone: (4,) dead-zone thresholds of the errors
            ``[swing position (m), pelvis position (m), swing velocity (m/s),
            pelvis velocity (m/s)]``, shared by both axes, or (2, 4): one row
            per axis (sagittal, lateral).
        window_samples: length of the velocity moving average in samples, a
            real number (``None``: the whole ring buffer of :func:`filter_init`,
            30 samples on COMAN). A fractional window weights the oldest sample
            by its fractional part (:func:`window_weights`), so the estimate is
            differentiable in the window and equals the plain moving average at
            whole numbers.
    """

    zeta: jax.Array
    deadzone: jax.Array
    window_samples: jax.Array | None = None


def make_filter_params(zeta: float = 0.1, deadzone=(1e-3, 1e-3, 1e-2, 1e-2),
                       window_samples: float | None = None) -> FilterParams:
    """Validated filter constants. Raises ``ValueError`` naming a bad value."""
    if _is_concrete(zeta):
        z = float(zeta)
        if not 0.0 < z <= 1.0:
            raise ValueError(f"zeta must lie in (0, 1], got {z}")
    if _is_concrete(deadzone):
        dz = np.asarray(deadzone, float)
        if dz.shape not in ((4,), (2, 4)):
            raise ValueError(f"deadzone must have 4 thresholds (or 2 x 4), got shape {dz.shape}")
        _check_positive("deadzone", dz)
    if window_samples is not None:
        if _is_concrete(window_samples) and not float(window_samples) >= 1.0:
            raise ValueError(f"window_samples must be >= 1, got {float(window_samples)}")
        window_samples = jnp.asarray(window_samples, float)
    return FilterParams(zeta=jnp.asarray(zeta, float), deadzone=jnp.asarray(deadzone, float),
                        window_samples=window_samples)


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


def window_weights(window_samples, ages):
    """Weights of a moving average over a real-valued window of samples.

    A sample of age ``k`` (0 the newest) gets ``clip(w - k, 0, 1) / w``: the
    ``floor(w)`` newest samples count fully, the next one by the fractional
    part of ``w``. At whole ``w`` this is the plain ``w``-sample average; in
    between it is piecewise linear in ``w``, so ``jax.grad`` reaches the window.
    ``w`` is clipped to ``[1, len(ages)]``.
    """
    w = jnp.clip(window_samples, 1.0, ages.shape[0])
    return jnp.clip(w - ages, 0.0, 1.0) / w


def filter_step(state: FilterState, observed, zeta, dt_s,
                window_samples=None) -> tuple[FilterState, jax.Array, jax.Array]:
    """One tick of the position IIR, differencing and moving average.

    Args:
        state: filter memory (:func:`filter_init`).
        observed: measured relative positions.
        zeta: IIR constant (eq. 26).
        dt_s: tick, s.
        window_samples: a real-valued averaging window (:func:`window_weights`),
            at most the ring buffer's length; ``None`` averages the whole buffer.

    Returns:
        The new state, the filtered positions and the averaged velocities.
    """
    prev = jnp.where(state.started, state.position, observed)
    pos = iir(prev, observed, zeta)
    diff = (pos - prev) / dt_s
    diffs = state.diffs.at[state.index].set(diff)
    window = state.diffs.shape[0]
    new = FilterState(position=pos, diffs=diffs, index=(state.index + 1) % window, started=jnp.ones((), bool))
    if window_samples is None:
        return new, pos, jnp.mean(diffs, axis=0)
    ages = ((state.index - jnp.arange(window)) % window).astype(diffs.dtype)  # 0: the sample just written
    weights = window_weights(jnp.asarray(window_samples, diffs.dtype), ages)
    return new, pos, jnp.tensordot(weights, diffs, axes=1)


# At a foot swap, relative coordinates (s1 = swing - stance, s2 = pelvis - stance)
# become s1' = -s1 and s2' = s2 - s1; velocities transform alike.
SWAP_RELATIVE = jnp.array([[-1.0, 0.0], [-1.0, 1.0]])


def filter_swap(state: FilterState) -> FilterState:
    """Carry the filter memory through a foot swap, so the swap is no jump for the filter."""
    return state._replace(
        position=state.position @ SWAP_RELATIVE.T,
        diffs=state.diffs @ SWAP_RELATIVE.T,
    )
