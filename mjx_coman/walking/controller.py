"""The closed-loop walking controller of the simulated COMAN (seed 000, Figure 3).

One pure ``init``/``step`` pair; ``step`` maps the sensor readings of a 2 ms
tick to the motor position targets of :class:`mjx_coman.env.Command`:

1. **Phase clock**: fixed timing, a phase change every ``T = 0.4 s`` (the seed
   "decided to keep a fixed timing instead of a phase-based control"); no
   early/late switching on contact. ``d = +1`` left swing, ``-1`` right swing.
   **Start-up**: from the crouched stance the controller first runs one
   phase (``step = -1``) with both feet down (no lift, no roll, both hips
   tracking) in which the pelvis sways ``start_sway_m sin(pi t / T)`` to the
   left and back, so that the first walking phase (``step = 0``, left swing)
   begins with the body moving towards its stance (right) foot, as the
   lateral bounce of a periodic gait does; starting from rest instead, the
   body falls towards the lifted foot and drifts out.
2. **Gait** (block A): the nominal 3LP state of the commanded speed at this
   tick, from per-tick tables (the sagittal gait is linear in the speed, so
   the speed is an array and vmaps). Walking starts from the crouched stance
   in place; the speed ramps up over ``ramp_steps`` phases after
   ``ramp_start_steps`` in-place phases.
3. **Estimation**: link encoders + IMU -> relative pelvis/feet positions ->
   IIR (eq. 26) -> velocities -> error ``e`` (eq. 15)
   (:mod:`mjx_coman.walking.estimation`), sagittal error through the smooth
   dead-zones (eq. 27).
4. **Footstep adjustment**: table B of Figure 13 (``jaxlp.projection``): the
   final swing-foot adjustment ``Delta = b(t) . e`` relative to the pelvis,
   truncated at 0.35 ``h1`` and converted to the attack angle ``Delta / h1``
   (:func:`jaxlp.filters.footstep_to_attack_angle`). The attack angle is
   realised by the IK as the horizontal foot shift ``h1 * angle`` it stands
   for (foot kept flat and on the ground plane): added to the hip pitch joint
   alone it would also lift the foot by ``l (1 - cos angle)`` and, with the
   crouched leg ``l = 0.417 m`` shorter than ``h1``, undershoot by ``l / h1``.
5. **Adaptive lift and foot orientation** (eq. 28-30): ``theta_hat =
   atan((e2 - e1 + Delta) / h1)`` (the seed's ``e2 - e1``, measured from the
   commanded, adjusted swing position because the adjustment is applied in
   Cartesian space here), extra lift ``h1 (1 - cos theta_hat) sin(pi t / T)``
   and swing foot pitch ``-theta_hat``.
6. **IK** (block B), **knee compensation** (eq. 21, filtered foot forces), and
   the **hip switching** of eq. 24 in position form: the env closes
   ``v = k_p (target - theta_m)`` on the motor shaft (eq. 25), so each hip
   pitch target is ``gamma q_des + (1 - gamma)(theta_m + pitch)``, which makes
   the board apply ``k_p (gamma (q_des - theta_m) + (1 - gamma) pitch)``
   (eq. 24; ``pitch`` the IMU pelvis pitch, forward lean > 0).

Controllers (static ``controller`` argument of :func:`step`):
``"time-projection"`` (the closed loop), ``"no-deadzone"`` (the same without
eq. 27), ``"dlqr"`` (the adjustment of table B at the phase start, i.e. of the
DLQR law, held for the phase: the seed's baseline) and ``"open-loop"`` (no
footstep adjustment; adaptive lift and orientation feedback stay on, as in
the seed's Figure 18).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control, filters, gait as gait_mod, projection
from jaxlp.params import ThreeLPParams
from mjx_coman.env import Command, EnvParams, standing_posture
from mjx_coman.sensors import Readings
from mjx_coman.walking import estimation as est
from mjx_coman.walking.open_loop import (
    FIXED_LIFT_M,
    LEFT_HIP_PITCH,
    LEFT_KNEE,
    LEFT_LEG_INDEX,
    RIGHT_HIP_PITCH,
    RIGHT_KNEE,
    RIGHT_LEG_INDEX,
    ROLL_AMP_RAD,
    crouched_pelvis_height_m,
    hip_switch_gamma,
    joint_targets,
    knee_compensation,
    targets_from_state,
)

CONTROLLERS = ("time-projection", "no-deadzone", "dlqr", "open-loop")
LEFT_ANKLE_PITCH = int(LEFT_LEG_INDEX[5])
RIGHT_ANKLE_PITCH = int(RIGHT_LEG_INDEX[5])
DEFAULT_STEP_WIDTH_M = 0.1452  # the crouched stance's feet distance (hips 2 x 0.0726 m apart)
DEFAULT_DEADZONE = (0.004, 0.004, 0.04, 0.04)  # [e1 m, e2 m, e1_dot m/s, e2_dot m/s], Figure-9-like
DEFAULT_KNEE_DEFLECTION_RAD = 0.012  # mu of eq. 21: knee link - motor at full support, open-loop in-place walk
DEFAULT_ANKLE_COMPLIANCE = 0.65  # stance ankle keeps 35 % of its ~290 N m/rad (see motor_targets_block)
DEFAULT_PELVIS_OFFSET_M = -0.03  # nominal pelvis over the ankle axis, the pivot of the compliant ankle
MAX_SPEED_MPS = 0.3  # the crouched stance leg reaches full extension near here (open_loop docstring)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "nominal_base", "nominal_per_mps", "speed_mps", "footstep_table", "step_time_s", "step_width_m",
        "h1_m", "pelvis_height_m", "lift_m", "roll_amp_rad", "adaptive_lift_gain", "foot_pitch_gain",
        "zeta", "deadzone", "footstep_gain", "truncation_m", "mu_left_rad", "mu_right_rad", "weight_n",
        "hip_switch", "posture_q_rad", "ramp_start_steps", "ramp_steps", "start_sway_m",
        "stance_feedback", "ankle_compliance", "pelvis_offset_m",
    ],
    meta_fields=["ticks_per_step", "dt_s", "window"],
)
@dataclasses.dataclass(frozen=True)
class ControllerParams:
    """Everything the controller reads (arrays; vmappable, tunable), plus static sizes.

    Attributes:
        nominal_base: (n + 1, 2, 6) nominal 3LP state per tick at zero speed, ``d = +1``.
        nominal_per_mps: (n + 1, 2, 6) its change per m/s of commanded speed.
        speed_mps: commanded speed, m/s.
        footstep_table: (n, 4) table B of Figure 13 (sagittal): final swing
            foot adjustment per unit error, per tick of the phase.
        step_time_s: T, s (``ticks_per_step * dt_s``).
        step_width_m: lateral distance of the feet, m.
        h1_m: 3LP pelvis height (truncation, attack angle, eq. 28-29), m.
        pelvis_height_m: crouched pelvis-point height above the foot points, m.
        lift_m, roll_amp_rad: fixed lift (eq. 23) and pelvis roll (eq. 22) amplitudes.
        adaptive_lift_gain: 1 applies eq. 29, 0 turns it off.
        foot_pitch_gain: 1 applies eq. 30, 0 turns it off.
        zeta: IIR constant per tick (eq. 26).
        deadzone: (4,) thresholds of eq. 27 for the sagittal ``[e1, e2, e1_dot, e2_dot]``.
        footstep_gain: scale of the footstep adjustment (1 closed loop; 0 makes
            any controller open loop, which shares one compiled walk).
        truncation_m: largest footstep adjustment, m (0.35 ``h1``).
        mu_left_rad, mu_right_rad: knee deflections of eq. 21, rad.
        weight_n: total weight ``m g`` of eq. 21, N.
        hip_switch: 1 applies the torso switch of eq. 24 to the hip pitch joints, 0 tracks the IK.
        posture_q_rad: (23,) crouched posture for the joints the IK does not set.
        ramp_start_steps: in-place phases before the speed ramps up.
        ramp_steps: phases over which the speed ramps from 0 to ``speed_mps``.
        start_sway_m: lateral pelvis sway of the start-up phase, m (see :func:`step`).
        stance_feedback: share of the measured sagittal pelvis-to-stance-foot
            vector in the stance leg's IK target (0: the nominal posture, as in the
            seed; 1: the measured one, so the stance ankle and knee hold the actual
            posture instead of driving the body back to the nominal one).
        ankle_compliance: share ``c`` of the measured link angle in the stance
            ankle pitch target, ``(1 - c) q_ik + c q_link``: it scales the stance
            ankle's stiffness against posture errors by ``1 - c`` (see
            :func:`motor_targets_block`).
        pelvis_offset_m: sagittal offset of the nominal pelvis from the 3LP
            pelvis over the stance foot point, m (negative: behind; -0.03 puts it
            over the ankle axis, the pivot of a compliant ankle).
        ticks_per_step: n, control ticks per phase (static).
        dt_s: control period, s (static).
        window: velocity moving-average length, samples (static).
    """

    nominal_base: jax.Array
    nominal_per_mps: jax.Array
    speed_mps: jax.Array
    footstep_table: jax.Array
    step_time_s: jax.Array
    step_width_m: jax.Array
    h1_m: jax.Array
    pelvis_height_m: jax.Array
    lift_m: jax.Array
    roll_amp_rad: jax.Array
    adaptive_lift_gain: jax.Array
    foot_pitch_gain: jax.Array
    zeta: jax.Array
    deadzone: jax.Array
    footstep_gain: jax.Array
    truncation_m: jax.Array
    mu_left_rad: jax.Array
    mu_right_rad: jax.Array
    weight_n: jax.Array
    hip_switch: jax.Array
    posture_q_rad: jax.Array
    ramp_start_steps: jax.Array
    ramp_steps: jax.Array
    start_sway_m: jax.Array
    stance_feedback: jax.Array
    ankle_compliance: jax.Array
    pelvis_offset_m: jax.Array
    ticks_per_step: int
    dt_s: float
    window: int

    def replace(self, **kw) -> "ControllerParams":
        return dataclasses.replace(self, **kw)


def _check(name: str, value, lo=None, hi=None, lo_open=False) -> float:
    v = float(value)
    if not np.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi):
        raise ValueError(f"{name}={value!r} is out of range"
                         + (f" (must be {'>' if lo_open else '>='} {lo})" if lo is not None else "")
                         + (f" (must be <= {hi})" if hi is not None else ""))
    return v


def make_controller_params(
    robot: EnvParams | ThreeLPParams | None = None,
    speed_mps: float = 0.0,
    *,
    step_time_s: float = 0.4,
    control_period_s: float | None = None,
    step_width_m: float = DEFAULT_STEP_WIDTH_M,
    deadzone=DEFAULT_DEADZONE,
    zeta: float = 0.1,
    window: int = est.VELOCITY_WINDOW,
    mu_left_rad: float = DEFAULT_KNEE_DEFLECTION_RAD,
    mu_right_rad: float = DEFAULT_KNEE_DEFLECTION_RAD,
    footstep_gain: float = 1.0,
    lift_m: float = FIXED_LIFT_M,
    roll_amp_rad: float = ROLL_AMP_RAD,
    adaptive_lift_gain: float = 1.0,
    foot_pitch_gain: float = 1.0,
    hip_switch: float = 1.0,
    knee_rad: float = 0.4,
    ramp_start_steps: int = 2,
    ramp_steps: int = 4,
    start_sway_m: float = 0.02,
    stance_feedback: float = 0.0,
    ankle_compliance: float = DEFAULT_ANKLE_COMPLIANCE,
    pelvis_offset_m: float = DEFAULT_PELVIS_OFFSET_M,
    max_adjustment_m: float | None = None,
    weights: control.LQRWeights | None = None,
) -> ControllerParams:
    """Validated controller parameters for a commanded speed (host function, not jittable).

    Args:
        robot: the environment (its 3LP model is ``coman-mjcf``, its control
            period and weight are read from it), or 3LP parameters directly
            (then the weight is ``(m1 + 2 m2) g``); ``None``: ``coman-mjcf``.
        speed_mps: commanded forward speed, m/s (|v| <= 0.3).
        step_time_s: T, s; a whole number of control periods.
        control_period_s: control tick, s; default the env's, else 0.002.
        step_width_m: lateral feet distance, m (default: the crouched stance's).
        deadzone: four sagittal dead-zone thresholds (eq. 27), positive.
        zeta: IIR constant in (0, 1] (eq. 26).
        window: velocity moving average, samples (static).
        mu_left_rad, mu_right_rad: knee deflections of eq. 21 (>= 0), rad.
        footstep_gain: scale of the footstep adjustment (>= 0).
        lift_m, roll_amp_rad: eq. 23 and eq. 22 amplitudes (>= 0).
        adaptive_lift_gain, foot_pitch_gain, hip_switch, stance_feedback: block switches in [0, 1].
        knee_rad: knee flexion of the crouched posture (the env's reset posture).
        ramp_start_steps, ramp_steps: in-place phases, then phases of speed ramp (>= 0).
        start_sway_m: amplitude of the start-up sway (>= 0), m.
        stance_feedback, ankle_compliance, pelvis_offset_m: see :class:`ControllerParams`.
        max_adjustment_m: truncation of the footstep adjustment, m (default 0.35 ``h1``).
        weights: DLQR weights (``jaxlp.control.default_weights`` if ``None``).

    Raises:
        ValueError: naming the bad value.
    """
    from jaxlp.presets import get_params

    if robot is None or isinstance(robot, EnvParams):
        params3 = get_params("coman-mjcf")
        if isinstance(robot, EnvParams):
            dt_env = round(float(np.asarray(robot.control_period_s)), 9)  # float32 -> 0.002
            if control_period_s is not None and abs(control_period_s - dt_env) > 1e-9:
                raise ValueError(f"control_period_s={control_period_s} differs from the env's {dt_env}")
            control_period_s = dt_env
            mass = float(np.asarray(robot.model.body_mass).sum())
            weight = mass * float(-np.asarray(robot.model.opt.gravity)[2])
        else:
            weight = float(params3.total_mass_kg * params3.g)
    elif isinstance(robot, ThreeLPParams):
        params3 = robot
        weight = float(params3.total_mass_kg * params3.g)
    else:
        raise ValueError(f"robot must be EnvParams, ThreeLPParams or None, got {type(robot).__name__}")
    dt = _check("control_period_s", 0.002 if control_period_s is None else control_period_s, 0.0, lo_open=True)
    T = _check("step_time_s", step_time_s, 0.0, lo_open=True)
    n = int(round(T / dt))
    if n < 2 or abs(n * dt - T) > 1e-6:
        raise ValueError(f"step_time_s={step_time_s} must be a whole number (>= 2) of control periods {dt}")
    v = _check("speed_mps", speed_mps)
    if abs(v) > MAX_SPEED_MPS:
        raise ValueError(f"speed_mps={speed_mps} is beyond +-{MAX_SPEED_MPS} m/s (the stance leg's reach)")
    _check("step_width_m", step_width_m, 0.0, 0.4)
    _check("zeta", zeta, 0.0, 1.0, lo_open=True)
    if int(window) != window or window < 1:
        raise ValueError(f"window={window!r} must be a positive whole number of samples")
    dz = np.asarray(deadzone, float)
    if dz.shape != (4,) or not np.all(np.isfinite(dz)) or np.any(dz <= 0):
        raise ValueError(f"deadzone={np.asarray(deadzone).tolist()} must be 4 positive thresholds")
    for name, val in (("mu_left_rad", mu_left_rad), ("mu_right_rad", mu_right_rad),
                      ("footstep_gain", footstep_gain), ("lift_m", lift_m), ("roll_amp_rad", roll_amp_rad),
                      ("ramp_start_steps", ramp_start_steps), ("ramp_steps", ramp_steps),
                      ("start_sway_m", start_sway_m)):
        _check(name, val, 0.0)
    for name, val in (("adaptive_lift_gain", adaptive_lift_gain), ("foot_pitch_gain", foot_pitch_gain),
                      ("hip_switch", hip_switch), ("stance_feedback", stance_feedback),
                      ("ankle_compliance", ankle_compliance)):
        _check(name, val, 0.0, 1.0)
    _check("knee_rad", knee_rad, 0.05, 1.5)

    trunc = filters.FOOTSTEP_TRUNCATION_RATIO * float(params3.h1) if max_adjustment_m is None else max_adjustment_m
    _check("max_adjustment_m", trunc, 0.0, lo_open=True)
    _check("pelvis_offset_m", pelvis_offset_m, -0.1, 0.1)
    g0 = gait_mod.periodic_gait(params3, T, 0.0, step_width_m)
    g1 = gait_mod.periodic_gait(params3, T, 0.1, step_width_m)
    ts = jnp.arange(n + 1) * dt
    nom0 = jax.vmap(lambda t: gait_mod.nominal_state(params3, g0, t))(ts)
    nom1 = jax.vmap(lambda t: gait_mod.nominal_state(params3, g1, t))(ts)
    per_mps = ((nom1 - nom0) / 0.1).at[:, 1].set(0.0)  # only the sagittal gait depends on the speed (linearly)
    ctrl = control.constrained_dlqr(params3, T, weights)
    table = projection.gain_table(params3, ctrl, T, n).footstep
    posture, _ = standing_posture(float(knee_rad))
    f = jnp.result_type(float)
    a = lambda x: jnp.asarray(x, f)  # noqa: E731
    return ControllerParams(
        nominal_base=a(nom0), nominal_per_mps=a(per_mps), speed_mps=a(v), footstep_table=a(table),
        step_time_s=a(T), step_width_m=a(step_width_m), h1_m=a(params3.h1),
        pelvis_height_m=a(crouched_pelvis_height_m(float(knee_rad))), lift_m=a(lift_m),
        roll_amp_rad=a(roll_amp_rad), adaptive_lift_gain=a(adaptive_lift_gain), foot_pitch_gain=a(foot_pitch_gain),
        zeta=a(zeta), deadzone=a(dz), footstep_gain=a(footstep_gain),
        truncation_m=a(trunc),
        mu_left_rad=a(mu_left_rad), mu_right_rad=a(mu_right_rad), weight_n=a(weight), hip_switch=a(hip_switch),
        posture_q_rad=a(posture), ramp_start_steps=a(ramp_start_steps), ramp_steps=a(ramp_steps),
        start_sway_m=a(start_sway_m), stance_feedback=a(stance_feedback), ankle_compliance=a(ankle_compliance),
        pelvis_offset_m=a(pelvis_offset_m),
        ticks_per_step=n, dt_s=dt, window=int(window),
    )


class ControllerState(NamedTuple):
    """The controller's memory (a pytree).

    Attributes:
        tick: control ticks done in the current phase (int32; ``ticks_per_step`` triggers the change).
        step: phase index, 0 for the first phase (int32); also the number of phase changes.
        d: phase sign, +1 left swing, -1 right swing.
        filt: IIR / velocity filter memory of the relative positions.
        force_n: (2,) IIR-filtered foot normal forces (right, left), N (eq. 21).
        error: (2, 4) last filtered error (eq. 15), before the dead-zone.
        adjustment_m: footstep adjustment applied at the last tick (truncated), m.
        held_m: the adjustment held by ``"dlqr"`` since the phase start, m.
    """

    tick: jax.Array
    step: jax.Array
    d: jax.Array
    filt: filters.FilterState
    force_n: jax.Array
    error: jax.Array
    adjustment_m: jax.Array
    held_m: jax.Array


def init(params: ControllerParams) -> ControllerState:
    """The state at the crouched stance: the start-up phase (``step = -1``, ``d = -1``) begins."""
    f = params.zeta.dtype
    z = jnp.zeros((), f)
    return ControllerState(
        tick=jnp.zeros((), jnp.int32), step=jnp.full((), -1, jnp.int32), d=-jnp.ones((), f),
        filt=est.estimator_init(params.window, f), force_n=jnp.full((2,), 0.5, f) * params.weight_n,
        error=jnp.zeros((2, 4), f), adjustment_m=z, held_m=z,
    )


def speed_factor(params: ControllerParams, step) -> jax.Array:
    """Share of the commanded speed in phase ``step``: 0 in place, then a linear ramp to 1."""
    ramp = jnp.maximum(params.ramp_steps, 1.0)
    return jnp.clip((step - params.ramp_start_steps + 1.0) / ramp, 0.0, 1.0)


def nominal_at(params: ControllerParams, tick, step, d, pelvis_offset_m=0.0) -> jax.Array:
    """(2, 6) nominal 3LP state at ``tick`` of phase ``step`` (lateral axis signed by ``d``; eq. 10).

    ``pelvis_offset_m`` moves the nominal pelvis forward (sagittal), m.
    """
    v = params.speed_mps * speed_factor(params, step)
    q = params.nominal_base[tick] + v * params.nominal_per_mps[tick]
    q = q * jnp.stack([jnp.ones_like(d), d])[:, None]
    return q.at[0, 1].add(pelvis_offset_m)


def footstep_block(params: ControllerParams, tick, error_sag, held_m, controller: str):
    """Footstep adjustment of table B (Figure 13), truncated at ``truncation_m``.

    Returns:
        ``(adjustment_m, held_m)``: the adjustment to apply now and the DLQR hold.
    """
    k = jnp.minimum(tick, params.ticks_per_step - 1)
    fresh = params.footstep_table[k] @ error_sag
    held = jnp.where(tick == 0, fresh, held_m)
    if controller == "dlqr":
        raw = held
    elif controller == "open-loop":
        raw = jnp.zeros_like(fresh)
    else:
        raw = fresh
    angle = filters.footstep_to_attack_angle(params.footstep_gain * raw, params.h1_m)
    angle = jnp.clip(angle, -params.truncation_m / params.h1_m, params.truncation_m / params.h1_m)
    return angle * params.h1_m, held


def lift_block(params: ControllerParams, t_s, error_sag, adjustment_m):
    """Adaptive lift (eq. 28-29) and foot orientation feedback (eq. 30).

    Returns:
        ``(extra_lift_m, swing_pitch_rad, theta_hat_rad)``.
    """
    theta = jnp.arctan((error_sag[1] - error_sag[0] + adjustment_m) / params.h1_m)
    sine = jnp.sin(jnp.pi * jnp.clip(t_s / params.step_time_s, 0.0, 1.0))
    lift = params.adaptive_lift_gain * params.h1_m * (1.0 - jnp.cos(theta)) * sine
    return lift, -params.foot_pitch_gain * theta, theta


def joint_targets_block(params: ControllerParams, q_nominal, t_s, d, adjustment_m, extra_lift_m,
                        swing_pitch_rad, pelvis_shift_m=None, walking=1.0, measured_s2_x=None) -> jax.Array:
    """(23,) desired joint angles: 3LP targets + lifts + footstep adjustment -> IK (Figure 3, A-B).

    Args:
        pelvis_shift_m: (3,) extra pelvis displacement in the heading frame (start-up sway), m.
        walking: 1 while walking, 0 in the start-up phase (no lift, no roll).
        measured_s2_x: measured sagittal pelvis-minus-stance-foot position, m; with
            ``stance_feedback`` it replaces the nominal one in the stance leg's target.
    """
    c = targets_from_state(q_nominal, params.step_width_m, t_s, d, params.pelvis_height_m,
                           walking * params.lift_m, walking * params.roll_amp_rad, params.step_time_s)
    shift = jnp.stack([adjustment_m, jnp.zeros_like(adjustment_m), extra_lift_m])
    pelvis = jnp.zeros(3, c.swing_m.dtype) if pelvis_shift_m is None else pelvis_shift_m
    stance = c.stance_m - pelvis
    if measured_s2_x is not None:
        fb = walking * params.stance_feedback
        stance = stance.at[0].set((1.0 - fb) * stance[0] + fb * (-measured_s2_x))
    c = c._replace(swing_m=c.swing_m + shift - pelvis, stance_m=stance)
    return joint_targets(c, d, params.posture_q_rad, swing_pitch_rad)


def motor_targets_block(params: ControllerParams, q_des, t_s, d, force_n, readings: Readings,
                        walking=1.0) -> jax.Array:
    """Knee compensation (eq. 21) and the position form of the hip switch (eq. 24): (23,) motor targets.

    ``walking = 0`` (start-up phase) makes both hips track ``q_des``.

    Stance ankle compliance: the stance ankle pitch target is
    ``(1 - c) q_des + c q_link`` (``c = ankle_compliance``). The simulated
    ankle (390 N m/rad spring in series with the 500 V/rad loop, about
    290 N m/rad) is much stiffer than gravity's toppling (about 150 N m/rad)
    and than the seed's worn robot (31 N m/rad, section "Effective Ankle
    Stiffness"): a foot placed ahead by the footstep adjustment lands with the
    ankle far from its nominal angle and the stiff ankle then throws the body
    forward over it, against the adjustment. Blending in the measured link
    angle leaves ``(1 - c)`` of that stiffness (the 20 ms delay of the
    blended part acts as damping).
    """
    dl, dr = knee_compensation(force_n[1], force_n[0], params.weight_n, params.mu_left_rad, params.mu_right_rad)
    q = q_des.at[LEFT_KNEE].add(dl).at[RIGHT_KNEE].add(dr)
    pitch = readings.imu_rpy_rad[1]
    left_swing = d > 0
    for idx, swing in ((LEFT_HIP_PITCH, left_swing), (RIGHT_HIP_PITCH, ~left_swing)):
        gamma = 1.0 - walking * params.hip_switch * (1.0 - hip_switch_gamma(t_s, params.step_time_s, swing))
        torso = readings.motor_angle_rad[idx] + pitch
        q = q.at[idx].set(gamma * q[idx] + (1.0 - gamma) * torso)
    c = walking * params.ankle_compliance
    stance_ankle = jnp.where(left_swing, RIGHT_ANKLE_PITCH, LEFT_ANKLE_PITCH)
    blended = (1.0 - c) * q[stance_ankle] + c * readings.link_angle_rad[stance_ankle]
    return q.at[stance_ankle].set(blended)


def step(params: ControllerParams, state: ControllerState, readings: Readings,
         controller: str = "time-projection") -> tuple[ControllerState, Command]:
    """One control tick: readings -> motor position targets (seed 000, Figure 3).

    Args:
        params: controller parameters.
        state: controller memory.
        readings: this tick's sensor readings (``EnvState.readings``).
        controller: static, one of :data:`CONTROLLERS`.

    Returns:
        The new state and the :class:`mjx_coman.env.Command` (position mode, zero torso force).
    """
    if controller not in CONTROLLERS:
        raise ValueError(f"unknown controller {controller!r}; choose one of {', '.join(CONTROLLERS)}")
    n = params.ticks_per_step
    swap = state.tick >= n
    d = jnp.where(swap, -state.d, state.d)
    tick = jnp.where(swap, 0, state.tick)
    step_idx = state.step + swap.astype(jnp.int32)
    swapped = est.estimator_swap(state.filt)
    filt = jax.tree_util.tree_map(lambda a, b: jnp.where(swap, a, b), swapped, state.filt)
    t = tick.astype(d.dtype) * params.dt_s

    walking = (step_idx >= 0).astype(d.dtype)
    ramp_in = walking + (1.0 - walking) * 0.5 * (1.0 - jnp.cos(jnp.pi * t / params.step_time_s))
    offset = params.pelvis_offset_m * ramp_in
    q_nom = nominal_at(params, tick, step_idx, d, offset)
    raw = est.measure_relative(readings, d)
    filt, e = est.estimator_step(filt, raw, q_nom, d, params.zeta, params.dt_s)
    err = e.error[0]
    if controller != "no-deadzone":
        err = filters.smooth_deadzone(err, params.deadzone)
    adj, held = footstep_block(params, tick, err, state.held_m, controller)
    adj = walking * adj
    lift, pitch, _ = lift_block(params, t, err, adj)
    sway = (1.0 - walking) * params.start_sway_m * jnp.sin(jnp.pi * t / params.step_time_s)
    pelvis_shift = jnp.stack([jnp.zeros_like(sway), sway, jnp.zeros_like(sway)])
    q_des = joint_targets_block(params, q_nom, t, d, adj, walking * lift, walking * pitch, pelvis_shift, walking,
                                e.pos_m[0, 1])
    force = filters.iir(state.force_n, readings.foot_normal_force_n, params.zeta)
    target = motor_targets_block(params, q_des, t, d, force, readings, walking)
    new = ControllerState(tick=tick + 1, step=step_idx, d=d, filt=filt, force_n=force, error=e.error,
                          adjustment_m=adj, held_m=held)
    return new, Command(target.astype(readings.motor_angle_rad.dtype), jnp.zeros(3, target.dtype),
                        jnp.asarray(False))


__all__ = [
    "CONTROLLERS", "ControllerParams", "ControllerState", "make_controller_params", "init", "step",
    "nominal_at", "footstep_block", "lift_block", "joint_targets_block", "motor_targets_block", "speed_factor",
]
