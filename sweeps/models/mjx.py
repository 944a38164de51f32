"""The ``mjx`` model: one pushed walk of COMAN in MuJoCo MJX under any registered controller, judged on ground truth.

The controller is a name of :mod:`mjx_coman.controllers` with its settings
overridden by ``controller_overrides`` (``--set``); its config is built once
on the host per configuration. The walk (:func:`mjx_coman.rollout.walk`)
starts from the controller's crouched stance; walking step ``k`` starts at
the controller's ``first_step_s + k step_time_s`` (one start-up phase for
the time-projection family), so the push, on the upper torso, starts at
``first_step_s + (push_step + phase) step_time_s`` as in ``python -m
mjx_coman.walk`` and lasts ``push_duration_s``; the walk lasts
``first_step_s + n_steps step_time_s``. Effort (:func:`effort`, from
records every 10 ms): mean absolute knee torque and cost of transport while
walking before the push, peak knee torque over the walk. The environment is the controller's
plant, :func:`mjx_coman.rollout.plant_env_params` (position control: the
seed's gains with a stiffer ankle roll loop; or a torque plant). Falls and
steps to recover are the simulator's
(:mod:`mjx_coman.ground_truth`); each rollout also records its touchdowns,
mean speed and the limit cycle it ends in.

Per rollout, from the rollout's own PRNG key (so results do not depend on
chunking or devices), the simulated robot may differ from the nominal one the
controller was designed for:

* ``randomize_mass_pct``: every body's mass and inertia scaled by its own ``1 + U(-1, 1) pct / 100``;
* ``randomize_spring_pct``: each SEA spring stiffness scaled by its own ``1 + U(-1, 1) pct / 100``;
* ``randomize_delay_ticks``: the transport delay shifted by a uniform integer in ``[-k, k]`` ticks;
* ``sensor_noise_scale``: IMU, gyro and F/T noise at that multiple of COMAN's nominal levels
  (0: noise-free; the 12-bit encoders always quantise);
* ``encoder_offset_std_rad``: constant link encoder offsets ``N(0, std)`` per joint.

Everything randomised is an array leaf of the environment parameters, built
inside the vmapped rollout, which is the same as vmapping ``walk`` with the
axes of :func:`mjx_coman.env.batch_axes` (``model_fields=("body_mass", "body_inertia")``).

A sweep's scenario axes (``SweepConfig.scenario``: payload, slope, sensor
noise, delay of :mod:`mjx_coman.scenarios`) are applied to the nominal
robot first (the randomisation above then scales its payload too): every
combination's parameters are built once on the host
(:func:`mjx_coman.scenarios.batched_env_params`) and a rollout takes row
``index % n_scenarios`` of them, so one compilation runs them all. The
terrain is the scene (a model of its own, and a compilation); the fall judge
measures heights above it.

The physics engine is ``config.engine`` (:mod:`mjx_coman.engines`: MJX, or MuJoCo C on the CPU's threads).
Tuning lives in :mod:`sweeps.models.mjx_tune`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from sweeps.grid import GridError, SweepConfig
from sweeps.models import Model, RolloutInputs, RolloutOutputs, check_settings
from sweeps.models.mjx_env import _controllers, _rollout_module, nominal_env  # noqa: F401 (nominal_env: the model's API)
from sweeps.models.mjx_tune import holdout_grid, tune_problem


def check(config: SweepConfig, build: bool = True) -> None:
    """The controller name, its overrides and, with ``build``, their values (by building the controller's
    config, which starts JAX) and the walk's timing."""
    ctrls = _controllers()
    try:
        ctrl = ctrls.get(config.controller)
    except ValueError as e:
        raise GridError(str(e)) from None
    if ctrl.privileged:
        raise GridError(f"controller {config.controller} reads the simulator's ground truth; sweeps judge "
                        "controllers on what they measure")
    check_settings("mjx", config.controller, ctrl.settings, config.overrides())
    if not build:
        return
    gait = _gait(config)
    try:
        gait.check_joystick(config.speed_mps)
    except ValueError as e:
        raise GridError(f"controller {config.controller}: {e}") from None
    if abs(gait.step_time_s - config.step_time_s) > 1e-9:
        raise GridError(f"step_time_s={config.step_time_s} differs from controller {config.controller}'s "
                        f"{gait.step_time_s:g} s (set its step time with --set, if it has one)")
    if config.scenario:
        try:
            scenario_env(config)
        except ValueError as e:
            raise GridError(f"scenario: {e}") from None


def _gait(config: SweepConfig):
    """The controller's :class:`~mjx_coman.controllers.base.Gait` with the config's overrides (GridError naming a
    bad value)."""
    ctrls = _controllers()
    try:
        _, cfg = ctrls.load(config.controller, config.overrides())
        return ctrls.get(config.controller).gait(cfg)
    except ValueError as e:
        raise GridError(f"controller {config.controller}: {e}") from None


def own_fields(config: SweepConfig) -> dict:
    """The controller's own step time (its gait's, with the config's overrides): a walk of ``n_steps`` of it."""
    return {"step_time_s": float(_gait(config).step_time_s)}


def scenario_list(config: SweepConfig) -> list:
    """The :class:`mjx_coman.scenarios.Scenario` of each scenario index of a sweep."""
    from mjx_coman.scenarios import Scenario

    return [Scenario(**row) for row in config.scenarios()]


def scenario_env(config: SweepConfig):
    """``(params, in_axes)`` of the sweep's scenarios on its nominal robot (host-built, cached per float width)."""
    return _scenario_env(config.compiled_part(), bool(jax.config.jax_enable_x64))


@functools.lru_cache(maxsize=8)
def _scenario_env(config: SweepConfig, x64: bool):
    from mjx_coman.scenarios import batched_env_params

    with jax.ensure_compile_time_eval():
        return batched_env_params(nominal_env(config.sensor_noise_scale, gait(config).plant, config.engine),
                                  scenario_list(config))


def controller(config: SweepConfig):
    """``(controller, its config)`` of a sweep (host-built, cached by the registry)."""
    return _controllers().load(config.controller, config.overrides())


def gait(config: SweepConfig):
    ctrl, cfg = controller(config)
    return ctrl.gait(cfg)


EFFORT_EVERY = 5  # ticks between effort records (10 ms)


def effort_record(state):
    """A save function: both knees' link torques (N m), the joints' absolute mechanical power
    ``sum |tau_j qdot_j|`` (W) and the CoM's horizontal position (m), of the tick's last physics step."""
    from mjx_coman import ground_truth as gt
    from mjx_coman.actuators import JOINT_INDEX

    d = state.env.data
    knees = jnp.asarray([JOINT_INDEX["RKneeSag"], JOINT_INDEX["LKneeSag"]])
    return dict(knee_nm=d.ctrl[knees], power_w=jnp.sum(jnp.abs(d.ctrl * d.qvel[6:])), com_xy_m=gt.com_m(d)[:2])


def effort(time_s, saved, walk_from_s, walk_to_s, fall_time_s, mass_kg):
    """Effort statistics of a walk from its :func:`effort_record` records.

    While walking, over the records in ``[walk_from_s, walk_to_s)`` before any fall: the mean absolute knee
    torque (both knees) and the cost of transport ``E / (m g d)`` (``E`` the absolute mechanical work of
    the joints, ``d`` the CoM's horizontal travel; NaN below 1 cm of travel). Over the whole walk before
    any fall: the peak absolute knee torque.
    """
    up = time_s < fall_time_s
    w = up & (time_s >= walk_from_s) & (time_s < walk_to_s)
    knee = jnp.abs(saved["knee_nm"])
    n = jnp.maximum(jnp.sum(w), 1)
    mean_knee = jnp.sum(jnp.where(w[:, None], knee, 0.0)) / (2 * n)
    dt = time_s[1] - time_s[0]
    work = jnp.sum(jnp.where(w, saved["power_w"], 0.0)) * dt
    idx = jnp.arange(time_s.shape[0])
    first = jnp.min(jnp.where(w, idx, idx.shape[0] - 1))
    last = jnp.max(jnp.where(w, idx, 0))
    travel = jnp.linalg.norm(saved["com_xy_m"][last] - saved["com_xy_m"][first])
    cot = jnp.where(travel > 0.01, work / (mass_kg * 9.81 * jnp.maximum(travel, 0.01)), jnp.nan)
    return dict(mean_abs_knee_torque_nm=jnp.where(jnp.any(w), mean_knee, jnp.nan),
                cost_of_transport=jnp.where(jnp.any(w), cot, jnp.nan),
                peak_abs_knee_torque_nm=jnp.max(jnp.where(up[:, None], knee, 0.0)))


def walk_spec(config: SweepConfig):
    """The static :class:`mjx_coman.rollout.WalkSpec` of a sweep."""
    from mjx_coman.ground_truth import judge_on

    g = gait(config)
    return _rollout_module().WalkSpec(seconds=g.first_step_s + config.n_steps * g.step_time_s,
                                      judge=judge_on(config.terrain))


def ticks_per_rollout(config: SweepConfig) -> int:
    """Control ticks of one walk (2 ms, each 2 physics steps of 1 ms)."""
    ro = _rollout_module()
    return ro.n_ticks(walk_spec(config), gait(config).control_period_s, ro.SaveAt(effort_record, EFFORT_EVERY))


def env_step_s(config: SweepConfig) -> float:
    """One environment step (control tick), s."""
    return gait(config).control_period_s


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
    ro = _rollout_module()
    ctrl, cfg = controller(config)
    g = ctrl.gait(cfg)
    env = nominal_env(config.sensor_noise_scale, g.plant, config.engine)
    key = jax.random.wrap_key_data(inputs.key, impl="threefry2x32")
    walk_key, robot_key = jax.random.split(key)
    if config.scenario:
        from mjx_coman.scenarios import select

        params, axes = scenario_env(config)
        env = select(params, axes, inputs.index % config.n_scenarios)
    env = randomized_env(env, config, robot_key)
    f = jnp.result_type(float)
    mag = inputs.impulse_ns / config.push_duration_s
    force = jnp.stack([mag * jnp.cos(inputs.direction_rad), mag * jnp.sin(inputs.direction_rad), 0.0 * mag])
    start_s = g.first_step_s + (config.push_step + inputs.phase) * g.step_time_s
    push = ro.Push(start_s=jnp.asarray(start_s, f), duration_s=jnp.asarray(config.push_duration_s, f),
                   force_n=force.astype(f))
    joy = _controllers().joystick(config.speed_mps)
    r = ro.walk(ctrl.core(), cfg, env, push, walk_key, walk_spec(config), joy,
                save=ro.SaveAt(effort_record, EFFORT_EVERY))
    # walking: from the first step to the push
    eff = effort(r.time_s, r.saved, g.first_step_s, start_s, r.fall_time_s, jnp.sum(env.model.body_mass))
    return RolloutOutputs(
        fell=r.fell, steps_to_recover=r.steps_to_recover.astype(jnp.int32),
        max_abs_footstep_adjustment_m=r.max_abs_footstep_adjustment_m, fall_time_s=r.fall_time_s, nan=r.nan,
        extra=dict(solve_failed=r.solve_failed & ~r.nan, touchdowns=r.touchdowns, mean_speed_mps=r.mean_speed_mps,
                   cycle_forward_mps=r.cycle_velocity_mps[0], cycle_lateral_mps=r.cycle_velocity_mps[1], **eff),
    )


def prepare(config: SweepConfig, inputs: RolloutInputs):
    """Build (and cache) the nominal robot and the controller's config outside the sharded call's trace."""
    nominal_env(config.sensor_noise_scale, gait(config).plant, config.engine)
    if config.scenario:
        scenario_env(config)
    controller(config)
    return None


def settings(name: str) -> tuple:
    """The settings of a registered controller (``GridError`` naming an unknown one)."""
    try:
        return _controllers().get(name).settings
    except ValueError as e:
        raise GridError(str(e)) from None


def controller_names() -> tuple[str, ...]:
    return _controllers().names()


def compare_default() -> tuple[str, ...]:
    """Every registered walking controller."""
    return _controllers().names(walking=True)


def load() -> Model:
    """The registry entry."""
    return Model(rollout, ticks_per_rollout, controllers=controller_names, compare_default=compare_default,
                 settings=settings, check=check, prepare=prepare,
                 env_step_s=env_step_s, tune_problem=tune_problem, holdout_grid=holdout_grid,
                 own_fields=own_fields)
