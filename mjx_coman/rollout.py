"""Walks of the simulated COMAN under any registered controller, judged on ground truth: ``walk``.

``walk`` resets the environment to the controller's crouched stance, then
runs one ``lax.scan`` of (controller step, env step) ticks, the push force
applied to the upper torso while it lasts. The controller sees only its
:class:`~mjx_coman.controllers.base.Observation`; the verdict (fell,
touchdowns, steps to recover, mean speed) comes from the simulator through
:mod:`mjx_coman.ground_truth`, the same for every controller. A fall is a
result: a tick whose pelvis drops or tilts too far, whose state goes
non-finite, or whose controller reports a failed solve (``Telemetry.ok``)
freezes the rollout at its last good state and is recorded (``fell``,
``fall_time_s``; ``nan`` and ``solve_failed`` say why).

What to record is a function of the rollout state (as diffrax's
``SaveAt(fn=...)``): ``SaveAt(fn, every)`` keeps ``fn(RolloutState)`` every
``every`` ticks in ``WalkResult.saved``; without one nothing is kept but the
verdict and the touchdown log, which is what a sweep needs.

``walk`` is pure: jit it with the controller, spec and save static
(:func:`jit_walk`, one compilation per controller family, shared by its
variants) and vmap it over pushes, keys, joysticks, configs and environment
parameters (:func:`batched_walk`; ``mjx_coman.env.batch_axes``).
"""

from __future__ import annotations

import functools
import math
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_coman import env as env_mod
from mjx_coman import ground_truth as gt
from mjx_coman.controllers.base import Joystick, Observation, Telemetry, joystick as make_joystick
from mjx_coman.plants import (SEA_TORQUE_DELAY_S, WALKING_ANKLE_ROLL_KP_V_PER_RAD,  # noqa: F401 (the walk's API)
                              plant_env_params, walking_env_params)
from mjx_coman.pushes import Push, make_push, no_push, push_force  # noqa: F401 (the walk's API)


class WalkSpec(NamedTuple):
    """Static choices of a walk (hashable; changing one recompiles).

    Attributes:
        seconds: walk duration, s (rounded up to whole control ticks, and to whole ``SaveAt.every``).
        judge: the ground-truth thresholds (:class:`mjx_coman.ground_truth.Judge`).
        checkpoint: rematerialize for reverse mode (``jax.checkpoint``): each tick keeps only its input
            carry, and segments of ticks (the ``SaveAt`` records, else :func:`segment_ticks`) keep only theirs,
            so a gradient's memory grows as segments + ticks per segment, not as ticks x one tick's residuals.
            The primal and forward mode are unchanged.
    """

    seconds: float = 10.0
    judge: gt.Judge = gt.Judge()
    checkpoint: bool = False

    def validate(self) -> "WalkSpec":
        if not (isinstance(self.seconds, (int, float)) and math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds={self.seconds!r} must be a finite positive number")
        if not isinstance(self.checkpoint, bool):
            raise ValueError(f"checkpoint={self.checkpoint!r} must be True or False")
        self.judge.validate()
        return self


class SaveAt(NamedTuple):
    """What to record: ``fn(RolloutState) -> pytree`` every ``every`` ticks (hashable: a module-level ``fn``)."""

    fn: Callable[["RolloutState"], Any]
    every: int = 10


class RolloutState(NamedTuple):
    """What a save function sees after a tick.

    Attributes:
        env: the simulation (``mjx.Data``, actuators, readings).
        ctrl: the controller's state.
        telemetry: the controller's telemetry of the tick.
        command: the command it sent (before the delay line).
        time_s: the end of the tick, s (runs on after a fall; the env clock is frozen).
    """

    env: env_mod.EnvState
    ctrl: Any
    telemetry: Telemetry
    command: env_mod.Command
    time_s: jax.Array


class WalkResult(NamedTuple):
    """Outcome of one walk (ground truth).

    Attributes:
        fell: it fell (or went non-finite).
        fall_time_s: when (``inf`` if it did not).
        nan: the simulation, the command or the common telemetry went non-finite (also counted in ``fell``;
            ``Telemetry.extra`` is left out: a failed solve may report infinite residuals there).
        solve_failed: the controller reported a failed solve (``Telemetry.ok`` False; also counted in ``fell``).
        touchdowns: feet landings before any fall (:class:`mjx_coman.ground_truth.Touchdowns`).
        steps_to_recover: see :mod:`mjx_coman.ground_truth` (0 unpushed, -1 fell or never settled).
        mean_speed_mps: forward CoM speed over the last half of the touchdowns.
        max_abs_footstep_adjustment_m: largest |planned footstep adjustment| the controller reported.
        log: the touchdown log.
        step_velocity_mps: (n, 2) step velocities of the log (:func:`mjx_coman.ground_truth.step_velocities`).
        cycle_velocity_mps: (2,) the limit cycle the walk ends in, the recovery's reference.
        time_s: (n_rec,) times of the records (``None`` without ``SaveAt``).
        saved: the records (leading axis ``n_rec``; ``None`` without ``SaveAt``).
    """

    fell: jax.Array
    fall_time_s: jax.Array
    nan: jax.Array
    solve_failed: jax.Array
    touchdowns: jax.Array
    steps_to_recover: jax.Array
    mean_speed_mps: jax.Array
    max_abs_footstep_adjustment_m: jax.Array
    log: gt.Touchdowns
    step_velocity_mps: jax.Array
    cycle_velocity_mps: jax.Array
    time_s: Any = None
    saved: Any = None


class _Carry(NamedTuple):
    env: env_mod.EnvState
    ctrl: Any
    telemetry: Telemetry
    command: env_mod.Command
    judge: gt.JudgeState
    fallen: jax.Array
    nan: jax.Array
    failed: jax.Array
    fall_time: jax.Array
    max_adj: jax.Array


def _all_finite(tree) -> jax.Array:
    leaves = [x for x in jax.tree_util.tree_leaves(tree) if jnp.issubdtype(jnp.asarray(x).dtype, jnp.floating)]
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))


def batched_like(tree, *refs):
    """``tree`` with a zero from every leaf of ``refs`` added: under ``vmap``, batched wherever a ref is.

    A scan's batching rule re-batches its body until the carries it makes batched are batched on entry too;
    a carry that starts as a constant (a zero counter, an empty record) costs one more pass per level of
    nesting. The zero is an integer ``x & 0``, which XLA folds away: only the trace changes.
    """
    zero = jnp.zeros((), jnp.int32)
    for x in jax.tree_util.tree_leaves(refs):
        x = jnp.asarray(x)
        if x.size and not jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            zero = zero + (jnp.ravel(x)[0].astype(jnp.int32) & 0)

    def add(x):
        x = jnp.asarray(x)
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            return x  # a typed key: left as it is
        return x | zero.astype(bool) if x.dtype == bool else x + zero.astype(x.dtype)

    return jax.tree_util.tree_map(add, tree)


def _select(pred, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


def _concrete(x) -> np.ndarray | None:
    """``x`` as NumPy, or ``None`` while tracing."""
    try:
        return np.asarray(x)
    except jax.errors.TracerArrayConversionError:
        return None


def n_ticks(spec: WalkSpec, control_period_s: float, save: SaveAt | None = None) -> int:
    """Control ticks of a walk (static): ``seconds`` rounded up to whole ticks and whole records."""
    every = 1 if save is None else int(save.every)
    return int(math.ceil(round(spec.seconds / control_period_s, 6) / every)) * every


def segment_ticks(total: int) -> int:
    """The largest divisor of ``total`` not above ``sqrt(total)``: the length of the checkpointed segments of
    a walk without records (a prime ``total`` gets segments of 1 tick: memory then grows with the ticks)."""
    return max(d for d in range(1, math.isqrt(max(int(total), 1)) + 1) if total % d == 0)


def check_walk(controller, config, env_params, joystick: Joystick | None = None, privileged_ok: bool = False) -> None:
    """The checks :func:`walk` makes on concrete inputs (host; also call it before tracing a batch).

    Raises:
        ValueError: a privileged controller without ``privileged_ok``, an env
            whose control period is not the controller's, or a joystick beyond
            what the controller walks.
    """
    if controller.privileged and not privileged_ok:
        raise ValueError(f"controller {getattr(controller, 'name', '')!r} reads the simulator's ground truth; "
                         "pass privileged_ok=True to run it beside controllers that do not")
    if config is None:
        return
    gait = controller.gait(config)
    dt = _concrete(env_params.control_period_s)
    if dt is not None and dt.ndim == 0 and abs(float(dt) - gait.control_period_s) > 1e-6:
        raise ValueError(f"the environment's control period {float(dt):g} s differs from the controller's "
                         f"{gait.control_period_s:g} s")
    if joystick is not None:
        vals = [_concrete(v) for v in joystick]
        if all(v is not None for v in vals):
            gait.check_joystick(*(float(np.max(np.abs(v))) for v in vals))


def walk(controller, config, env_params: env_mod.EnvParams, push: Push, key: jax.Array, spec: WalkSpec = WalkSpec(),
         joystick: Joystick | None = None, save: SaveAt | None = None, privileged_ok: bool = False) -> WalkResult:
    """One walk from the controller's crouched stance (pure; jit with ``controller``, ``spec``, ``save`` static).

    Args:
        controller: a :class:`~mjx_coman.controllers.base.Controller` (or its ``core()``).
        config: its config pytree (:func:`mjx_coman.controllers.load`).
        env_params: environment parameters.
        push: the torso push (:func:`no_push` for none).
        key: PRNG key (sensor noise; the controller's ``init`` gets ``fold_in(key, 1)``).
        spec: static choices.
        joystick: commanded velocities (default: stand / walk in place).
        save: what to record (``None``: the verdict only).
        privileged_ok: allow a controller that reads ground truth.

    Returns:
        A :class:`WalkResult`.

    Raises:
        ValueError: see :func:`check_walk`, and a bad spec.
    """
    spec.validate()
    check_walk(controller, config, env_params, joystick, privileged_ok)
    gait = controller.gait(config)
    joystick = make_joystick() if joystick is None else joystick
    dt = gait.control_period_s
    total = n_ticks(spec, dt, save)
    judge = spec.judge

    env0 = env_mod.reset(key, env_params, gait.knee_rad)
    f = env0.time_s.dtype
    ctrl0 = controller.init(config, env_params, jax.random.fold_in(key, 1))
    obs0 = Observation(env0.readings, joystick, jnp.zeros((), f), env0.data if controller.privileged else None)
    step = jax.jit(controller.step)  # traced once: the shapes below, then the tick reuses the trace
    shapes = jax.eval_shape(step, config, ctrl0, obs0)
    tel0, cmd0 = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), (shapes[2], shapes[1]))
    carry0 = _Carry(env=env0, ctrl=ctrl0, telemetry=tel0, command=cmd0, judge=gt.init(judge, spec.seconds, f),
                    fallen=jnp.zeros((), bool), nan=jnp.zeros((), bool), failed=jnp.zeros((), bool), fall_time=jnp.full((), jnp.inf, f),
                    max_adj=jnp.zeros((), f))
    carry0 = batched_like(carry0, key, push, config)

    def tick(c: _Carry, k):
        time = k.astype(f) * dt
        obs = Observation(c.env.readings, joystick, time, c.env.data if controller.privileged else None)
        cs, cmd, tel = step(config, c.ctrl, obs)
        cmd = cmd._replace(torso_force_n=push_force(push, time, dt).astype(f))
        e = env_mod.step(env_params, c.env, cmd)
        finite = _all_finite((e.data.qpos, e.data.qvel, e.actuator.motor_angle_rad, cmd, tel._replace(extra=())))
        failed = jnp.zeros((), bool) if tel.ok is None else ~jnp.asarray(tel.ok, bool)
        bad = ~finite | failed | gt.fallen(e.data, judge)
        stop = c.fallen | bad
        new = _Carry(env=e, ctrl=cs, telemetry=tel, command=cmd, judge=gt.update(c.judge, e.data, time + dt, dt, judge),
                     fallen=c.fallen, nan=c.nan, failed=c.failed, fall_time=c.fall_time,
                     max_adj=jnp.maximum(c.max_adj, jnp.linalg.norm(tel.footstep_adjustment_m)))
        out = _select(stop, c, new)
        out = out._replace(fallen=stop, nan=c.nan | (~c.fallen & ~finite), failed=c.failed | (~c.fallen & failed),
                           fall_time=jnp.where(bad & ~c.fallen, time + dt, c.fall_time))
        return out, None

    remat = jax.checkpoint if spec.checkpoint else (lambda fn: fn)
    tick = remat(tick)
    if save is None and not spec.checkpoint:
        c, _ = jax.lax.scan(tick, carry0, jnp.arange(total))
        time_s = saved = None
    elif save is None:
        seg = segment_ticks(total)

        def segment(c: _Carry, k0):
            return jax.lax.scan(tick, c, k0 + jnp.arange(seg))[0], None

        c, _ = jax.lax.scan(remat(segment), carry0, jnp.arange(total // seg) * seg)
        time_s = saved = None
    else:
        every = int(save.every)

        def record(c: _Carry, k0):
            c, _ = jax.lax.scan(tick, c, k0 + jnp.arange(every))
            t = (k0 + every).astype(f) * dt
            return c, (t, save.fn(RolloutState(c.env, c.ctrl, c.telemetry, c.command, t)))

        c, (time_s, saved) = jax.lax.scan(remat(record), carry0, jnp.arange(total // every) * every)

    pushed = jnp.any(push.force_n != 0)
    v = gt.verdict(c.judge.log, push.start_s + push.duration_s, pushed, c.fallen, judge)
    return WalkResult(
        fell=c.fallen, fall_time_s=c.fall_time, nan=c.nan, solve_failed=c.failed, touchdowns=c.judge.log.count,
        steps_to_recover=v.steps_to_recover, mean_speed_mps=v.mean_speed_mps, max_abs_footstep_adjustment_m=c.max_adj,
        log=c.judge.log, step_velocity_mps=v.step_velocity_mps, cycle_velocity_mps=v.cycle_velocity_mps, time_s=time_s,
        saved=saved,
    )


def pelvis_and_com(state: RolloutState) -> dict:
    """A save function: pelvis and CoM positions (world), pelvis yaw and the common telemetry without ``extra``."""
    return dict(pelvis_m=gt.pelvis_m(state.env.data), com_m=gt.com_m(state.env.data),
                pelvis_yaw_rad=gt.pelvis_yaw_rad(state.env.data),
                telemetry=state.telemetry._replace(extra=()))


def pelvis_com_and_torque(state: RolloutState) -> dict:
    """:func:`pelvis_and_com` and the torques: the link torque of the tick's last physics step
    (``data.ctrl``) and the command's target (the controller's, before the transport delay)."""
    return dict(pelvis_and_com(state), link_torque_nm=state.env.data.ctrl, command_nm=state.command.target)


def _build(core, spec: WalkSpec, save, privileged_ok: bool, axes):
    def one(config, env_params, push, key, joystick):
        return walk(core, config, env_params, push, key, spec, joystick, save, privileged_ok)

    return jax.jit(one if axes is None else jax.vmap(one, in_axes=axes))


_cached = functools.lru_cache(maxsize=64)(_build)


def _jitted(controller, spec, save, privileged_ok, axes):
    if controller.privileged and not privileged_ok:
        check_walk(controller, None, None, privileged_ok=False)
    try:
        return _cached(controller.core(), spec, save, privileged_ok, axes)
    except TypeError:  # unhashable axes (an EnvParams of in_axes): compiled per call site
        return _build(controller.core(), spec, save, privileged_ok, axes)


def jit_walk(controller, spec: WalkSpec = WalkSpec(), save: SaveAt | None = None, privileged_ok: bool = False):
    """``fn(config, env_params, push, key, joystick)``: :func:`walk` jitted, shared by the family's variants.

    Keep the returned function to reuse its compilation (it is also cached per family, spec and save).
    """
    return _jitted(controller, spec, save, privileged_ok, None)


def batched_walk(controller, spec: WalkSpec = WalkSpec(), save: SaveAt | None = None, *, config_axes=None,
                 env_axes=None, joystick_axes=None, privileged_ok: bool = False):
    """:func:`walk` jitted and vmapped over ``(push, key)`` (leading axis), optionally configs, envs, joysticks.

    Args:
        config_axes: ``None`` shares the config, ``0`` batches every leaf.
        env_axes: ``None`` shares the env params, or ``in_axes`` from ``mjx_coman.env.batch_axes``.
        joystick_axes: ``None`` shares the joystick, ``0`` batches it.

    Returns:
        ``fn(config, env_params, push, key, joystick) -> WalkResult`` with a leading batch axis.
    """
    return _jitted(controller, spec, save, privileged_ok, (config_axes, env_axes, 0, 0, joystick_axes))
