"""Walks of the simulated COMAN under the walking controller, with a push: ``walk``.

``walk`` resets the environment to the crouched stance, then runs one
``lax.scan`` of (controller step, env step) ticks, the push force applied to
the upper torso while it lasts. Falls are results: a tick whose pelvis drops
below ``fall_height_m`` or tilts beyond ``max_tilt_rad``, or whose state goes
non-finite, freezes the whole rollout at its last good state and is recorded
(``fell``, ``fall_time_s``; ``nan`` says it was a non-finite state). Nothing
non-finite reaches the outputs.

``walk`` is a pure function: jit it with ``spec`` static
(:func:`jit_walk`) and vmap it over pushes, keys, controller parameters and
environment parameters (``mjx_coman.env.batch_axes``); :func:`batched_walk`
builds the jitted vmap.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_coman import env as env_mod
from mjx_coman import load_model
from mjx_coman.actuators import JOINT_INDEX, default_kp_v_per_rad, make_actuator_params
from mjx_coman.kinematics import quat_to_rot
from mjx_coman.sensors import model_ids
from mjx_coman.walking import controller as ctl
from mjx_coman.walking import estimation as est


WALKING_ANKLE_ROLL_KP_V_PER_RAD = 100.0


def walking_env_params(ankle_roll_kp_v_per_rad: float = WALKING_ANKLE_ROLL_KP_V_PER_RAD,
                       **actuator_kwargs) -> env_mod.EnvParams:
    """Environment parameters for walking: the seed's gains except a stiffer ankle roll loop.

    The seed sets the ankle roll gain "to a small value" (10 V/rad, eq. 25) so
    the foot settles on the floor. On the simulated robot that ankle (22 N m/rad
    through the motor) leaves the single-support body free to topple sideways
    over its soft ankle roll, and every in-place walk tried with it fell
    sideways within 2.5 s; 100 V/rad (and 500) walked. Other gains follow
    :func:`mjx_coman.actuators.default_kp_v_per_rad`.

    Args:
        ankle_roll_kp_v_per_rad: ankle roll position gain, V/rad (> 0).
        **actuator_kwargs: passed to :func:`mjx_coman.actuators.make_actuator_params`
            (``kp_v_per_rad`` there overrides the gains, ankle roll included).

    Raises:
        ValueError: a non-positive gain (and what ``make_actuator_params`` rejects).
    """
    if not (math.isfinite(ankle_roll_kp_v_per_rad) and ankle_roll_kp_v_per_rad > 0):
        raise ValueError(f"ankle_roll_kp_v_per_rad={ankle_roll_kp_v_per_rad!r} must be finite and positive")
    if "kp_v_per_rad" not in actuator_kwargs:
        kp = default_kp_v_per_rad()
        for side in "RL":
            kp[JOINT_INDEX[side + "AnkLat"]] = ankle_roll_kp_v_per_rad
        actuator_kwargs["kp_v_per_rad"] = kp
    return env_mod.make_env_params(actuator=make_actuator_params(**actuator_kwargs))


class WalkSpec(NamedTuple):
    """Static choices of a walk (hashable; changing one recompiles).

    Attributes:
        controller: one of :data:`mjx_coman.walking.controller.CONTROLLERS`.
        speed_mps: ``None`` walks at the controller parameters' speed (an
            array, no recompilation); a float overrides it.
        seconds: walk duration, s.
        step_time_s: T, s; must match the controller parameters.
        record_every: keep every Nth tick of the trajectories.
        fall_height_m: a pelvis lower than this above the floor is a fall, m.
        max_tilt_rad: a pelvis tilted further from upright is a fall, rad.
        recover_tol_m, recover_tol_mps: a phase change counts as recovered when
            the filtered sagittal pelvis error (eq. 15, ``e2`` and ``e2_dot``, the
            pelvis relative to the stance foot) is within these, m and m/s
            (unpushed in-place walking stays within about 0.03 m and 0.15 m/s).
    """

    controller: str = "time-projection"
    speed_mps: float | None = None
    seconds: float = 10.0
    step_time_s: float = 0.4
    record_every: int = 10
    fall_height_m: float = 0.3
    max_tilt_rad: float = 0.8
    recover_tol_m: float = 0.03
    recover_tol_mps: float = 0.2

    def validate(self) -> "WalkSpec":
        if self.controller not in ctl.CONTROLLERS:
            raise ValueError(f"unknown controller {self.controller!r}; choose one of {', '.join(ctl.CONTROLLERS)}")
        for name in ("seconds", "step_time_s", "fall_height_m", "max_tilt_rad", "recover_tol_m", "recover_tol_mps"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} must be a finite positive number")
        if int(self.record_every) != self.record_every or self.record_every < 1:
            raise ValueError(f"record_every={self.record_every!r} must be a positive integer")
        if self.speed_mps is not None and not (math.isfinite(self.speed_mps)
                                               and abs(self.speed_mps) <= ctl.MAX_SPEED_MPS):
            raise ValueError(f"speed_mps={self.speed_mps!r} must be finite and within +-{ctl.MAX_SPEED_MPS}")
        return self


class WalkPush(NamedTuple):
    """A push on the upper torso (arrays; vmappable).

    Attributes:
        start_s: start time from the walk's start, s.
        duration_s: duration, s.
        force_n: (3,) force in the world frame, N.
    """

    start_s: jax.Array
    duration_s: jax.Array
    force_n: jax.Array


def no_push() -> WalkPush:
    """A zero push."""
    return WalkPush(jnp.zeros(()), jnp.zeros(()), jnp.zeros(3))


def make_push(start_s, duration_s=0.1, force_n=None, *, impulse_ns=None, direction_rad=0.0) -> WalkPush:
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
    return WalkPush(jnp.asarray(s, f), jnp.asarray(dur, f), jnp.asarray(force, f))


class WalkTrace(NamedTuple):
    """Signals at every ``record_every``-th tick (leading axis ``n_rec``).

    Attributes:
        error: (n_rec, 4) filtered sagittal error ``[e1, e2, e1_dot, e2_dot]`` (eq. 15), before the dead-zone.
        adjustment_m: (n_rec,) footstep adjustment applied.
        d: (n_rec,) phase sign.
        measured_rel_m: (n_rec, 2, 2) relative positions from encoders + IMU (unfiltered).
        true_rel_m: (n_rec, 2, 2) the same from the simulator's true poses.
        knee_deflection_rad: (n_rec, 2) knee spring deflection link - motor (left, right), from the encoders.
        foot_force_n: (n_rec, 2) foot normal forces (left, right), N.
        pelvis_rpy_rad: (n_rec, 3) IMU roll, pitch, yaw of the pelvis, rad.
        target_rad: (n_rec, 23) motor position targets sent at the recorded tick (before the delay).
        link_angle_rad: (n_rec, 23) link encoder readings, rad.
    """

    error: jax.Array
    adjustment_m: jax.Array
    d: jax.Array
    measured_rel_m: jax.Array
    true_rel_m: jax.Array
    knee_deflection_rad: jax.Array
    foot_force_n: jax.Array
    pelvis_rpy_rad: jax.Array
    target_rad: jax.Array
    link_angle_rad: jax.Array


class WalkResult(NamedTuple):
    """Outcome of one walk.

    Attributes:
        fell: it fell (or went non-finite).
        fall_time_s: when (``inf`` if it did not).
        steps: phase changes done after the start-up phase (before a fall): the
            index of the last walking phase begun (the start-up phase is -1).
        steps_to_recover: phase changes after the one that ends the push until
            the filtered sagittal pelvis error stays within ``recover_tol_m`` and
            ``recover_tol_mps`` at every later phase change; 0 without a push; -1
            if it fell or never settled.
        max_abs_footstep_adjustment_m: largest |footstep adjustment| applied.
        mean_speed_mps: pelvis x displacement over time across the last half of
            the whole phases walked (at least two phases; 0 otherwise).
        nan: the state went non-finite (also counted in ``fell``).
        pelvis_m: (n_rec, 3) pelvis position, world frame.
        footsteps_m: (n_steps_max, 3) world position of each walking phase's stance
            foot point at the phase start (index 0 the right foot after the start-up
            phase; k >= 1 where the swing foot had landed at the k-th phase change); nan-padded.
        phase_error: (n_steps_max, 4) filtered sagittal error at each phase start; nan-padded.
        pelvis_at_step_m: (n_steps_max, 3) pelvis position at each phase start; nan-padded.
        time_s: (n_rec,) time of the records, s.
        trace: :class:`WalkTrace`.
    """

    fell: jax.Array
    fall_time_s: jax.Array
    steps: jax.Array
    steps_to_recover: jax.Array
    max_abs_footstep_adjustment_m: jax.Array
    mean_speed_mps: jax.Array
    nan: jax.Array
    pelvis_m: jax.Array
    footsteps_m: jax.Array
    phase_error: jax.Array
    pelvis_at_step_m: jax.Array
    time_s: jax.Array
    trace: WalkTrace


class _Carry(NamedTuple):
    env: env_mod.EnvState
    ctrl: ctl.ControllerState
    fallen: jax.Array
    nan: jax.Array
    fall_time: jax.Array
    max_adj: jax.Array
    footsteps: jax.Array
    phase_error: jax.Array
    pelvis_at_step: jax.Array
    target: jax.Array


def _push_force(push: WalkPush, t0, dt):
    """Mean push force over the tick ``[t0, t0 + dt]`` (exact impulse)."""
    overlap = jnp.clip(jnp.minimum(t0 + dt, push.start_s + push.duration_s) - jnp.maximum(t0, push.start_s), 0.0, dt)
    return push.force_n * overlap / dt


def _tilt_rad(quat) -> jax.Array:
    """Angle between the pelvis z axis and the vertical."""
    return jnp.arccos(jnp.clip(quat_to_rot(quat)[2, 2], -1.0, 1.0))


def _all_finite(tree) -> jax.Array:
    leaves = [x for x in jax.tree_util.tree_leaves(tree) if jnp.issubdtype(x.dtype, jnp.floating)]
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))


def _select(pred, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


@functools.lru_cache(maxsize=1)
def foot_body_ids() -> tuple[int, int]:
    """MuJoCo ids of the (left, right) foot bodies (their origin is the ankle centre)."""
    m = load_model()
    return (mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "LFoot"),
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "RFoot"))


def sizes(spec: WalkSpec, ctrl_params: ctl.ControllerParams) -> tuple[int, int, int]:
    """``(n_ticks, n_rec, n_steps_max)`` of a walk (static)."""
    dt = ctrl_params.dt_s
    n_rec = int(math.ceil(round(spec.seconds / dt, 6) / spec.record_every))
    n_ticks = n_rec * spec.record_every
    return n_ticks, n_rec, n_ticks // ctrl_params.ticks_per_step + 1


def walk(env_params: env_mod.EnvParams, ctrl_params: ctl.ControllerParams, push: WalkPush, spec: WalkSpec,
         key: jax.Array) -> WalkResult:
    """One walk from the crouched stance (pure; jit with ``spec`` static).

    Args:
        env_params: environment parameters.
        ctrl_params: controller parameters (:func:`~mjx_coman.walking.controller.make_controller_params`).
        push: the torso push (:func:`no_push` for none).
        spec: static choices; ``seconds`` is rounded up to whole ``record_every`` ticks.
        key: PRNG key (sensor noise).

    Returns:
        A :class:`WalkResult`.

    Raises:
        ValueError: a bad spec, or a step time that differs from the controller's.
    """
    spec.validate()
    if abs(ctrl_params.ticks_per_step * ctrl_params.dt_s - spec.step_time_s) > 1e-6:
        raise ValueError(f"spec.step_time_s={spec.step_time_s} differs from the controller's "
                         f"{ctrl_params.ticks_per_step * ctrl_params.dt_s}")
    if spec.speed_mps is not None:
        ctrl_params = ctrl_params.replace(speed_mps=jnp.asarray(spec.speed_mps, ctrl_params.speed_mps.dtype))
    n_ticks, n_rec, n_steps_max = sizes(spec, ctrl_params)
    dt = ctrl_params.dt_s
    foot_ids = foot_body_ids()
    pelvis_id = model_ids()["pelvis_body"]

    env0 = env_mod.reset(key, env_params, ctrl_params.knee_rad)
    f = env0.time_s.dtype
    nanpad = lambda *shape: jnp.full(shape, jnp.nan, f)  # noqa: E731
    feet0 = est.foot_points_world(env0.data, foot_ids)
    carry0 = _Carry(
        env=env0, ctrl=ctl.init(ctrl_params), fallen=jnp.zeros((), bool), nan=jnp.zeros((), bool),
        fall_time=jnp.full((), jnp.inf, f), max_adj=jnp.zeros((), f),
        footsteps=nanpad(n_steps_max, 3).at[0].set(feet0[1]), phase_error=nanpad(n_steps_max, 4),
        pelvis_at_step=nanpad(n_steps_max, 3).at[0].set(env0.data.xpos[pelvis_id]),
        target=env0.actuator.motor_angle_rad,
    )

    def tick(c: _Carry, k):
        time = k.astype(f) * dt
        cs, cmd = ctl.step(ctrl_params, c.ctrl, c.env.readings, spec.controller)
        cmd = cmd._replace(torso_force_n=_push_force(push, time, dt).astype(f))
        e = env_mod.step(env_params, c.env, cmd)
        finite = _all_finite((e.data.qpos, e.data.qvel, e.actuator.motor_angle_rad, cs.error, cs.adjustment_m))
        low = e.data.xpos[pelvis_id, 2] < spec.fall_height_m
        tilted = _tilt_rad(e.data.xquat[pelvis_id]) > spec.max_tilt_rad
        bad = ~finite | low | tilted
        stop = c.fallen | bad
        changed = (cs.tick == 1) & (cs.step > c.ctrl.step)  # the controller swapped feet this tick
        idx = jnp.minimum(cs.step, n_steps_max - 1)
        feet = est.foot_points_world(e.data, foot_ids)
        stance = jnp.where(cs.d > 0, feet[1], feet[0])
        rec = lambda arr, val: jnp.where(changed & ~stop, arr.at[idx].set(val), arr)  # noqa: E731
        new = _Carry(
            env=e, ctrl=cs, fallen=c.fallen, nan=c.nan, fall_time=c.fall_time,
            max_adj=jnp.maximum(c.max_adj, jnp.abs(cs.adjustment_m)),
            footsteps=rec(c.footsteps, stance), phase_error=rec(c.phase_error, cs.error[0]),
            pelvis_at_step=rec(c.pelvis_at_step, e.data.xpos[pelvis_id]), target=cmd.target,
        )
        out = _select(stop, c, new)
        out = out._replace(
            fallen=stop, nan=c.nan | (~c.fallen & ~finite),
            fall_time=jnp.where(bad & ~c.fallen, time + dt, c.fall_time),
        )
        return out, None

    def record(c: _Carry, k0):
        c, _ = jax.lax.scan(tick, c, k0 + jnp.arange(spec.record_every))
        e, cs = c.env, c.ctrl
        left, right = est.true_feet(e.data, foot_ids, pelvis_id)
        true_rel = est.relative_from_feet(left, right, cs.d)
        force = e.readings.foot_normal_force_n
        trace = WalkTrace(
            error=cs.error[0], adjustment_m=cs.adjustment_m, d=cs.d,
            measured_rel_m=est.measure_relative(e.readings, cs.d), true_rel_m=true_rel,
            knee_deflection_rad=est.knee_deflection_rad(e.readings), foot_force_n=jnp.stack([force[1], force[0]]),
            pelvis_rpy_rad=e.readings.imu_rpy_rad, target_rad=c.target, link_angle_rad=e.readings.link_angle_rad,
        )
        time = (k0 + spec.record_every).astype(f) * dt  # runs on after a fall (the env clock is frozen)
        return c, (time, e.data.xpos[pelvis_id], trace)

    c, (time_s, pelvis, trace) = jax.lax.scan(record, carry0, jnp.arange(n_rec) * spec.record_every)
    steps = c.ctrl.step
    T = spec.step_time_s

    # Steps to recover: phase changes after the one ending the push until the error stays small.
    ks = jnp.arange(n_steps_max)
    done = ks <= steps
    small = (jnp.abs(c.phase_error[:, 1]) <= spec.recover_tol_m) & (jnp.abs(c.phase_error[:, 3]) <= spec.recover_tol_mps)
    ok = jnp.where(done & (ks >= 1), small, True)
    settled = jnp.flip(jnp.cumprod(jnp.flip(ok))).astype(bool)  # ok from k on
    push_end = push.start_s + push.duration_s
    pushed = jnp.any(push.force_n != 0)
    push_step = jnp.floor(push_end / T).astype(jnp.int32) - 1  # walking phase in which the push ends (start-up = -1)
    first = jnp.min(jnp.where(settled & (ks > push_step) & done, ks, n_steps_max))
    recovered = (first < n_steps_max) & ~c.fallen & (steps > push_step)
    steps_to_recover = jnp.where(pushed, jnp.where(recovered, first - push_step, -1),
                                 jnp.where(c.fallen, -1, 0)).astype(jnp.int32)

    # Mean speed over the last half of the whole phases.
    k1 = steps
    k0 = steps // 2
    x = jnp.nan_to_num(c.pelvis_at_step[:, 0])
    span = (k1 - k0).astype(f) * T
    speed = jnp.where(k1 - k0 >= 2, (x[k1 % n_steps_max] - x[k0]) / jnp.maximum(span, T), 0.0)
    return WalkResult(
        fell=c.fallen, fall_time_s=c.fall_time, steps=steps, steps_to_recover=steps_to_recover,
        max_abs_footstep_adjustment_m=c.max_adj, mean_speed_mps=speed, nan=c.nan, pelvis_m=pelvis,
        footsteps_m=c.footsteps, phase_error=c.phase_error, pelvis_at_step_m=c.pelvis_at_step, time_s=time_s,
        trace=trace,
    )


jit_walk = jax.jit(walk, static_argnames=("spec",))


def batched_walk(spec: WalkSpec, env_axes=None, ctrl_axes=None):
    """A jitted ``walk`` vmapped over ``(push, key)`` (leading axis), optionally env/controller params too.

    Args:
        spec: static walk choices.
        env_axes: ``None`` shares the env params, or ``in_axes`` from ``mjx_coman.env.batch_axes``.
        ctrl_axes: ``None`` shares the controller params, or ``0`` to batch every leaf.

    Returns:
        ``fn(env_params, ctrl_params, push, key) -> WalkResult`` with a leading batch axis.
        Keep the returned function to reuse its compilation.
    """
    fn = jax.vmap(lambda e, cp, p, k: walk(e, cp, p, spec, k), in_axes=(env_axes, ctrl_axes, 0, 0))
    return jax.jit(fn)
