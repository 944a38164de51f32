"""Parameters of the walking controller (:mod:`mjx_coman.walking.controller`): one array pytree.

:class:`ControllerParams` holds everything the controller reads: per-tick
tables of the nominal 3LP gait (``jaxlp.gait``, seed 000 eq. 10) and of the
time-projection footstep gains (table B of Figure 13, ``jaxlp.projection``),
the filter and dead-zone constants (eq. 26-27), the foot lift and roll
amplitudes (eq. 22-23, 28-30), the knee deflections (eq. 21) and the switches
of each block, all arrays (vmappable, differentiable); the tick counts are
static. :func:`make_controller_params` builds and validates them on the host.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control, filters, gait as gait_mod, projection
from jaxlp.params import ThreeLPParams
from mjx_coman.env import EnvParams, standing_posture
from mjx_coman.walking import estimation as est
from mjx_coman.walking.open_loop import FIXED_LIFT_M, ROLL_AMP_RAD, crouched_pelvis_height_m

DEFAULT_STEP_WIDTH_M = 0.1452  # the crouched stance's feet distance (hips 2 x 0.0726 m apart)
DEFAULT_DEADZONE = (0.004, 0.004, 0.04, 0.04)  # [e1 m, e2 m, e1_dot m/s, e2_dot m/s], Figure-9-like
DEFAULT_KNEE_DEFLECTION_RAD = 0.012  # mu of eq. 21: knee link - motor at full support, open-loop in-place walk
DEFAULT_ANKLE_COMPLIANCE = 0.675  # stance ankle keeps 32.5 % of its ~290 N m/rad (see motor_targets_block)
DEFAULT_HIP_ATTACK = 0.75  # share of the footstep adjustment applied as the seed's attack angle on the swing hip
DEFAULT_PELVIS_OFFSET_M = -0.03  # nominal pelvis over the ankle axis, the pivot of the compliant ankle
DEFAULT_LEAN_S = 0.03  # 3 mm of pelvis lead per 0.1 m/s: walks within 20 % of 0.1 and 0.2 m/s (0 lean: -19 %, -47 %)
MAX_SPEED_MPS = 0.3  # the crouched stance leg reaches full extension near here (open_loop docstring)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "nominal_base", "nominal_per_mps", "speed_mps", "footstep_table", "step_time_s", "step_width_m",
        "h1_m", "pelvis_height_m", "lift_m", "roll_amp_rad", "adaptive_lift_gain", "foot_pitch_gain",
        "zeta", "deadzone", "footstep_gain", "truncation_m", "mu_left_rad", "mu_right_rad", "weight_n",
        "hip_switch", "posture_q_rad", "ramp_start_steps", "ramp_steps", "start_sway_m",
        "stance_feedback", "ankle_compliance", "pelvis_offset_m", "stance_deadzone_m",
        "lean_s", "adjustment_tau_s", "hip_attack",
    ],
    meta_fields=["ticks_per_step", "dt_s", "window", "knee_rad"],
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
        stance_feedback: gain ``f`` of the stance leg's posture feedback: the
            stance leg's IK target puts the pelvis at ``nominal + f dz(e2)``
            relative to the stance foot (sagittal), ``dz`` the smooth dead-zone of
            eq. 27 with threshold ``stance_deadzone_m``. Small pelvis errors are
            resisted by the stance ankle (the seed's passive CoP modulation);
            beyond the threshold the stance leg holds the actual posture instead
            of driving the body back over the foot, against the footstep
            adjustment (0: the seed's nominal stance targets).
        stance_deadzone_m: threshold of that dead-zone, m.
        lean_s: forward pelvis offset per commanded speed, s (m per m/s): moves
            the nominal pelvis ahead by ``lean_s v`` while walking at ``v``.
        adjustment_tau_s: time constant of a first-order filter on the applied
            footstep adjustment, s (0: applied at once, as the seed does).
        hip_attack: share ``a`` of the footstep adjustment ``Delta`` applied as
            the seed's attack angle on the swing hip: ``a Delta / h1`` is
            added to the swing hip pitch (forward) and taken off the swing ankle
            pitch (foot orientation kept), the knee left to the lift; the rest,
            ``(1 - a) Delta``, moves the IK's swing-foot target (see
            :func:`mjx_coman.walking.controller.joint_targets_block`).
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
        knee_rad: knee flexion of the crouched posture the walk starts from and
            the IK keeps (static; :func:`mjx_coman.walking.rollout.walk` resets the
            env to it).
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
    stance_deadzone_m: jax.Array
    lean_s: jax.Array
    adjustment_tau_s: jax.Array
    hip_attack: jax.Array
    ticks_per_step: int
    dt_s: float
    window: int
    knee_rad: float = 0.4

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
    stance_deadzone_m: float = 0.02,
    lean_s: float = DEFAULT_LEAN_S,
    adjustment_tau_s: float = 0.0,
    hip_attack: float = DEFAULT_HIP_ATTACK,
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
        stance_feedback, ankle_compliance, pelvis_offset_m, stance_deadzone_m, lean_s, adjustment_tau_s,
            hip_attack: see
            :class:`ControllerParams`.
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
                      ("ankle_compliance", ankle_compliance), ("hip_attack", hip_attack)):
        _check(name, val, 0.0, 1.0)
    _check("knee_rad", knee_rad, 0.05, 1.5)

    trunc = filters.FOOTSTEP_TRUNCATION_RATIO * float(params3.h1) if max_adjustment_m is None else max_adjustment_m
    _check("max_adjustment_m", trunc, 0.0, lo_open=True)
    _check("pelvis_offset_m", pelvis_offset_m, -0.1, 0.1)
    _check("stance_deadzone_m", stance_deadzone_m, 0.0, lo_open=True)
    _check("lean_s", lean_s, 0.0, 0.5)
    _check("adjustment_tau_s", adjustment_tau_s, 0.0, 1.0)
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
        pelvis_offset_m=a(pelvis_offset_m), stance_deadzone_m=a(stance_deadzone_m),
        lean_s=a(lean_s), adjustment_tau_s=a(adjustment_tau_s), hip_attack=a(hip_attack),
        ticks_per_step=n, dt_s=dt, window=int(window), knee_rad=float(knee_rad),
    )


