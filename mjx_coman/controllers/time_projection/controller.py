"""The time-projection walking controller of the simulated COMAN (seed 000, Figure 3).

One pure ``init``/``step`` pair of the controller interface
(:mod:`mjx_coman.controllers.base`); ``step`` maps the sensor readings of a
2 ms tick and the joystick's forward speed to the motor position targets of
:class:`mjx_coman.env.Command`:

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
   ``ramp_start_steps`` in-place phases. The nominal pelvis is moved
   ``pelvis_offset_m + lean_s v`` forward of the 3LP one (default 3 cm back,
   over the ankle axis: the pivot of the compliant stance ankle below; the 3LP
   foot point is 3 cm ahead of it, and a pelvis held above the foot point
   makes the body fall forward and walk off at about 0.1 m/s).
3. **Estimation**: link encoders + IMU -> relative pelvis/feet positions ->
   IIR (eq. 26) -> velocities -> error ``e`` (eq. 15)
   (:mod:`~mjx_coman.controllers.time_projection.estimation`), sagittal error through the smooth
   dead-zones (eq. 27). Run as a privileged controller (``observation.truth``
   given: ``push-table --truth-estimate``) it takes the simulator's true
   relative positions instead of the sensors', to measure what the estimate costs.
4. **Footstep adjustment**: table B of Figure 13 (``jaxlp.projection``): the
   final swing-foot adjustment ``Delta = b(t) . e`` relative to the pelvis,
   truncated at 0.35 ``h1`` and converted to the attack angle ``Delta / h1``
   (:func:`jaxlp.filters.footstep_to_attack_angle`). A share ``hip_attack``
   (default 0.75) of it goes, as in the seed, onto the swing hip pitch joint
   (the swing ankle pitch takes the opposite angle so the foot keeps its
   orientation; the knee keeps the lift); the rest is realised by the IK as
   the horizontal foot shift ``h1 * angle`` it stands for. All through the
   IK, a target beyond the crouched leg's reach (about 9 cm ahead of the hip
   at the crouched height) straightens the knee, and at the start of the
   swing after a forward push that pushes the trailing, still loaded foot
   into the ground instead of lifting it: the closed loop then recovered
   5 N s at every phase instead of 6-7.
   On the hip the attack angle moves the foot by ``l sin(angle)`` (crouched
   leg ``l = 0.417 m``) and lifts it by ``l (1 - cos angle)``.
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
   (eq. 24; ``pitch`` the IMU pelvis pitch, forward lean > 0). The stance
   ankle pitch target blends in the measured link angle
   (``ankle_compliance``, :func:`motor_targets_block`): the simulated ankle
   is about ten times stiffer than the seed's worn one. With the former
   diagonal DLQR cost the stiff ankle threw the body over every adjusted
   footstep (a forward walk of 0.3 m/s in place); with the authors' cost it
   drifts 0.009 m/s in place, but the open loop then recovers nearly what the
   closed loop does (README, "Seed 000 on the simulated COMAN"), so the
   default keeps the compliant ankle the seed's claims were made with.

Variants are configurations of the same compiled step (registered in
:mod:`mjx_coman.controllers`): ``time-projection`` (the closed loop),
``no-deadzone`` (thresholds of 1e-7: eq. 27 then shifts the error by at most
1e-7), ``dlqr`` (``hold_adjustment = 1``: the adjustment of table B at the
phase start, i.e. of the DLQR law, held for the phase: the seed's baseline)
and ``open-loop`` (``footstep_gain = 0``: no footstep adjustment; adaptive
lift and orientation feedback stay on, as in the seed's Figure 18).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp import filters
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT, Observation, Telemetry
from mjx_coman.controllers.time_projection import estimation as est
from mjx_coman.controllers.time_projection.config import Config
from mjx_coman.controllers.time_projection.open_loop import (
    LEFT_HIP_PITCH,
    LEFT_KNEE,
    LEFT_LEG_INDEX,
    RIGHT_HIP_PITCH,
    RIGHT_KNEE,
    RIGHT_LEG_INDEX,
    hip_switch_gamma,
    joint_targets,
    knee_compensation,
    targets_from_state,
)
from mjx_coman.env import MODE_POSITION, Command
from mjx_coman.sensors import Readings

LEFT_ANKLE_PITCH = int(LEFT_LEG_INDEX[5])
RIGHT_ANKLE_PITCH = int(RIGHT_LEG_INDEX[5])


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
        held_m: the adjustment of the phase start (held when ``hold_adjustment = 1``), m.
    """

    tick: jax.Array
    step: jax.Array
    d: jax.Array
    filt: filters.FilterState
    force_n: jax.Array
    error: jax.Array
    adjustment_m: jax.Array
    held_m: jax.Array


class Extra(NamedTuple):
    """The controller-specific part of the telemetry.

    Attributes:
        error: (2, 4) filtered error (eq. 15) per axis, before the dead-zone.
        d: phase sign, +1 left swing, -1 right swing.
        measured_rel_m: (2, 2) relative positions from encoders + IMU (unfiltered).
        adjustment_m: sagittal footstep adjustment applied, m.
    """

    error: jax.Array
    d: jax.Array
    measured_rel_m: jax.Array
    adjustment_m: jax.Array


def init(params: Config, env_params=None, key=None) -> ControllerState:
    """The state at the crouched stance: the start-up phase (``step = -1``, ``d = -1``) begins.

    ``env_params`` and ``key`` (of the controller interface) are not used.
    """
    f = params.zeta.dtype
    z = jnp.zeros((), f)
    return ControllerState(
        tick=jnp.zeros((), jnp.int32), step=jnp.full((), -1, jnp.int32), d=-jnp.ones((), f),
        filt=est.estimator_init(params.window, f), force_n=jnp.full((2,), 0.5, f) * params.weight_n,
        error=jnp.zeros((2, 4), f), adjustment_m=z, held_m=z,
    )


def speed_factor(params: Config, step) -> jax.Array:
    """Share of the commanded speed in phase ``step``: 0 in place, then a linear ramp to 1."""
    ramp = jnp.maximum(params.ramp_steps, 1.0)
    return jnp.clip((step - params.ramp_start_steps + 1.0) / ramp, 0.0, 1.0)


def nominal_at(params: Config, tick, step, d, speed_mps, pelvis_offset_m=0.0) -> jax.Array:
    """(2, 6) nominal 3LP state at ``tick`` of phase ``step`` (lateral axis signed by ``d``; eq. 10).

    ``speed_mps`` is the commanded speed (ramped in by :func:`speed_factor`);
    ``pelvis_offset_m`` moves the nominal pelvis forward (sagittal), m.
    """
    v = speed_mps * speed_factor(params, step)
    q = params.nominal_base[tick] + v * params.nominal_per_mps[tick]
    q = q * jnp.stack([jnp.ones_like(d), d])[:, None]
    return q.at[0, 1].add(pelvis_offset_m)


def footstep_block(params: Config, tick, error_sag, held_m):
    """Footstep adjustment of table B (Figure 13), truncated at ``max_adjustment_m``.

    The fresh time projection ``b(t) . e`` of this tick is blended with the
    adjustment of the phase start by ``hold_adjustment`` (1: the DLQR law held
    for the phase).

    Returns:
        ``(adjustment_m, held_m)``: the adjustment to apply now and the phase start's.
    """
    k = jnp.minimum(tick, params.ticks_per_step - 1)
    fresh = params.footstep_table[k] @ error_sag
    held = jnp.where(tick == 0, fresh, held_m)
    raw = params.hold_adjustment * held + (1.0 - params.hold_adjustment) * fresh
    angle = filters.footstep_to_attack_angle(params.footstep_gain * raw, params.h1_m, params.max_adjustment_m)
    return angle * params.h1_m, held


def lift_block(params: Config, t_s, error_sag, adjustment_m):
    """Adaptive lift (eq. 28-29) and foot orientation feedback (eq. 30).

    Returns:
        ``(extra_lift_m, swing_pitch_rad, theta_hat_rad)``.
    """
    theta = jnp.arctan((error_sag[1] - error_sag[0] + adjustment_m) / params.h1_m)
    sine = jnp.sin(jnp.pi * jnp.clip(t_s / params.step_time_s, 0.0, 1.0))
    lift = params.adaptive_lift_gain * params.h1_m * (1.0 - jnp.cos(theta)) * sine
    return lift, -params.foot_pitch_gain * theta, theta


def joint_targets_block(params: Config, q_nominal, t_s, d, adjustment_m, extra_lift_m,
                        swing_pitch_rad, pelvis_shift_m=None, walking=1.0, stance_shift_m=None) -> jax.Array:
    """(23,) desired joint angles: 3LP targets + lifts + footstep adjustment -> IK (Figure 3, A-B).

    Args:
        pelvis_shift_m: (3,) extra pelvis displacement in the heading frame (start-up sway), m.
        walking: 1 while walking, 0 in the start-up phase (no lift, no roll).
        stance_shift_m: sagittal shift of the pelvis from the stance foot in the
            stance leg's target only (posture feedback), m.

    The footstep adjustment ``adjustment_m`` is split by ``params.hip_attack``
    (``a``): ``(1 - a) Delta`` moves the swing foot target of the IK, and the
    attack angle ``a Delta / h1`` (seed 000, "Footstep Adjustment") is then
    added to the swing hip pitch (forward, i.e. subtracted from the joint
    angle) and to the swing ankle pitch (keeping the foot's orientation).
    """
    c = targets_from_state(q_nominal, params.step_width_m, t_s, d, params.pelvis_height_m,
                           walking * params.lift_m, walking * params.roll_amp_rad, params.step_time_s)
    shift = jnp.stack([(1.0 - params.hip_attack) * adjustment_m, jnp.zeros_like(adjustment_m), extra_lift_m])
    pelvis = jnp.zeros(3, c.swing_m.dtype) if pelvis_shift_m is None else pelvis_shift_m
    stance = c.stance_m - pelvis
    if stance_shift_m is not None:
        stance = stance.at[0].add(-stance_shift_m)
    c = c._replace(swing_m=c.swing_m + shift - pelvis, stance_m=stance)
    q = joint_targets(c, d, params.posture_q_rad, swing_pitch_rad)
    attack = params.hip_attack * adjustment_m / params.h1_m
    left = (jnp.asarray(d) > 0).astype(q.dtype)  # static joint indices: no traced index dtypes under x64
    q = q.at[LEFT_HIP_PITCH].add(-left * attack).at[LEFT_ANKLE_PITCH].add(left * attack)
    return q.at[RIGHT_HIP_PITCH].add((left - 1.0) * attack).at[RIGHT_ANKLE_PITCH].add((1.0 - left) * attack)


def motor_targets_block(params: Config, q_des, t_s, d, force_n, readings: Readings,
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


def step(params: Config, state: ControllerState, obs: Observation
         ) -> tuple[ControllerState, Command, Telemetry]:
    """One control tick: readings and commanded speed -> motor position targets (seed 000, Figure 3).

    Args:
        params: the config.
        state: controller memory.
        obs: this tick's observation (readings; ``joystick.forward_mps`` is the speed).

    Returns:
        The new state, the :class:`mjx_coman.env.Command` (position mode, zero
        torso force) and the :class:`~mjx_coman.controllers.base.Telemetry`
        (``extra``: :class:`Extra`).
    """
    readings = obs.readings
    speed = obs.joystick.forward_mps
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
    lean = params.lean_s * speed * speed_factor(params, step_idx)
    offset = (params.pelvis_offset_m + lean) * ramp_in
    q_nom = nominal_at(params, tick, step_idx, d, speed, offset)
    raw = est.measure_relative(readings, d) if obs.truth is None else est.true_relative(obs.truth, d)
    filt, e = est.estimator_step(filt, raw, q_nom, d, params.zeta, params.dt_s)
    err = filters.smooth_deadzone(e.error[0], params.deadzone)
    adj, held = footstep_block(params, tick, err, state.held_m)
    adj = walking * adj
    previous = jnp.where(swap, 0.0, state.adjustment_m)  # a new swing leg starts from its nominal target
    alpha = params.dt_s / (params.adjustment_tau_s + params.dt_s)
    adj = previous + alpha * (adj - previous)
    lift, pitch, _ = lift_block(params, t, err, adj)
    sway = (1.0 - walking) * params.start_sway_m * jnp.sin(jnp.pi * t / params.step_time_s)
    pelvis_shift = jnp.stack([jnp.zeros_like(sway), sway, jnp.zeros_like(sway)])
    stance_shift = walking * params.stance_feedback * filters.smooth_deadzone(e.error[0, 1], params.stance_deadzone_m)
    q_des = joint_targets_block(params, q_nom, t, d, adj, walking * lift, walking * pitch, pelvis_shift, walking,
                                stance_shift)
    force = filters.iir(state.force_n, readings.foot_normal_force_n, params.zeta)
    target = motor_targets_block(params, q_des, t, d, force, readings, walking)
    new = ControllerState(tick=tick + 1, step=step_idx, d=d, filt=filt, force_n=force, error=e.error,
                          adjustment_m=adj, held_m=held)
    command = Command(target.astype(readings.motor_angle_rad.dtype), jnp.zeros(3, target.dtype), jnp.asarray(MODE_POSITION, jnp.int32))
    return new, command, telemetry(params, tick, step_idx, d, speed, adj, e, raw)


def telemetry(params: Config, tick, step_idx, d, speed_mps, adjustment_m, estimate: est.Estimate, raw_m
              ) -> Telemetry:
    """The common telemetry: support, phase, planned landing (nominal + adjustment), estimated pelvis state."""
    end = nominal_at(params, params.ticks_per_step, step_idx, d, speed_mps)
    landing = (end[:, 0] - end[:, 2]) * (step_idx >= 0)  # nominal swing - stance at the phase end
    adj = jnp.stack([adjustment_m, jnp.zeros_like(adjustment_m)])
    support = jnp.where(step_idx < 0, SUPPORT_DOUBLE, jnp.where(d > 0, SUPPORT_RIGHT, SUPPORT_LEFT))
    return Telemetry(
        support=support.astype(jnp.int32), step=step_idx, phase=tick.astype(d.dtype) / params.ticks_per_step,
        next_footstep_m=landing + adj, footstep_adjustment_m=adj,
        com_m=estimate.pos_m[:, 1], com_vel_mps=estimate.vel_mps[:, 1],
        extra=Extra(error=estimate.error, d=d, measured_rel_m=raw_m, adjustment_m=adjustment_m),
    )


__all__ = [
    "Config", "ControllerState", "Extra", "init", "step", "telemetry",
    "nominal_at", "footstep_block", "lift_block", "joint_targets_block", "motor_targets_block", "speed_factor",
]
