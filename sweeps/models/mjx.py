"""The ``mjx`` sweep model: one pushed walk of COMAN in MuJoCo MJX (:func:`mjx_coman.walking.rollout.walk`).

The walk starts from the crouched stance under the walking controller of
:mod:`mjx_coman.walking.controller`, which first runs one start-up phase, so
walking step ``k`` starts at ``(k + 1) * step_time_s``. The push, on the upper
torso, starts at ``(push_step + 1 + phase) * step_time_s`` as in ``python -m
mjx_coman.walk`` and lasts ``push_duration_s``; the walk lasts ``(n_steps +
1) * step_time_s`` (the start-up phase and ``n_steps`` walking steps). The
environment is :func:`mjx_coman.walking.rollout.walking_env_params` (the
seed's gains with a stiffer ankle roll loop), when it exists.

Per rollout, from the rollout's own PRNG key (so results do not depend on
chunking or devices), the simulated robot may differ from the nominal one the
controller was designed for:

* ``randomize_mass_pct``: every body's mass and inertia scaled by its own ``1 + U(-1, 1) pct / 100``;
* ``randomize_spring_pct``: each SEA spring stiffness scaled by its own ``1 + U(-1, 1) pct / 100``;
* ``randomize_delay_ticks``: the transport delay shifted by a uniform integer in ``[-k, k]`` ticks;
* ``sensor_noise_scale``: IMU, gyro and F/T noise at that multiple of COMAN's nominal levels
  (0: noise-free; the 12-bit encoders always quantise);
* ``encoder_offset_std_rad``: constant link encoder offsets ``N(0, std)`` per joint.

The controller parameters are built once on the host by
:func:`mjx_coman.walking.controller.make_controller_params`, with the
configuration's estimation constants (``deadzone``, ``zeta``,
``velocity_window``; e.g. tuned ones) where it sets them. Everything
randomised is an array leaf of the environment parameters, built inside the
vmapped rollout, which is the same as vmapping ``walk`` with the axes of
:func:`mjx_coman.env.batch_axes` (``model_fields=("body_mass", "body_inertia")``).

While ``mjx_coman.walking.rollout`` does not exist, :func:`load` returns an
unavailable model (the command line exits 2 naming it).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io

import jax
import jax.numpy as jnp

from sweeps.grid import SweepConfig
from sweeps.models import Model, RolloutInputs, RolloutOutputs

UNAVAILABLE = "model 'mjx': the MJX walking controller is not available yet ({}); use --model 3lp"
CONTROL_PERIOD_S = 0.002


def _walking():
    """The walking controller and rollout modules (ImportError while they do not exist)."""
    with contextlib.redirect_stdout(io.StringIO()):  # mujoco.mjx prints "Failed to import warp" without Warp
        from mjx_coman.walking import controller, rollout
    return controller, rollout


@functools.lru_cache(maxsize=4)
def nominal_env(sensor_noise_scale: float):
    """The nominal robot's environment parameters with the sensor noise scaled (host-built, cached)."""
    _, rollout_mod = _walking()  # first: imports mujoco.mjx quietly
    from mjx_coman.env import make_env_params
    from mjx_coman.sensors import make_sensor_params

    with jax.ensure_compile_time_eval():
        s = sensor_noise_scale
        d = make_sensor_params()
        sensor = make_sensor_params(imu_orientation_noise_rad=float(d.imu_orientation_noise_rad) * s,
                                    gyro_noise_rad_per_s=float(d.gyro_noise_rad_per_s) * s,
                                    ft_force_noise_n=float(d.ft_force_noise_n) * s,
                                    ft_torque_noise_nm=float(d.ft_torque_noise_nm) * s)
        if hasattr(rollout_mod, "walking_env_params"):
            return dataclasses.replace(rollout_mod.walking_env_params(), sensor=sensor)
        return make_env_params(control_period_s=CONTROL_PERIOD_S, sensor=sensor)


@functools.lru_cache(maxsize=4)
def nominal(config: SweepConfig):
    """``(env_params, ctrl_params)`` of the nominal robot (host-built, cached per configuration)."""
    controller, _ = _walking()
    env = nominal_env(config.sensor_noise_scale)
    constants = dict(deadzone=config.deadzone, zeta=config.zeta, window=config.velocity_window)
    with jax.ensure_compile_time_eval():
        ctrl = controller.make_controller_params(env, config.speed_mps, step_time_s=config.step_time_s,
                                                 **{k: v for k, v in constants.items() if v is not None})
    return env, ctrl


def walk_spec(config: SweepConfig):
    """The static :class:`mjx_coman.walking.rollout.WalkSpec` of a sweep."""
    _, rollout_mod = _walking()
    return rollout_mod.WalkSpec(controller=config.controller, speed_mps=None,
                                seconds=(config.n_steps + 1) * config.step_time_s, step_time_s=config.step_time_s,
                                record_every=50)


def ticks_per_rollout(config: SweepConfig) -> int:
    """Control ticks (2 ms, each 2 physics steps of 1 ms) of one walk."""
    _, rollout_mod = _walking()
    return rollout_mod.sizes(walk_spec(config), nominal(config)[1])[0]


def env_step_s(config: SweepConfig) -> float:
    """One environment step (control tick), s."""
    return CONTROL_PERIOD_S


def randomized_env(env, config: SweepConfig, key):
    """``env`` with this rollout's masses, springs, delay and encoder offsets (traceable)."""
    from mjx_coman.actuators import MAX_DELAY_TICKS

    k_mass, k_spring, k_delay, k_enc = jax.random.split(key, 4)
    model, act, sen = env.model, env.actuator, env.sensor
    if config.randomize_mass_pct > 0:
        nb = model.body_mass.shape[0]
        s = 1.0 + jax.random.uniform(k_mass, (nb,), minval=-1.0, maxval=1.0) * config.randomize_mass_pct / 100.0
        model = model.replace(body_mass=model.body_mass * s.astype(model.body_mass.dtype),
                              body_inertia=model.body_inertia * s[:, None].astype(model.body_inertia.dtype))
    if config.randomize_spring_pct > 0:
        k = act.spring_stiffness_nm_per_rad
        s = 1.0 + jax.random.uniform(k_spring, k.shape, minval=-1.0, maxval=1.0) * config.randomize_spring_pct / 100.0
        act = dataclasses.replace(act, spring_stiffness_nm_per_rad=k * s.astype(k.dtype))
    if config.randomize_delay_ticks > 0:
        shift = jax.random.randint(k_delay, (), -config.randomize_delay_ticks, config.randomize_delay_ticks + 1)
        act = dataclasses.replace(act, delay_ticks=jnp.clip(act.delay_ticks + shift, 0, MAX_DELAY_TICKS)
                                  .astype(act.delay_ticks.dtype))
    if config.encoder_offset_std_rad > 0:
        off = sen.encoder_offset_rad
        sen = dataclasses.replace(sen, encoder_offset_rad=off + config.encoder_offset_std_rad
                                  * jax.random.normal(k_enc, off.shape, off.dtype))
    return dataclasses.replace(env, model=model, actuator=act, sensor=sen)


def rollout(config: SweepConfig, inputs: RolloutInputs, aux) -> RolloutOutputs:
    """One pushed walk (see the module docstring)."""
    _, rollout_mod = _walking()
    env, ctrl = nominal(config)
    key = jax.random.wrap_key_data(inputs.key, impl="threefry2x32")
    walk_key, robot_key = jax.random.split(key)
    env = randomized_env(env, config, robot_key)
    f = ctrl.zeta.dtype
    mag = inputs.impulse_ns / config.push_duration_s
    force = jnp.stack([mag * jnp.cos(inputs.direction_rad), mag * jnp.sin(inputs.direction_rad), 0.0 * mag])
    start_s = (config.push_step + 1 + inputs.phase) * config.step_time_s  # after the start-up phase
    push = rollout_mod.WalkPush(start_s=jnp.asarray(start_s, f),
                                duration_s=jnp.asarray(config.push_duration_s, f), force_n=force.astype(f))
    r = rollout_mod.walk(env, ctrl, push, walk_spec(config), walk_key)
    return RolloutOutputs(
        fell=r.fell, steps_to_recover=r.steps_to_recover.astype(jnp.int32),
        max_abs_footstep_adjustment_m=r.max_abs_footstep_adjustment_m, fall_time_s=r.fall_time_s, nan=r.nan,
    )


def prepare(config: SweepConfig, inputs: RolloutInputs):
    """Build (and cache) the nominal robot and controller outside the sharded call's trace."""
    nominal(config)
    return None


def load() -> Model:
    """The registry entry (unavailable while the MJX walking controller does not exist)."""
    try:
        _walking()
    except ImportError as e:
        return Model(None, lambda config: 0, unavailable=UNAVAILABLE.format(e))
    return Model(rollout, ticks_per_rollout, prepare=prepare, env_step_s=env_step_s)
