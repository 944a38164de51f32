"""Second layer of seed 001 (section III): swing-foot, base and CoM references of one swing phase.

Pure JAX, per step (vmap for batches), differentiable, following the input dtype. Quaternions are
``(w, x, y, z)`` (MuJoCo); angular velocities and accelerations are in world axes. Time ``t_s`` counts from
the start of the swing phase of duration ``duration_s``; outside ``[0, duration_s]`` every profile holds its
end value with zero derivatives. Tracking (``a = a_ff + kp e + kd ed``) is left to the caller
(:func:`mjx_coman.wbc.tasks.position_pd`, :func:`mjx_coman.wbc.tasks.orientation_pd`), except the CoM
height PD of :func:`com_reference_acc`.

Decisions:
    * eq. 8 as printed peaks at ``2 z_cl``; :func:`swing_height` is normalised so that the apex is ``z_cl``:
      ``z = z_cl (3 sin(w t) - sin(3 w t)) / 4 = z_cl sin^3(w t)``, ``w = pi / duration``.
    * :func:`blend` (horizontal swing, height drift, Slerp parameter) is the quintic
      ``s = 10 u^3 - 15 u^4 + 6 u^5``, ``u = t / duration``: zero velocity and acceleration at both ends.
    * Slerp ``q(s) = exp(s r) q0`` with ``r = log(q1 q0^-1)`` (world rotation vector, shortest arc), so the
      world angular velocity is ``sd r`` and the angular acceleration ``sdd r`` (constant axis); this equals
      ``q0 exp(s log(q0^-1 q1))`` with ``r = R(q0) log(q0^-1 q1)``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman.sensors import quat_conj, quat_mul
from mjx_coman.wbc.tasks import position_pd

_SMALL = 1e-12  # squared norm below which log/exp use their series (no 0/0, finite gradients)


# --- time laws -------------------------------------------------------------------------------------------


def swing_height(t_s, duration_s, clearance_m):
    """Swing-foot lift ``(z, zd, zdd)`` of seed 001 eq. 8, normalised to an apex of ``clearance_m``.

    ``z(t) = z_cl (3 sin(w t) - sin(3 w t)) / 4``, ``w = pi / duration`` (eq. 8 divided by 2: as printed it
    peaks at ``2 z_cl``). Zero position, velocity and acceleration at both ends; ``t`` clipped to the step.
    """
    t = jnp.clip(t_s, 0.0, duration_s)
    w = jnp.pi / duration_s
    s1, s3 = jnp.sin(w * t), jnp.sin(3.0 * w * t)
    c1, c3 = jnp.cos(w * t), jnp.cos(3.0 * w * t)
    z = clearance_m * (3.0 * s1 - s3) / 4.0
    zd = clearance_m * w * 3.0 * (c1 - c3) / 4.0
    zdd = clearance_m * w * w * (9.0 * s3 - 3.0 * s1) / 4.0
    return z, zd, zdd


def blend(t_s, duration_s):
    """Quintic 0 -> 1 profile ``(s, sd, sdd)``: ``s = 10 u^3 - 15 u^4 + 6 u^5``, ``u = clip(t / duration, 0, 1)``.

    ``sd = 30 u^2 (1 - u)^2 / T`` and ``sdd = 60 u (1 - u) (1 - 2 u) / T^2`` vanish at both ends.
    """
    u = jnp.clip(t_s / duration_s, 0.0, 1.0)
    s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
    sd = 30.0 * u * u * (1.0 - u) ** 2 / duration_s
    sdd = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / duration_s**2
    return s, sd, sdd


# --- quaternions -----------------------------------------------------------------------------------------


def quat_log(q):
    """Rotation vector ``theta u`` (rad) of the unit quaternion ``q``, taking ``q`` or ``-q`` whichever has
    ``w >= 0`` (the shorter arc, ``theta <= pi``); smooth at the identity."""
    q = jnp.where(q[..., :1] < 0, -q, q)
    w, v = q[..., 0], q[..., 1:]
    n2 = jnp.sum(v * v, axis=-1)
    small = n2 < _SMALL
    n = jnp.sqrt(jnp.where(small, 1.0, n2))
    w_safe = jnp.where(small, w, 1.0)  # w ~ 1 on the series branch
    factor = jnp.where(small, 2.0 / w_safe * (1.0 - n2 / (3.0 * w_safe * w_safe)), 2.0 * jnp.arctan2(n, w) / n)
    return factor[..., None] * v


def quat_exp(r):
    """Unit quaternion of the rotation vector ``r`` (rad): ``(cos(|r|/2), sin(|r|/2) r / |r|)``."""
    t2 = jnp.sum(r * r, axis=-1)
    small = t2 < _SMALL
    th = jnp.sqrt(jnp.where(small, 1.0, t2))
    c = jnp.where(small, 1.0 - t2 / 8.0, jnp.cos(th / 2.0))
    k = jnp.where(small, 0.5 - t2 / 48.0, jnp.sin(th / 2.0) / th)
    return jnp.concatenate([c[..., None], k[..., None] * r], axis=-1)


def quat_delta(q0, q1):
    """World rotation vector ``log(q1 q0^-1)`` (shortest arc) taking orientation ``q0`` to ``q1``, rad."""
    return quat_log(quat_mul(q1, quat_conj(q0)))


def quat_slerp(q0, q1, s):
    """Spherical linear interpolation ``exp(s log(q1 q0^-1)) q0`` along the shorter arc.

    Constant angular speed in ``s``; ``q1`` and ``-q1`` give the same path; ends at ``q1`` up to sign.
    Safe (finite values and gradients) at ``q0 == q1``.
    """
    s = jnp.asarray(s)
    return quat_mul(quat_exp(s[..., None] * quat_delta(q0, q1)), q0)


def yaw_quat(yaw_rad):
    """Upright orientation of heading ``yaw_rad`` (rotation about world z)."""
    h = 0.5 * jnp.asarray(yaw_rad)
    zero = jnp.zeros_like(h)
    return jnp.stack([jnp.cos(h), zero, zero, jnp.sin(h)], axis=-1)


def quat_yaw(q):
    """Heading (ZYX yaw, rad, in (-pi, pi]) of a (w, x, y, z) quaternion."""
    w, x, y, z = (q[..., i] for i in range(4))
    return jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rotate_yaw(q, dyaw_rad):
    """``q`` rotated by ``dyaw_rad`` about the world z axis: ``yaw_quat(dyaw) q``."""
    return quat_mul(yaw_quat(dyaw_rad), q)


# --- references ------------------------------------------------------------------------------------------


class FootReference(NamedTuple):
    """Swing-foot reference at one instant (world frame): position m (3,), velocity m/s (3,), acceleration
    m/s^2 (3,), orientation (w, x, y, z) (4,), angular velocity rad/s (3,), angular acceleration rad/s^2 (3,)."""

    pos: jax.Array
    vel: jax.Array
    acc: jax.Array
    quat: jax.Array
    ang_vel: jax.Array
    ang_acc: jax.Array


def swing_foot_reference(t_s, duration_s, start_pos_m, target_xy_m, ground_z_m, clearance_m, start_quat,
                         target_yaw_rad) -> FootReference:
    """Swing foot from its lift-off pose to the next footstep (seed 001 section III).

    Horizontal: ``xy = xy0 + s (xy_target - xy0)``; height: ``z = z0 + s (ground_z - z0) + swing_height(t)``
    (eq. 8, apex ``clearance_m`` above the drifting base line); orientation: Slerp from ``start_quat`` to the
    flat ``yaw_quat(target_yaw_rad)``, ``w = sd r``, ``wd = sdd r`` with ``r = log(q_target q_start^-1)``;
    ``(s, sd, sdd) = blend(t)``.
    """
    s, sd, sdd = blend(t_s, duration_s)
    h, hd, hdd = swing_height(t_s, duration_s, clearance_m)
    start_pos_m = jnp.asarray(start_pos_m)
    delta = jnp.concatenate([jnp.asarray(target_xy_m) - start_pos_m[:2],
                             jnp.reshape(ground_z_m - start_pos_m[2], (1,))])
    lift = jnp.stack([jnp.zeros_like(h), jnp.zeros_like(h), jnp.ones_like(h)])
    r = quat_delta(start_quat, yaw_quat(target_yaw_rad))
    return FootReference(
        pos=start_pos_m + s * delta + h * lift,
        vel=sd * delta + hd * lift,
        acc=sdd * delta + hdd * lift,
        quat=quat_mul(quat_exp(s * r), start_quat),
        ang_vel=sd * r,
        ang_acc=sdd * r,
    )


def step_over_reference(t_s, duration_s, start_pos_m, target_xy_m, ground_z_m, clearance_m, start_quat,
                        target_yaw_rad, lift_fraction) -> FootReference:
    """Swing foot over an edge (a stair's riser): up, across, down, for a known terrain.

    With ``a = lift_fraction`` and ``top = max(z0, ground_z) + clearance_m``, the height rises from ``z0`` to
    ``top`` over the first ``a`` of the swing and falls to ``ground_z`` over the last ``a`` (:func:`blend` each);
    the horizontal motion and the Slerp run between ``a / 2`` and ``1 - a / 2``, so the foot has risen half way
    before it moves toward an edge ahead and is past it before it drops. ``lift_fraction = 0`` is a straight
    line (no clearance): use :func:`swing_foot_reference` on flat ground.
    """
    T = duration_s
    a = lift_fraction * T
    up, upd, updd = blend(t_s, a)
    dn, dnd, dndd = blend(t_s - (T - a), a)
    s, sd, sdd = blend(t_s - 0.5 * a, T - a)
    start_pos_m = jnp.asarray(start_pos_m)
    z0 = start_pos_m[2]
    top = jnp.maximum(z0, ground_z_m) + clearance_m
    rise, fall = top - z0, ground_z_m - top
    dxy = jnp.asarray(target_xy_m) - start_pos_m[:2]
    zero = jnp.zeros_like(up)
    r = quat_delta(start_quat, yaw_quat(target_yaw_rad))
    return FootReference(
        pos=jnp.concatenate([start_pos_m[:2] + s * dxy, jnp.reshape(z0 + up * rise + dn * fall, (1,))]),
        vel=jnp.concatenate([sd * dxy, jnp.reshape(upd * rise + dnd * fall + zero, (1,))]),
        acc=jnp.concatenate([sdd * dxy, jnp.reshape(updd * rise + dndd * fall + zero, (1,))]),
        quat=quat_mul(quat_exp(s * r), start_quat),
        ang_vel=sd * r,
        ang_acc=sdd * r,
    )


def base_reference(t_s, duration_s, start_yaw_rad, turn_rad_per_s):
    """Upright base (pelvis) orientation turning by ``turn_rad_per_s * duration_s`` over the step.

    Seed 001: at the end of each swing phase the base is rotated by ``w_joy dt`` about z. The heading is
    ``yaw0 + s w_joy dt`` with ``(s, sd, sdd) = blend(t)``: the Slerp between the two upright orientations
    (for any turn, also beyond pi). Returns ``(quat (4,), ang_vel (3,), ang_acc (3,))``, world axes.
    """
    s, sd, sdd = blend(t_s, duration_s)
    turn = turn_rad_per_s * duration_s
    zero = jnp.zeros_like(sd * turn)
    return (yaw_quat(start_yaw_rad + s * turn), jnp.stack([zero, zero, sd * turn]),
            jnp.stack([zero, zero, sdd * turn]))


def com_reference_acc(com_m, com_vel_mps, base_xy_m, z0_m, kp_z, kd_z, gravity_mps2=9.81, lipm_height_m=None):
    """Desired CoM acceleration (3,): eq. 3 horizontally, a height PD vertically (seed 001 section III).

    ``[xdd, ydd] = g / z_lipm (p_com - p_base)`` with ``p_base`` the stance-foot centre (xy); ``zdd = kp_z
    (z0 - z) - kd_z zd``. ``z0_m`` is the absolute desired CoM height (world z); ``lipm_height_m`` is the
    pendulum height of eq. 3, the CoM height above the stance foot (``None``: ``z0_m``, ground at z = 0).
    """
    com_m, com_vel_mps = jnp.asarray(com_m), jnp.asarray(com_vel_mps)
    height = z0_m if lipm_height_m is None else lipm_height_m
    xy = gravity_mps2 / height * (com_m[:2] - jnp.asarray(base_xy_m))
    z = position_pd(z0_m, com_m[2], 0.0, com_vel_mps[2], kp_z, kd_z)
    return jnp.concatenate([xy, jnp.reshape(z, (1,))])
