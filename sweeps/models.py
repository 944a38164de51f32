"""The rollout registry: one pure function per model, ``rollout(config, inputs) -> outputs``.

A rollout simulates one push on one robot and returns a few scalars
(:class:`RolloutOutputs`). The runner vmaps it over a chunk of rollouts, jits
it once per configuration and shards the chunk over the local devices, so a
model only has to be a pure, jittable function of scalars.

Registered models:

* ``3lp``: the closed-loop 3LP simulation of :func:`jaxlp.simulate.simulate`.
* ``mjx``: COMAN in MuJoCo MJX; a placeholder until the MJX walking controller
  exists (asking for it raises :class:`ModelUnavailable`). To add it, write
  ``mjx_rollout(config, inputs) -> RolloutOutputs`` and register it with
  ``register_model("mjx", Model(mjx_rollout, mjx_ticks_per_rollout))``.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from sweeps.grid import SweepConfig


class ModelUnavailable(RuntimeError):
    """A registered model that cannot run yet (the command line exits 2)."""


class RolloutInputs(NamedTuple):
    """One rollout's inputs (scalars; batched by the runner).

    Attributes:
        index: global rollout index; the rollout's PRNG stream is ``fold_in(PRNGKey(seed), index)``.
        phase: push start as a fraction of the step.
        impulse_ns: push impulse, N s.
        direction_rad: push heading, rad (0 forward, pi/2 left).
    """

    index: jax.Array
    phase: jax.Array
    impulse_ns: jax.Array
    direction_rad: jax.Array


class RolloutOutputs(NamedTuple):
    """One rollout's outcome.

    Attributes:
        fell: left the model's valid range (or went non-finite).
        steps_to_recover: steps after the push until the error stays small (-1: never or fell).
        max_abs_footstep_adjustment_m: largest |sagittal footstep adjustment|, m.
        fall_time_s: when it fell (``inf``: never).
        nan: the rollout went numerically bad.
    """

    fell: jax.Array
    steps_to_recover: jax.Array
    max_abs_footstep_adjustment_m: jax.Array
    fall_time_s: jax.Array
    nan: jax.Array


class Model(NamedTuple):
    """A registered model.

    Attributes:
        rollout: ``rollout(config, inputs) -> RolloutOutputs`` (pure, jittable), or ``None``.
        ticks_per_rollout: ``ticks_per_rollout(config) -> int`` environment steps per rollout.
        unavailable: why the model cannot run yet ("" when it can).
    """

    rollout: Callable[[SweepConfig, RolloutInputs], RolloutOutputs] | None
    ticks_per_rollout: Callable[[SweepConfig], int]
    unavailable: str = ""


def _randomized_params(params, key, mass_pct: float, leg_pct: float):
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


def threelp_ticks_per_rollout(config: SweepConfig) -> int:
    """Control ticks (2 ms) of one 3LP rollout."""
    from jaxlp.simulate import SimSpec

    return SimSpec(step_time_s=config.step_time_s, n_steps=config.n_steps).ticks_per_step * config.n_steps


def threelp_rollout(config: SweepConfig, inputs: RolloutInputs) -> RolloutOutputs:
    """One push on the 3LP model of ``config.robot`` under ``config.controller``.

    The push starts at ``(push_step + phase) * step_time_s`` and lasts
    ``push_duration_s`` with force ``impulse_ns / push_duration_s``. With
    randomisation the robot (and the controller designed for it) change per
    rollout; with noise or bias the measurements pass through jaxlp's filters.
    """
    from jaxlp.presets import get_params
    from jaxlp.simulate import Push, SimSpec, make_sensing, simulate

    params = get_params(config.robot)
    key = jax.random.fold_in(jax.random.PRNGKey(config.seed), inputs.index)
    noise_key, robot_key = jax.random.split(key)
    if config.randomize_mass_pct > 0 or config.randomize_leg_pct > 0:
        params = _randomized_params(params, robot_key, config.randomize_mass_pct, config.randomize_leg_pct)
    T = config.step_time_s
    dtype = params.m1.dtype
    push = Push(
        start_s=jnp.asarray((config.push_step + inputs.phase) * T, dtype),
        duration_s=jnp.asarray(config.push_duration_s, dtype),
        force_n=jnp.asarray(inputs.impulse_ns / config.push_duration_s, dtype),
        direction_rad=jnp.asarray(inputs.direction_rad, dtype),
    )
    spec = SimSpec(step_time_s=T, n_steps=config.n_steps, controller=config.controller, sensing=config.sensing)
    sensing = None
    if config.sensing:
        sensing = make_sensing(noise_std_m=config.noise_std_m, bias_m=[[0.0, config.bias_m], [0.0, 0.0]])
    r = simulate(params, push, spec, speed_mps=config.speed_mps, sensing=sensing, key=noise_key)
    finite = (jnp.all(jnp.isfinite(r.pelvis_m)) & jnp.all(jnp.isfinite(r.footstep_adjustment_m))
              & jnp.all(jnp.isfinite(r.step_error)))
    return RolloutOutputs(
        fell=r.fell,
        steps_to_recover=r.steps_to_recover.astype(jnp.int32),
        max_abs_footstep_adjustment_m=jnp.max(jnp.abs(r.footstep_adjustment_m)),
        fall_time_s=r.fall_time_s,
        nan=~finite,
    )


_MJX_UNAVAILABLE = "model 'mjx': the MJX walking controller is not available yet; use --model 3lp"

MODELS: dict[str, Model] = {
    "3lp": Model(threelp_rollout, threelp_ticks_per_rollout),
    "mjx": Model(None, lambda config: 0, _MJX_UNAVAILABLE),
}


def register_model(name: str, model: Model) -> None:
    """Add or replace a model in the registry."""
    MODELS[name] = model


def get_model(name: str) -> Model:
    """A runnable model.

    Raises:
        ValueError: an unknown name.
        ModelUnavailable: a registered model that cannot run yet.
    """
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; choose one of {', '.join(MODELS)}")
    model = MODELS[name]
    if model.rollout is None:
        raise ModelUnavailable(model.unavailable or f"model {name!r} is not available")
    return model
