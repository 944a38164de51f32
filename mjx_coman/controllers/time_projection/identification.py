"""Identification from an open-loop in-place walk: dead-zone thresholds and knee deflections.

Seed 000 tunes two sets of constants on the robot itself, from a recorded
open-loop in-place walk (the feet step in place, the 3LP gait has zero speed
and the footstep adjustment is off):

* **Dead-zones** (section "State Estimation", Figure 9, eq. 27): the filtered
  sagittal errors ``e1, e2`` (swing foot and pelvis relative to the stance
  foot, against the nominal gait, eq. 15) and their velocities would be zero
  with ideal sensing and actuation. Backlash, calibration and model mismatch
  leave a spread; the seed fits a Gaussian to each of the four signals over
  the walk and sets each dead-zone threshold ``a`` to its standard deviation.
  The Gaussian fit is the maximum-likelihood one (sample mean and standard
  deviation); the mean is the systematic bias, reported but not part of the
  symmetric dead-zone of eq. 27. The seed samples the errors over the whole
  walk, i.e. at every control tick; sampling at the phase changes only is an
  option of :func:`error_sample_mask`.
* **Knee deflections** (section "SEA Compensation", Figure 7, eq. 21): the
  knee springs of a loaded leg deflect by a nearly constant angle (link minus
  motor angle, from the post- and pre-spring encoders). Eq. 21 scales the
  compensation by the normalised foot force ``|F| / (m g)``, so ``mu`` is the
  deflection at full support. It is fitted here as the least-squares slope of
  deflection against normalised force through the origin, which uses the
  double-support samples too; the seed's histogram mean at (nearly) full
  support is reported alongside.

The fitting functions are pure and vmappable (masks instead of boolean
indexing). :func:`knee_load_moment_nm` is the physics check: the moment of the
measured ground reaction (ankle F/T) and of the lower-leg weight about each
knee axis, which a static spring must balance, so ``deflection ~ moment / k``.

:func:`identify_deadzones` and :func:`identify_knee_deflection` fit a walk
recorded at every tick with ``SaveAt(trace.trace, every=1)``
(``mjx_coman.seed000.open_loop_walk`` records the seed's open-loop in-place
walk; pass the same recording to both).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman.actuators import JOINT_INDEX
from mjx_coman.kinematics import leg_fk, quat_to_rot, rot_x, rot_y, rot_z

LEFT_KNEE = JOINT_INDEX["LKneeSag"]
RIGHT_KNEE = JOINT_INDEX["RKneeSag"]
LEFT_LEG = jnp.array([JOINT_INDEX["L" + n] for n in ("HipSag", "HipLat", "HipYaw", "KneeSag", "AnkLat", "AnkSag")])
RIGHT_LEG = jnp.array([JOINT_INDEX["R" + n] for n in ("HipSag", "HipLat", "HipYaw", "KneeSag", "AnkLat", "AnkSag")])
FT_BELOW_ANKLE_M = 0.065  # F/T site below the ankle centre, foot frame (mjcf.FT_BELOW_ANKLE_M)
ERROR_NAMES = ("swing_position_m", "pelvis_position_m", "swing_velocity_mps", "pelvis_velocity_mps")
MIN_THRESHOLD = 1e-6  # dead-zone thresholds must stay positive (eq. 27 divides by a)


class DeadzoneFit(NamedTuple):
    """Gaussian fit of the filtered errors (seed 000, Figure 9).

    Attributes:
        mean: (..., 4) sample mean per error component (systematic bias),
            ``[swing position (m), pelvis position (m), swing velocity (m/s), pelvis velocity (m/s)]``.
        std: (..., 4) sample standard deviation per component (the dead-zone threshold).
        n_samples: number of samples used.
    """

    mean: jax.Array
    std: jax.Array
    n_samples: jax.Array

    @property
    def thresholds(self) -> jax.Array:
        """Dead-zone thresholds ``a`` of eq. 27: the standard deviations, floored at :data:`MIN_THRESHOLD`."""
        return jnp.maximum(self.std, MIN_THRESHOLD)


def _mask_like(samples: jax.Array, mask) -> jax.Array:
    n = samples.shape[0]
    m = jnp.ones((n,), bool) if mask is None else jnp.asarray(mask, bool)
    return m & jnp.all(jnp.isfinite(samples.reshape(n, -1)), axis=1)


def fit_gaussian(samples, mask=None) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Maximum-likelihood Gaussian (mean, unbiased std) along axis 0 over the masked samples.

    Samples with any non-finite entry are left out. With fewer than two
    samples the std is NaN.

    Args:
        samples: (n, ...) samples.
        mask: (n,) bool, True for the samples to use (default all).

    Returns:
        ``(mean (...), std (...), n_used ())``.
    """
    x = jnp.asarray(samples)
    m = _mask_like(x, mask)
    w = m.reshape((-1,) + (1,) * (x.ndim - 1)).astype(x.dtype)
    x0 = jnp.where(w > 0, x, 0.0)
    n = jnp.sum(m)
    mean = jnp.sum(w * x0, axis=0) / n
    var = jnp.sum(w * (x0 - mean) ** 2, axis=0) / (n - 1)
    return mean, jnp.sqrt(var), n


def fit_deadzones(errors, mask=None) -> DeadzoneFit:
    """Dead-zone thresholds from recorded filtered errors (seed 000, Figure 9, eq. 27).

    Args:
        errors: (n, 4) sagittal filtered errors ``e(t)`` of eq. 15 in the
            order of :data:`ERROR_NAMES` (``jaxlp.filters.FilterParams.deadzone``),
            or (n, 2, 4) with the sagittal and lateral axes (both are fitted).
        mask: (n,) bool of the samples to use (e.g. :func:`error_sample_mask`).

    Returns:
        :class:`DeadzoneFit`; ``.thresholds`` goes to the controller's dead-zones.
    """
    e = jnp.asarray(errors)
    if e.shape[-1] != 4:
        raise ValueError(f"errors must end in 4 components {ERROR_NAMES}, got shape {e.shape}")
    mean, std, n = fit_gaussian(e, mask)
    return DeadzoneFit(mean, std, n)


def error_sample_mask(time_s, phase_index, settle_s, valid=None, at_phase_change: bool = False) -> jax.Array:
    """Which recorded ticks enter the fit.

    Args:
        time_s: (n,) time of each sample, s.
        phase_index: (n,) index of the phase (step) each sample belongs to.
        settle_s: leave out the samples before this time (the start from standing).
        valid: (n,) bool, e.g. "not fallen" (default all).
        at_phase_change: static; keep only the first sample of each phase
            (the seed's Figure 14 view) instead of every tick (Figure 9).

    Returns:
        (n,) bool mask.
    """
    t = jnp.asarray(time_s)
    k = jnp.asarray(phase_index)
    m = t >= settle_s
    if valid is not None:
        m = m & jnp.asarray(valid, bool)
    if at_phase_change:
        first = jnp.concatenate([jnp.ones((1,), bool), k[1:] != k[:-1]])
        m = m & first
    return m


class KneeFit(NamedTuple):
    """Knee spring deflections of eq. 21 (seed 000, Figure 7), ``[left, right]``.

    Attributes:
        mu_rad: (2,) deflection (link minus motor, rad) at full support: the
            least-squares slope of deflection on normalised foot force through the origin.
        residual_std_rad: (2,) standard deviation of the fit residuals, rad.
        full_support_mean_rad: (2,) mean deflection over the samples with a
            normalised force above ``full_support`` (the seed's histogram mean); NaN if none.
        n_samples: samples used.
    """

    mu_rad: jax.Array
    residual_std_rad: jax.Array
    full_support_mean_rad: jax.Array
    n_samples: jax.Array

    @property
    def mu_left_rad(self) -> jax.Array:
        return self.mu_rad[..., 0]

    @property
    def mu_right_rad(self) -> jax.Array:
        return self.mu_rad[..., 1]


def total_weight_n(model) -> jax.Array:
    """``m g`` of an ``mjx.Model`` (or ``mujoco.MjModel``), N."""
    return jnp.sum(jnp.asarray(model.body_mass)) * jnp.linalg.norm(jnp.asarray(model.opt.gravity))


def knee_samples(link_angle_rad, motor_angle_rad, foot_normal_force_n, weight_n) -> tuple[jax.Array, jax.Array]:
    """Knee deflections and normalised loads, ``[left, right]`` on the last axis.

    Args:
        link_angle_rad: (..., 23) link (post-spring) encoder angles.
        motor_angle_rad: (..., 23) motor (pre-spring) encoder angles.
        foot_normal_force_n: (..., 2) normal foot forces in the sensor order ``(right, left)``.
        weight_n: total weight ``m g``, N.

    Returns:
        ``(deflection_rad (..., 2), load (..., 2))``: link minus motor knee angle
        (positive when the load flexes the knee) and ``|F| / (m g)``.
    """
    q, th = jnp.asarray(link_angle_rad), jnp.asarray(motor_angle_rad)
    idx = jnp.array([LEFT_KNEE, RIGHT_KNEE])
    defl = q[..., idx] - th[..., idx]
    load = jnp.abs(jnp.asarray(foot_normal_force_n)[..., ::-1]) / weight_n
    return defl, load


def fit_knee_deflection(deflection_rad, load, mask=None, full_support: float = 0.9) -> KneeFit:
    """``mu`` of eq. 21 per knee: deflection ``~ mu |F| / (m g)``, least squares through the origin.

    Args:
        deflection_rad: (n, 2) knee deflections ``[left, right]`` (link minus motor), rad.
        load: (n, 2) normalised foot forces ``|F| / (m g)`` ``[left, right]``.
        mask: (n,) bool of the samples to use (default all finite ones).
        full_support: load above which a sample counts as full support for
            ``full_support_mean_rad``.

    Returns:
        :class:`KneeFit`.
    """
    y, x = jnp.asarray(deflection_rad), jnp.asarray(load)
    m = _mask_like(jnp.concatenate([y, x], axis=-1), mask)
    w = m[:, None].astype(y.dtype)
    y0, x0 = jnp.where(w > 0, y, 0.0), jnp.where(w > 0, x, 0.0)
    mu = jnp.sum(w * x0 * y0, axis=0) / jnp.sum(w * x0 * x0, axis=0)
    r = y0 - mu * x0
    n = jnp.sum(m)
    res = jnp.sqrt(jnp.sum(w * r**2, axis=0) / jnp.maximum(n - 1, 1))
    full = w * (x0 >= full_support)
    full_mean = jnp.sum(full * y0, axis=0) / jnp.sum(full, axis=0)
    return KneeFit(mu, res, full_mean, n)


@functools.lru_cache(maxsize=1)
def lower_leg_masses() -> tuple[tuple[float, tuple[float, float, float], str], ...]:
    """Mass (kg), CoM (m, body frame) and frame (``"shank"``, ``"ankle_roll"``, ``"foot"``) below a knee.

    Read from the packaged model (right leg; the left one mirrors it up to
    CAD asymmetries of a few mm).
    """
    import mujoco

    from mjx_coman import load_model

    m = load_model()
    out = []
    for name, frame in (("RLowLeg", "shank"), ("RFootmot", "ankle_roll"), ("RFoot", "foot")):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        out.append((float(m.body_mass[b]), tuple(float(v) for v in m.body_ipos[b]), frame))
    return tuple(out)


def knee_load_moment_nm(link_angle_rad, ft_left, ft_right, pelvis_quat=None, gravity_mps2: float = 9.81) -> jax.Array:
    """Static moment on each lower leg (shank and foot) about its knee axis, ``[left, right]``, N m.

    The ankle F/T wrench (force and moment at the sensor, 0.065 m below the
    ankle centre, foot frame) is carried by leg kinematics (link encoders)
    into the pelvis frame and taken about the knee centre; with
    ``pelvis_quat`` (the IMU orientation) the weight of the shank and foot is
    added too. Projected on the knee axis (the thigh's +y, knee flexion
    positive). In a quasi-static stance the knee spring balances it,
    ``k (theta_m - q) + moment = 0``, so the deflection ``q - theta_m``
    is ``moment / k``: the physics check of eq. 21's ``mu``.

    Args:
        link_angle_rad: (23,) link angles.
        ft_left, ft_right: (6,) F/T readings ``(fx, fy, fz, mx, my, mz)``, sensor frame.
        pelvis_quat: (4,) pelvis orientation ``(w, x, y, z)`` in the world, or
            ``None`` to leave out the lower-leg weight.
        gravity_mps2: gravitational acceleration.

    Returns:
        (2,) moments, N m.
    """
    q = jnp.asarray(link_angle_rad)
    dt = q.dtype
    if pelvis_quat is None:
        g_pelvis = jnp.zeros(3, dt)
    else:
        g_pelvis = quat_to_rot(jnp.asarray(pelvis_quat, dt)).T @ jnp.array([0.0, 0.0, -gravity_mps2], dt)

    def one(angles, ft, side):
        pose = leg_fk(angles, side)
        r_hip = rot_y(angles[0]) @ rot_x(angles[1]) @ rot_z(angles[2])
        frames = dict(shank=r_hip @ rot_y(angles[3]), foot=pose.foot_rot)
        frames["ankle_roll"] = frames["shank"] @ rot_x(angles[4])
        origins = dict(shank=pose.knee_m, ankle_roll=pose.ankle_m, foot=pose.ankle_m)
        r = pose.foot_rot
        f = r @ ft[:3]
        p_ft = pose.ankle_m + r @ jnp.array([0.0, 0.0, -FT_BELOW_ANKLE_M], dt)
        about_knee = r @ ft[3:] + jnp.cross(p_ft - pose.knee_m, f)
        for mass, com, frame in lower_leg_masses():
            c = origins[frame] + frames[frame] @ jnp.asarray(com, dt)
            about_knee = about_knee + jnp.cross(c - pose.knee_m, mass * g_pelvis)
        return about_knee @ r_hip[:, 1]  # the knee axis: the thigh's +y

    return jnp.stack([one(q[LEFT_LEG], jnp.asarray(ft_left), 1.0), one(q[RIGHT_LEG], jnp.asarray(ft_right), -1.0)])



def phase_index_from_sign(d) -> jax.Array:
    """(n,) phase counter from the recorded phase sign ``d`` (it flips at every phase change)."""
    d = jnp.asarray(d)
    return jnp.concatenate([jnp.zeros((1,), jnp.int32), jnp.cumsum(d[1:] != d[:-1]).astype(jnp.int32)])


def _walk_mask(result, settle_s: float, at_phase_change: bool = False) -> tuple[jax.Array, jax.Array]:
    if settle_s < 0:
        raise ValueError(f"settle_s must be non-negative, got {settle_s}")
    # After a fall the walk is frozen (its recorded time stops): use the nominal record times.
    t_rec = jnp.asarray(result.time_s)
    t = t_rec[0] * (jnp.arange(t_rec.shape[0]) + 1)
    k = phase_index_from_sign(result.saved.d)
    return error_sample_mask(t, k, settle_s, t < result.fall_time_s, at_phase_change), k


def identify_deadzones(result, *, settle_s: float = 2.0, at_phase_change: bool = False) -> DeadzoneFit:
    """Dead-zone thresholds from a recorded open-loop in-place walk (seed 000, Figure 9).

    Fits the sagittal filtered errors after ``settle_s`` (the start from
    standing) and before any fall; ``fit.thresholds`` goes to the config's ``deadzone``.

    Args:
        result: a :class:`mjx_coman.rollout.WalkResult` saved with ``SaveAt(trace.trace, every=1)``.
        settle_s: samples before this time are left out, s.
        at_phase_change: fit the samples at the phase changes only (default: every tick, as Figure 9).

    Returns:
        :class:`DeadzoneFit` of the four sagittal errors.
    """
    mask, _ = _walk_mask(result, settle_s, at_phase_change)
    return fit_deadzones(result.saved.error, mask)


def identify_knee_deflection(result, weight_n, *, settle_s: float = 2.0) -> KneeFit:
    """Knee deflections ``mu`` of eq. 21 from a recorded open-loop in-place walk (seed 000, Figure 7).

    Like :func:`identify_deadzones`; the deflections (link minus motor
    encoders) are regressed on the foot forces over ``m g`` (``weight_n``,
    e.g. :func:`total_weight_n` of the env's model). ``fit.mu_left_rad`` and
    ``fit.mu_right_rad`` go to the config's ``mu_left_rad``, ``mu_right_rad``.
    """
    mask, _ = _walk_mask(result, settle_s)
    return fit_knee_deflection(result.saved.knee_deflection_rad, jnp.abs(result.saved.foot_force_n) / weight_n, mask)
