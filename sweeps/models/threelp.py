"""The ``3lp`` sweep model: one push on the closed-loop 3LP model of :mod:`jaxlp.simulate`.

The controller's plan (gait, tick transitions, DLQR gains, time-projection
tables: :func:`jaxlp.simulate.make_plan`) is computed outside the sharded
rollout: once per configuration for the nominal robot, or per rollout in
:func:`prepare` when the robot is randomised (each robot gets the controller
designed for it, as the seed designs the 3LP controller from the robot's
parameters).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.presets import get_params
from jaxlp.simulate import Push, SimSpec, make_plan, make_sensing, simulate
from sweeps.grid import SweepConfig
from sweeps.models import Model, RolloutInputs, RolloutOutputs


def _spec(config: SweepConfig) -> SimSpec:
    return SimSpec(step_time_s=config.step_time_s, n_steps=config.n_steps, controller=config.controller,
                   sensing=config.sensing)


def ticks_per_rollout(config: SweepConfig) -> int:
    """Control ticks (2 ms) of one 3LP rollout."""
    return _spec(config).ticks_per_step * config.n_steps


def env_step_s(config: SweepConfig) -> float:
    """One control tick, s."""
    return _spec(config).dt_s


def randomized_params(params, key, mass_pct: float, leg_pct: float):
    """Scale ``m1``, ``m2`` by ``1 + U(-1, 1) mass_pct %`` each, the leg by ``1 + U(-1, 1) leg_pct %``.

    A longer leg scales ``h1`` and ``h2`` alike and ``I2`` as mass x length^2.
    """
    u = jax.random.uniform(key, (3,), minval=-1.0, maxval=1.0, dtype=params.m1.dtype)
    s_m1 = 1.0 + u[0] * mass_pct / 100.0
    s_m2 = 1.0 + u[1] * mass_pct / 100.0
    s_leg = 1.0 + u[2] * leg_pct / 100.0
    return dataclasses.replace(
        params, m1=params.m1 * s_m1, m2=params.m2 * s_m2, h1=params.h1 * s_leg, h2=params.h2 * s_leg,
        I2=params.I2 * s_m2 * s_leg**2,
    )


def _keys(key_data):
    """``(noise_key, robot_key)`` of a rollout's key."""
    return jax.random.split(jax.random.wrap_key_data(key_data, impl="threefry2x32"))


def _randomized(config: SweepConfig) -> bool:
    return config.randomize_mass_pct > 0 or config.randomize_leg_pct > 0


@functools.lru_cache(maxsize=16)
def nominal_plan(config: SweepConfig):
    """The plan of the nominal robot (concrete arrays; cached per configuration and float width)."""
    with jax.ensure_compile_time_eval():  # concrete even when first asked for while tracing
        params = get_params(config.robot)
        plan = jax.jit(lambda p: make_plan(p, _spec(config), config.speed_mps))(params)
    return jax.tree_util.tree_map(np.asarray, plan)  # host constants, valid on every device


def _robot_and_plan(config: SweepConfig, key_data):
    params = randomized_params(get_params(config.robot), _keys(key_data)[1], config.randomize_mass_pct,
                               config.randomize_leg_pct)
    return params, make_plan(params, _spec(config), config.speed_mps)


@functools.lru_cache(maxsize=16)
def _prepare_fn(config: SweepConfig):
    return jax.jit(jax.vmap(lambda key_data: _robot_and_plan(config, key_data)))


def prepare(config: SweepConfig, inputs: RolloutInputs):
    """Per-rollout randomised robots and their plans (``None`` for the nominal robot)."""
    if not _randomized(config):
        nominal_plan(config)  # computed here, outside the sharded call's trace
        return None
    out = _prepare_fn(config)(jnp.asarray(inputs.key))
    return jax.tree_util.tree_map(np.asarray, out)


def rollout(config: SweepConfig, inputs: RolloutInputs, aux) -> RolloutOutputs:
    """One push on the 3LP model of ``config.robot`` under ``config.controller``.

    The push starts at ``(push_step + phase) * step_time_s`` and lasts
    ``push_duration_s`` with force ``impulse_ns / push_duration_s``. With
    randomisation ``aux`` holds this rollout's robot and plan; with noise or
    bias the measurements pass through jaxlp's filters (noise from the
    rollout's own PRNG stream).
    """
    if aux is None:
        params, plan = get_params(config.robot), jax.tree_util.tree_map(jnp.asarray, nominal_plan(config))
    else:
        params, plan = aux
    noise_key = _keys(inputs.key)[0]
    T = config.step_time_s
    dtype = params.m1.dtype
    push = Push(
        start_s=jnp.asarray((config.push_step + inputs.phase) * T, dtype),
        duration_s=jnp.asarray(config.push_duration_s, dtype),
        force_n=jnp.asarray(inputs.impulse_ns / config.push_duration_s, dtype),
        direction_rad=jnp.asarray(inputs.direction_rad, dtype),
    )
    sensing = None
    if config.sensing:
        sensing = make_sensing(noise_std_m=config.noise_std_m, bias_m=[[0.0, config.bias_m], [0.0, 0.0]])
    r = simulate(params, push, _spec(config), speed_mps=config.speed_mps, sensing=sensing, key=noise_key, plan=plan)
    finite = (jnp.all(jnp.isfinite(r.pelvis_m)) & jnp.all(jnp.isfinite(r.footstep_adjustment_m))
              & jnp.all(jnp.isfinite(r.step_error)))
    return RolloutOutputs(
        fell=r.fell,
        steps_to_recover=r.steps_to_recover.astype(jnp.int32),
        max_abs_footstep_adjustment_m=jnp.max(jnp.abs(r.footstep_adjustment_m)),
        fall_time_s=r.fall_time_s,
        nan=~finite,
    )


def load() -> Model:
    """The registry entry."""
    return Model(rollout, ticks_per_rollout, prepare=prepare, env_step_s=env_step_s)
