"""Instantaneous capture point (ICP): planning from constant CMPs, feedback, step adjustment (seed 004).

Pure JAX, horizontal plane (x, y), following the input dtype; vmap for batches; differentiable in every
array argument. ``omega`` (1/s) is a design parameter (seed 004, sec. II-A), not necessarily ``sqrt(g/z)``.

* eq. 1: ``xi = x + xd / omega``; eq. 2: ``xid = omega (xi - r_cmp)``; so the CoM follows
  ``xd = omega (xi - x)`` and the LIP's ``xdd = omega^2 (x - r_cmp)``.
* eq. 3-4: the CMP error of a varying CoM height (:func:`cmp_from_ecmp`, :func:`cmp_height_deviation_m`).
* Planning (seed 004's ref. [21], constant CMPs, exponential ICP segments): with CMPs ``r_0 .. r_{K-1}``,
  ``r_k`` held from the switch time ``s_k`` to ``s_{k+1}`` (``r_0`` from now to ``s_1``, the last one for
  ever), the ICP ends at the final CMP (the robot comes to rest over it) and, backwards,
  ``xi(s_k) = r_k + exp(-omega (s_{k+1} - s_k)) (xi(s_{k+1}) - r_k)``; within segment ``k``
  ``xi(t) = r_k + exp(omega (t - s_{k+1})) (xi(s_{k+1}) - r_k)``. Through a transfer window of
  ``transfer_s`` around each switch (``split`` of it before the switch) the ICP is a cubic Hermite
  segment matching position and velocity at the window's ends, so the reference CMP
  ``r = xi - xid / omega`` moves continuously from one foot to the next during double support.
* Feedback: ``r_cmp = r_ref + gain (xi - xi_ref)`` with ``r_ref = xi_ref - xid_ref / omega``: the ICP error
  obeys ``ed = omega (1 - gain) e``, so it decays for ``gain > 1``.
* Step adjustment (beyond seed 004, for pushes): the ICP error left at touchdown with the CMP held at the
  edge of its range, moved into the next footstep (:func:`step_adjustment`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.params import _check_nonnegative, _check_positive

GRAVITY_MPS2 = 9.81


def natural_frequency(height_m, gravity_mps2=GRAVITY_MPS2) -> jax.Array:
    """``omega = sqrt(g / z)``, 1/s (seed 004, eq. 1)."""
    _check_positive("height_m", height_m)
    _check_positive("gravity_mps2", gravity_mps2)
    return jnp.sqrt(gravity_mps2 / jnp.asarray(height_m))


def capture_point(com_m, com_vel_mps, omega) -> jax.Array:
    """``xi = x + xd / omega`` (seed 004, eq. 1)."""
    return com_m + com_vel_mps / omega


def capture_point_rate(icp_m, cmp_m, omega) -> jax.Array:
    """``xid = omega (xi - r_cmp)`` (seed 004, eq. 2)."""
    return omega * (icp_m - cmp_m)


def lip_com_acceleration(com_m, cmp_m, omega) -> jax.Array:
    """``xdd = omega^2 (x - r_cmp)``: the CoM acceleration of eq. 1-2 (constant ``omega``)."""
    return omega**2 * (com_m - cmp_m)


def cmp_from_ecmp(com_m, ecmp_m, com_height_m, nominal_height_m) -> jax.Array:
    """The CMP that the eCMP corresponds to at CoM height ``z``: ``x - (z / z_nom)(x - r_eCMP)`` (seed 004, eq. 3)."""
    return com_m - com_height_m / nominal_height_m * (com_m - ecmp_m)


def cmp_height_deviation_m(stride_m, nominal_height_m) -> jax.Array:
    """Largest CMP error of a rigid pendulum of length ``z_nom`` at the support exchange of a stride ``l``:
    ``0.5 l (1 - sqrt(z_nom^2 - l^2 / 4) / z_nom)`` (seed 004, eq. 4; 2.7 cm for 1 m and 0.75 m).

    Raises:
        ValueError: a negative stride, a non-positive height, or a stride longer than twice the height.
    """
    _check_nonnegative("stride_m", stride_m)
    _check_positive("nominal_height_m", nominal_height_m)
    if all(isinstance(v, (int, float)) for v in (stride_m, nominal_height_m)) and stride_m > 2 * nominal_height_m:
        raise ValueError(f"stride_m={stride_m} exceeds twice nominal_height_m={nominal_height_m}: the leg cannot reach")
    z = jnp.asarray(nominal_height_m)
    return 0.5 * stride_m * (1.0 - jnp.sqrt(z**2 - 0.25 * stride_m**2) / z)


class Plan(NamedTuple):
    """An ICP plan over constant CMPs (arrays; ``K`` CMPs, static).

    Attributes:
        cmp_m: (K, 2) the CMPs, current first.
        switch_s: (K - 1,) times (from now, s) at which CMP ``k + 1`` takes over from ``k``.
        knot_m: (K - 1, 2) the exponential ICP at each switch time.
        omega: 1/s.
        transfer_s: length of the smoothing window around each switch, s.
        split: fraction of the window before its switch.
    """

    cmp_m: jax.Array
    switch_s: jax.Array
    knot_m: jax.Array
    omega: jax.Array
    transfer_s: jax.Array
    split: jax.Array


def plan(cmp_m, first_switch_s, step_time_s, omega, transfer_s, split=0.5) -> Plan:
    """The ICP plan backwards from the final CMP (module docstring).

    Args:
        cmp_m: (K, 2), K >= 2 (static): the CMP of the current support, then one per planned step; the last
            is where the robot comes to rest (e.g. between its final two feet).
        first_switch_s: time from now to the first switch, s; negative: that switch is past (the current
            segment is then CMP 1, and ``cmp_m[0]`` only shapes the transfer window behind it).
        step_time_s: time between later switches (swing plus transfer), s.
        omega: 1/s.
        transfer_s: smoothing window around each switch, s, shorter than ``step_time_s``.
        split: fraction of ``transfer_s`` before each switch, in [0, 1].

    Raises:
        ValueError: fewer than two CMPs, or a bad time, ``omega`` or ``split``.
    """
    cmp_m = jnp.asarray(cmp_m)
    if cmp_m.ndim != 2 or cmp_m.shape[0] < 2 or cmp_m.shape[1] != 2:
        raise ValueError(f"cmp_m must be (K, 2) with K >= 2, got shape {cmp_m.shape}")
    if isinstance(first_switch_s, (int, float)) and not np.isfinite(first_switch_s):
        raise ValueError(f"first_switch_s={first_switch_s} must be finite")
    _check_positive("step_time_s", step_time_s)
    _check_positive("omega", omega)
    _check_nonnegative("transfer_s", transfer_s)
    _check_nonnegative("split", split)
    if isinstance(split, (int, float)) and split > 1:
        raise ValueError(f"split={split} must be in [0, 1]")
    if all(isinstance(v, (int, float)) for v in (transfer_s, step_time_s)) and transfer_s >= step_time_s:
        raise ValueError(f"transfer_s={transfer_s} must be shorter than step_time_s={step_time_s}")
    dtype = cmp_m.dtype
    k = cmp_m.shape[0]
    switch = first_switch_s + step_time_s * jnp.arange(k - 1, dtype=dtype)
    decay = jnp.exp(-omega * step_time_s)
    knots = [cmp_m[-1]]  # the ICP at the last switch is the final CMP: the robot comes to rest
    for j in range(k - 3, -1, -1):  # xi(s_j) = r_j + exp(-omega T)(xi(s_{j+1}) - r_j), segment j = [s_j, s_{j+1})
        knots.append(cmp_m[j + 1] + decay * (knots[-1] - cmp_m[j + 1]))
    knot = jnp.stack(knots[::-1])
    return Plan(cmp_m, switch, knot, jnp.asarray(omega, dtype), jnp.asarray(transfer_s, dtype),
                jnp.asarray(split, dtype))


def _exponential(p: Plan, t_s):
    """``(xi, xid)`` of the piecewise-exponential plan (no smoothing) at time ``t_s``."""
    k = jnp.sum(t_s >= p.switch_s)  # segment index, 0 .. K-1
    last = k >= p.switch_s.shape[0]
    j = jnp.minimum(k, p.switch_s.shape[0] - 1)
    r = p.cmp_m[k]
    xi = r + jnp.exp(p.omega * jnp.minimum(t_s - p.switch_s[j], 0.0)) * (p.knot_m[j] - r)
    xi = jnp.where(last, p.cmp_m[-1], xi)
    return xi, p.omega * (xi - r)


def reference(p: Plan, t_s):
    """``(xi, xid, r_cmp)`` of the plan at time ``t_s`` (from now), the transfer windows smoothed.

    ``r_cmp = xi - xid / omega`` is the feedforward CMP: the constant CMP of the segment outside the windows,
    moving between the two within them.
    """
    t_s = jnp.asarray(t_s, p.cmp_m.dtype)
    j = jnp.argmin(jnp.abs(t_s - p.switch_s))
    a = p.switch_s[j] - p.split * p.transfer_s
    b = a + p.transfer_s
    inside = (t_s > a) & (t_s < b) & (p.transfer_s > 0)
    xi, xid = _exponential(p, t_s)
    # cubic Hermite between the exponential's ends of the window
    d = jnp.maximum(p.transfer_s, 1e-9)
    p0, v0 = _exponential(p, a)
    p1, v1 = _exponential(p, b)
    u = jnp.clip((t_s - a) / d, 0.0, 1.0)
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    g00, g10, g01, g11 = 6 * u**2 - 6 * u, 3 * u**2 - 4 * u + 1, -6 * u**2 + 6 * u, 3 * u**2 - 2 * u
    xi_h = h00 * p0 + h10 * d * v0 + h01 * p1 + h11 * d * v1
    xid_h = (g00 * p0 + g01 * p1) / d + g10 * v0 + g11 * v1
    xi = jnp.where(inside, xi_h, xi)
    xid = jnp.where(inside, xid_h, xid)
    return xi, xid, xi - xid / p.omega


def feedback_cmp(icp_m, icp_ref_m, icp_ref_rate_mps, omega, gain) -> jax.Array:
    """Desired CMP ``xi_ref - xid_ref / omega + gain (xi - xi_ref)``: the ICP error decays at
    ``omega (gain - 1)`` (module docstring); ``gain`` > 1, dimensionless."""
    return icp_ref_m - icp_ref_rate_mps / omega + gain * (icp_m - icp_ref_m)


def step_adjustment(icp_m, icp_ref_m, omega, time_to_touchdown_s, cmp_margin_m, adjust_weight, icp_weight,
                    max_offset_m, deadband_m=0.0):
    """Footstep offset ``delta`` (2,) for the ICP error the CMP cannot take out before touchdown (beyond seed 004).

    With the CMP ``d`` off the plan's, the ICP error obeys ``ed = omega (e - d)`` (eq. 2), so a constant ``d``
    over the time ``t`` left gives ``e_td = E e - (E - 1) d`` with ``E = exp(omega t)``. The CMP can move at
    most ``cmp_margin_m`` (per axis, in the frame of the arguments: the stance foot's) toward the error, so the
    error left at touchdown is ``r = sign(E e) max(|E e| - (E - 1) m, 0)`` per axis: zero while the CMP can
    null it. Moving the next footstep (and every later one) by ``delta`` moves the plan's ICP at touchdown by
    ``delta``; the offset minimises ``adjust_weight |delta|^2 + icp_weight |r - delta|^2`` subject to
    ``|delta_i| <= max_offset_m``: separable with a diagonal Hessian, so the box-constrained minimum is the
    clipped unconstrained one, ``clip(icp_weight / (adjust_weight + icp_weight) r, -max, max)``. An error
    within ``deadband_m`` (per axis) of the plan counts as none, and beyond it by its excess: a walk's own
    deviation from an idealised plan does not move its steps.

    Returns:
        ``(delta, r)``.
    """
    grow = jnp.exp(omega * jnp.maximum(time_to_touchdown_s, 0.0))
    e = icp_m - icp_ref_m
    e_free = grow * jnp.sign(e) * jnp.maximum(jnp.abs(e) - deadband_m, 0.0)
    residual = jnp.sign(e_free) * jnp.maximum(jnp.abs(e_free) - (grow - 1.0) * cmp_margin_m, 0.0)
    share = icp_weight / (adjust_weight + icp_weight)
    return jnp.clip(share * residual, -max_offset_m, max_offset_m), residual


def step_cmps(stance_xy, footsteps_xy, n_cmps: int) -> jax.Array:
    """CMPs at the current stance foot and each planned footstep, the last one between the final two feet
    (the robot stops there): ``(n_cmps, 2)`` from ``footsteps_xy`` (at least ``n_cmps - 1`` rows).

    Raises:
        ValueError: ``n_cmps < 2`` or too few footsteps.
    """
    footsteps_xy = jnp.asarray(footsteps_xy)
    if n_cmps < 2 or footsteps_xy.shape[0] < n_cmps - 1:
        raise ValueError(f"n_cmps={n_cmps} needs n_cmps >= 2 and at least n_cmps - 1 footsteps, "
                         f"got {footsteps_xy.shape[0]}")
    feet = jnp.concatenate([jnp.asarray(stance_xy)[None], footsteps_xy[: n_cmps - 1]])
    return feet.at[-1].set(0.5 * (feet[-1] + feet[-2]))


def check_gain(gain) -> None:
    """Raise ``ValueError`` if a concrete ICP feedback ``gain`` is not above 1 (the error would not decay)."""
    if isinstance(gain, (int, float, np.floating)) and not (np.isfinite(gain) and gain > 1.0):
        raise ValueError(f"gain={gain} must be finite and above 1: the ICP error decays at omega (gain - 1)")
