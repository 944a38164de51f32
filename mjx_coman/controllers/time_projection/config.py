"""The config of the time-projection controller (seed 000): one array pytree and its settings.

:class:`Config` holds everything the controller reads: per-tick tables of the
nominal 3LP gait (``jaxlp.gait``, seed 000 eq. 10; the sagittal gait is linear
in the commanded speed, so the speed comes from the joystick at run time) and
of the time-projection footstep gains (table B of Figure 13,
``jaxlp.projection``), the filter and dead-zone constants (eq. 26-27), the
foot lift and roll amplitudes (eq. 22-23, 28-30), the knee deflections (eq.
21) and the switches of each block, all arrays (vmappable, differentiable);
the tick counts and the crouch are static. :func:`make_config` builds and
validates it on the host from the settings of :data:`SETTINGS`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control, filters, gait as gait_mod, projection
from jaxlp.host import host_eval
from mjx_coman.controllers.base import Setting
from mjx_coman.controllers.time_projection import estimation as est
from mjx_coman.controllers.time_projection.open_loop import FIXED_LIFT_M, ROLL_AMP_RAD, crouched_pelvis_height_m
from mjx_coman.env import standing_posture

DEFAULT_STEP_WIDTH_M = 0.1452  # the crouched stance's feet distance (hips 2 x 0.0726 m apart)
# [e1 m, e2 m, e1_dot m/s, e2_dot m/s], Figure-9-like. Seed 000 sets each to the standard deviation of its error
# in open-loop in-place walking; identified here (`python -m mjx_coman.seed000 identify`) that is (0.0169, 0.0076,
# 0.152, 0.043). Kept because the identified widths do no better on the push table at 0.5 N s (`push-table
# --impulse-step 0.5 --max-impulse 12 --variants time-projection --set deadzone=...`): backward 6.5 N s at every
# phase against 7.0, forward 6.5 both, median steps to recover 4/5 against 4/4; in place they drift 0.080 m/s
# against 0.072 and settle a 4.5 N s push after a median of 8 steps against 7 (`seed000 ablate`).
DEFAULT_DEADZONE = (0.004, 0.004, 0.04, 0.04)
DEFAULT_KNEE_DEFLECTION_RAD = 0.012  # mu of eq. 21: knee link - motor at full support, open-loop in-place walk
# At 0.8 (58 N m/rad, nearer the seed's worn 31) the closed loop recovers 2x the open loop at every phase but
# less in all (forward 4.5 N s at every phase against 6.5): README, "Seed 000", the stance ankle switched.
DEFAULT_ANKLE_COMPLIANCE = 0.675  # stance ankle keeps 32.5 % of its ~290 N m/rad (see motor_targets_block)
DEFAULT_HIP_ATTACK = 0.75  # share of the footstep adjustment applied as the seed's attack angle on the swing hip
# 3 mm further back (-0.033) the in-place walk stops drifting (0.012 against 0.071 m/s) but the open loop turns
# lopsided and the 2x claim fails forward: README, "Seed 000", the nominal posture switched.
DEFAULT_PELVIS_OFFSET_M = -0.03  # nominal pelvis over the ankle axis, the pivot of the compliant ankle
DEFAULT_LEAN_S = 0.03  # 3 mm of pelvis lead per 0.1 m/s: walks within 20 % of 0.1 and 0.2 m/s (0 lean: -19 %, -47 %)
MAX_SPEED_MPS = 0.3  # the crouched stance leg reaches full extension near here (open_loop docstring)
DESIGN_ROBOT = "coman-mjcf"  # the 3LP model the gait, DLQR and tables are designed on

SETTINGS = (
    Setting("robot", DESIGN_ROBOT, "3LP preset the gait, DLQR and gain tables are designed on"),
    Setting("step_time_s", 0.4, "T, s: a whole number of control periods"),
    Setting("control_period_s", 0.002, "control tick, s (the environment's)"),
    Setting("step_width_m", DEFAULT_STEP_WIDTH_M, "lateral distance of the feet, m"),
    Setting("knee_rad", 0.4, "knee flexion of the crouched posture the walk starts from and the IK keeps"),
    Setting("window", est.VELOCITY_WINDOW, "velocity moving-average length, samples"),
    Setting("lqr_weight_scale", (1.0, 1.0, 1.0), "multipliers of the DLQR weights [position, velocity, torque]"),
    Setting("deadzone", DEFAULT_DEADZONE, "eq. 27 thresholds [e1 m, e2 m, e1_dot m/s, e2_dot m/s]", True, (0.0, None)),
    Setting("zeta", 0.1, "IIR constant per tick (eq. 26), in (0, 1]", True, (0.0, 1.0)),
    Setting("footstep_gain", 1.0, "scale of the footstep adjustment (0: open loop)", True, (0.0, None)),
    Setting("hold_adjustment", 0.0, "1: the phase start's adjustment held (DLQR); 0: time projection", True, (0.0, 1.0)),
    Setting("max_adjustment_m", None, "truncation of the footstep adjustment, m (None: 0.35 h1)", True, (0.0, None)),
    Setting("hip_attack", DEFAULT_HIP_ATTACK, "share of the adjustment applied as the swing hip's attack angle", True, (0.0, 1.0)),
    Setting("mu_left_rad", DEFAULT_KNEE_DEFLECTION_RAD, "left knee deflection of eq. 21, rad", True, (0.0, None)),
    Setting("mu_right_rad", DEFAULT_KNEE_DEFLECTION_RAD, "right knee deflection of eq. 21, rad", True, (0.0, None)),
    Setting("lift_m", FIXED_LIFT_M, "fixed foot lift amplitude (eq. 23), m", True, (0.0, None)),
    Setting("roll_amp_rad", ROLL_AMP_RAD, "pelvis roll amplitude (eq. 22), rad", True, (0.0, None)),
    Setting("adaptive_lift_gain", 1.0, "1 applies eq. 29, 0 turns it off", True, (0.0, 1.0)),
    Setting("foot_pitch_gain", 1.0, "1 applies eq. 30, 0 turns it off", True, (0.0, 1.0)),
    Setting("hip_switch", 1.0, "1 applies the torso switch of eq. 24 to the hip pitch joints", True, (0.0, 1.0)),
    Setting("ankle_compliance", DEFAULT_ANKLE_COMPLIANCE, "share of the link angle in the stance ankle target", True, (0.0, 1.0)),
    Setting("pelvis_offset_m", DEFAULT_PELVIS_OFFSET_M, "nominal pelvis offset from the 3LP one, m", True, (-0.1, 0.1)),
    Setting("lean_s", DEFAULT_LEAN_S, "forward pelvis offset per commanded speed, s", True, (0.0, 0.5)),
    Setting("stance_feedback", 0.0, "gain of the stance leg's posture feedback", True, (0.0, 1.0)),
    Setting("stance_deadzone_m", 0.02, "dead-zone threshold of the posture feedback, m", True, (0.0, None)),
    Setting("adjustment_tau_s", 0.0, "time constant of a filter on the applied adjustment, s", True, (0.0, 1.0)),
    Setting("ramp_start_steps", 2, "in-place steps before the speed ramps up", True, (0.0, None)),
    Setting("ramp_steps", 4, "steps over which the speed ramps to the command", True, (0.0, None)),
    Setting("start_sway_m", 0.02, "lateral pelvis sway of the start-up phase, m", True, (0.0, None)),
)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "nominal_base", "nominal_per_mps", "footstep_table", "step_time_s", "step_width_m",
        "h1_m", "pelvis_height_m", "lift_m", "roll_amp_rad", "adaptive_lift_gain", "foot_pitch_gain",
        "zeta", "deadzone", "footstep_gain", "hold_adjustment", "max_adjustment_m", "mu_left_rad", "mu_right_rad",
        "weight_n", "hip_switch", "posture_q_rad", "ramp_start_steps", "ramp_steps", "start_sway_m",
        "stance_feedback", "ankle_compliance", "pelvis_offset_m", "stance_deadzone_m",
        "lean_s", "adjustment_tau_s", "hip_attack",
    ],
    meta_fields=["ticks_per_step", "dt_s", "window", "knee_rad"],
)
@dataclasses.dataclass(frozen=True)
class Config:
    """Everything the controller reads (arrays; vmappable, tunable), plus static sizes.

    Attributes:
        nominal_base: (n + 1, 2, 6) nominal 3LP state per tick at zero speed, ``d = +1``.
        nominal_per_mps: (n + 1, 2, 6) its change per m/s of commanded speed.
        footstep_table: (n, 4) table B of Figure 13 (sagittal): final swing
            foot adjustment per unit error, per tick of the phase.
        step_time_s: T, s (``ticks_per_step * dt_s``; built into the tables, not tunable).
        step_width_m: lateral distance of the feet, m (built into the tables).
        h1_m: 3LP pelvis height (truncation, attack angle, eq. 28-29), m.
        pelvis_height_m: crouched pelvis-point height above the foot points, m.
        lift_m, roll_amp_rad: fixed lift (eq. 23) and pelvis roll (eq. 22) amplitudes.
        adaptive_lift_gain: 1 applies eq. 29, 0 turns it off.
        foot_pitch_gain: 1 applies eq. 30, 0 turns it off.
        zeta: IIR constant per tick (eq. 26).
        deadzone: (4,) thresholds of eq. 27 for the sagittal ``[e1, e2, e1_dot, e2_dot]``.
        footstep_gain: scale of the footstep adjustment (1 closed loop; 0 makes
            the controller open loop, which shares one compiled walk).
        hold_adjustment: blend ``h`` of the adjustment of the phase start, held
            for the phase (the DLQR law, the seed's baseline), and the fresh time
            projection of every tick: ``h held + (1 - h) fresh``.
        max_adjustment_m: largest footstep adjustment, m (0.35 ``h1``).
        mu_left_rad, mu_right_rad: knee deflections of eq. 21, rad.
        weight_n: total weight ``m g`` of eq. 21, N.
        hip_switch: 1 applies the torso switch of eq. 24 to the hip pitch joints, 0 tracks the IK.
        posture_q_rad: (23,) crouched posture for the joints the IK does not set.
        ramp_start_steps: in-place phases before the speed ramps up.
        ramp_steps: phases over which the speed ramps from 0 to the command.
        start_sway_m: lateral pelvis sway of the start-up phase, m (see :func:`controller.step`).
        stance_feedback: gain ``f`` of the stance leg's posture feedback: the
            stance leg's IK target puts the pelvis at ``nominal + f dz(e2)``
            relative to the stance foot (sagittal), ``dz`` the smooth dead-zone of
            eq. 27 with threshold ``stance_deadzone_m`` (0: the seed's nominal stance targets).
        stance_deadzone_m: threshold of that dead-zone, m.
        lean_s: forward pelvis offset per commanded speed, s (m per m/s): moves
            the nominal pelvis ahead by ``lean_s v`` while walking at ``v``.
        adjustment_tau_s: time constant of a first-order filter on the applied
            footstep adjustment, s (0: applied at once, as the seed does).
        hip_attack: share ``a`` of the footstep adjustment ``Delta`` applied as
            the seed's attack angle on the swing hip: ``a Delta / h1`` is
            added to the swing hip pitch (forward) and taken off the swing ankle
            pitch (foot orientation kept), the knee left to the lift; the rest,
            ``(1 - a) Delta``, moves the IK's swing-foot target
            (:func:`~mjx_coman.controllers.time_projection.controller.joint_targets_block`).
        ankle_compliance: share ``c`` of the measured link angle in the stance
            ankle pitch target, ``(1 - c) q_ik + c q_link``: it scales the stance
            ankle's stiffness against posture errors by ``1 - c``
            (:func:`~mjx_coman.controllers.time_projection.controller.motor_targets_block`).
        pelvis_offset_m: sagittal offset of the nominal pelvis from the 3LP
            pelvis over the stance foot point, m (negative: behind; -0.03 puts it
            over the ankle axis, the pivot of a compliant ankle).
        ticks_per_step: n, control ticks per phase (static).
        dt_s: control period, s (static).
        window: velocity moving-average length, samples (static).
        knee_rad: knee flexion of the crouched posture the walk starts from and
            the IK keeps (static; the rollout resets the env to it).
    """

    nominal_base: jax.Array
    nominal_per_mps: jax.Array
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
    hold_adjustment: jax.Array
    max_adjustment_m: jax.Array
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

    def replace(self, **kw) -> "Config":
        return dataclasses.replace(self, **kw)


def _check(name: str, value, lo=None, hi=None, lo_open=False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} must be a number") from None
    if not np.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi):
        raise ValueError(f"{name}={value!r} is out of range"
                         + (f" (must be {'>' if lo_open else '>='} {lo})" if lo is not None else "")
                         + (f" (must be <= {hi})" if hi is not None else ""))
    return v


def design_weight_n(robot: str) -> float:
    """Total weight ``m g`` the knee compensation (eq. 21) assumes, N: the packaged MJCF's for ``coman-mjcf``."""
    return _design_weight_n(robot, bool(jax.config.jax_enable_x64))


@functools.lru_cache(maxsize=8)
def _design_weight_n(robot: str, x64: bool) -> float:
    if robot == DESIGN_ROBOT:
        from mjx_coman import load_model

        m = load_model()
        mass = np.asarray(jnp.asarray(m.body_mass)).sum()  # in JAX's float width, as the MJX model holds it
        return float(mass) * float(-np.asarray(jnp.asarray(m.opt.gravity))[2])
    from jaxlp.presets import get_params

    p = get_params(robot)
    return float(p.total_mass_kg * p.g)


@functools.lru_cache(maxsize=16)
def _design_tables(robot: str, T: float, n: int, dt: float, step_width_m: float, lqr_weight_scale: tuple):
    """Per-tick nominal gait (zero speed and per m/s) and table B, designed in 64-bit floats, once per design.

    One jitted computation (a few hundred small eager ops would each compile); the
    3LP design runs in 64 bits whatever the walk's precision, as the 3LP analysis does.
    """
    from jaxlp.presets import get_params

    ws = np.asarray(lqr_weight_scale)

    def build(p):
        g0 = gait_mod.periodic_gait(p, T, 0.0, step_width_m)
        g1 = gait_mod.periodic_gait(p, T, 0.1, step_width_m)
        ts = jnp.arange(n + 1) * dt
        nom0 = jax.vmap(lambda t: gait_mod.nominal_state(p, g0, t))(ts)
        nom1 = jax.vmap(lambda t: gait_mod.nominal_state(p, g1, t))(ts)
        per_mps = ((nom1 - nom0) / 0.1).at[:, 1].set(0.0)  # only the sagittal gait depends on the speed (linearly)
        weights = None
        if not np.allclose(ws, 1.0):
            weights = control.default_weights(p).scaled(ws)
        ctrl = control.constrained_dlqr(p, T, weights)
        return nom0, per_mps, projection.gain_table(p, ctrl, T, n).footstep

    with jax.enable_x64(True):  # host_eval runs in this float width
        return host_eval(build, get_params(robot))


def make_config(
    *,
    robot: str = DESIGN_ROBOT,
    step_time_s: float = 0.4,
    control_period_s: float = 0.002,
    step_width_m: float = DEFAULT_STEP_WIDTH_M,
    knee_rad: float = 0.4,
    window: int = est.VELOCITY_WINDOW,
    lqr_weight_scale=(1.0, 1.0, 1.0),
    deadzone=DEFAULT_DEADZONE,
    zeta: float = 0.1,
    footstep_gain: float = 1.0,
    hold_adjustment: float = 0.0,
    max_adjustment_m: float | None = None,
    hip_attack: float = DEFAULT_HIP_ATTACK,
    mu_left_rad: float = DEFAULT_KNEE_DEFLECTION_RAD,
    mu_right_rad: float = DEFAULT_KNEE_DEFLECTION_RAD,
    lift_m: float = FIXED_LIFT_M,
    roll_amp_rad: float = ROLL_AMP_RAD,
    adaptive_lift_gain: float = 1.0,
    foot_pitch_gain: float = 1.0,
    hip_switch: float = 1.0,
    ankle_compliance: float = DEFAULT_ANKLE_COMPLIANCE,
    pelvis_offset_m: float = DEFAULT_PELVIS_OFFSET_M,
    lean_s: float = DEFAULT_LEAN_S,
    stance_feedback: float = 0.0,
    stance_deadzone_m: float = 0.02,
    adjustment_tau_s: float = 0.0,
    ramp_start_steps: int = 2,
    ramp_steps: int = 4,
    start_sway_m: float = 0.02,
) -> Config:
    """Validated config (host function, not jittable); the settings are those of :data:`SETTINGS`.

    Raises:
        ValueError: naming the bad value.
    """
    from jaxlp.presets import get_params

    params3 = get_params(robot)
    weight = design_weight_n(robot)
    dt = _check("control_period_s", control_period_s, 0.0, lo_open=True)
    T = _check("step_time_s", step_time_s, 0.0, lo_open=True)
    n = int(round(T / dt))
    if n < 2 or abs(n * dt - T) > 1e-6:
        raise ValueError(f"step_time_s={step_time_s} must be a whole number (>= 2) of control periods {dt}")
    _check("step_width_m", step_width_m, 0.0, 0.4)
    _check("zeta", zeta, 0.0, 1.0, lo_open=True)
    if isinstance(window, bool) or int(window) != window or window < 1:
        raise ValueError(f"window={window!r} must be a positive whole number of samples")
    dz = np.asarray(deadzone, float)
    if dz.shape != (4,) or not np.all(np.isfinite(dz)) or np.any(dz <= 0):
        raise ValueError(f"deadzone={np.asarray(deadzone).tolist()} must be 4 positive thresholds")
    ws = np.asarray(lqr_weight_scale, float)
    if ws.shape != (3,) or not np.all(np.isfinite(ws)) or np.any(ws <= 0):
        raise ValueError(f"lqr_weight_scale={np.asarray(lqr_weight_scale).tolist()} must be 3 positive numbers")
    for name, val in (("mu_left_rad", mu_left_rad), ("mu_right_rad", mu_right_rad),
                      ("footstep_gain", footstep_gain), ("lift_m", lift_m), ("roll_amp_rad", roll_amp_rad),
                      ("ramp_start_steps", ramp_start_steps), ("ramp_steps", ramp_steps),
                      ("start_sway_m", start_sway_m)):
        _check(name, val, 0.0)
    for name, val in (("adaptive_lift_gain", adaptive_lift_gain), ("foot_pitch_gain", foot_pitch_gain),
                      ("hip_switch", hip_switch), ("stance_feedback", stance_feedback),
                      ("ankle_compliance", ankle_compliance), ("hip_attack", hip_attack),
                      ("hold_adjustment", hold_adjustment)):
        _check(name, val, 0.0, 1.0)
    _check("knee_rad", knee_rad, 0.05, 1.5)

    trunc = filters.FOOTSTEP_TRUNCATION_RATIO * float(params3.h1) if max_adjustment_m is None else max_adjustment_m
    _check("max_adjustment_m", trunc, 0.0, lo_open=True)
    _check("pelvis_offset_m", pelvis_offset_m, -0.1, 0.1)
    _check("stance_deadzone_m", stance_deadzone_m, 0.0, lo_open=True)
    _check("lean_s", lean_s, 0.0, 0.5)
    _check("adjustment_tau_s", adjustment_tau_s, 0.0, 1.0)
    nom0, per_mps, table = _design_tables(robot, T, n, dt, float(step_width_m), tuple(float(w) for w in ws))
    posture, _ = standing_posture(float(knee_rad))
    f = jnp.result_type(float)
    a = lambda x: jnp.asarray(x, f)  # noqa: E731
    return Config(
        nominal_base=a(nom0), nominal_per_mps=a(per_mps), footstep_table=a(table),
        step_time_s=a(T), step_width_m=a(step_width_m), h1_m=a(params3.h1),
        pelvis_height_m=a(crouched_pelvis_height_m(float(knee_rad))), lift_m=a(lift_m),
        roll_amp_rad=a(roll_amp_rad), adaptive_lift_gain=a(adaptive_lift_gain), foot_pitch_gain=a(foot_pitch_gain),
        zeta=a(zeta), deadzone=a(dz), footstep_gain=a(footstep_gain), hold_adjustment=a(hold_adjustment),
        max_adjustment_m=a(trunc),
        mu_left_rad=a(mu_left_rad), mu_right_rad=a(mu_right_rad), weight_n=a(weight), hip_switch=a(hip_switch),
        posture_q_rad=a(posture), ramp_start_steps=a(ramp_start_steps), ramp_steps=a(ramp_steps),
        start_sway_m=a(start_sway_m), stance_feedback=a(stance_feedback), ankle_compliance=a(ankle_compliance),
        pelvis_offset_m=a(pelvis_offset_m), stance_deadzone_m=a(stance_deadzone_m),
        lean_s=a(lean_s), adjustment_tau_s=a(adjustment_tau_s), hip_attack=a(hip_attack),
        ticks_per_step=n, dt_s=dt, window=int(window), knee_rad=float(knee_rad),
    )
