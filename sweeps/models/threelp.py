"""The ``3lp`` model: one push on the closed-loop 3LP model of :mod:`jaxlp.simulate` under jaxlp's controllers.

Controllers: ``time-projection``, ``dlqr``, ``open-loop`` (:mod:`jaxlp.controllers`). Their settings
(:data:`SETTINGS`): the DLQR weight scales behind the gains and, when the
measurements go through the sensor model (``noise_std_m``, ``bias_m`` or
``bias_std_m`` non-zero), the IIR constant, the real-valued velocity window
and the sagittal and lateral dead-zones of the seed's filters (eq. 26-27).

The controller's plan (gait, tick transitions, DLQR gains, time-projection
tables: :func:`jaxlp.simulate.make_plan`) is computed outside the sharded
rollout: once per configuration for the nominal robot, or per rollout in
:func:`prepare` when the robot is randomised (each robot gets the controller
designed for it, as the seed designs the 3LP controller from the robot's
parameters). Steps to recover are the 3LP's own ground truth (the plant's
state is exact): landings until the error stays under ``recover_tol``.

Tuning (:func:`tune_problem`): the differentiable objective of
:mod:`sweeps.objective` (exact gradients through the plant and its sensor
model) of the dead-zones, ``zeta``, the window and optionally the weight scales.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control
from jaxlp.controllers import CONTROLLERS as JAXLP_CONTROLLERS
from jaxlp.host import host_eval
from jaxlp.presets import get_params
from jaxlp.simulate import Push, SimSpec, make_plan, make_sensing, simulate
from mjx_coman.controllers.base import Setting
from sweeps.grid import GridError, SweepConfig
from sweeps.models import Model, RolloutInputs, RolloutOutputs, TuneProblem, check_settings

SETTINGS = (
    Setting("lqr_weight_scale", (1.0, 1.0, 1.0), "multipliers of the DLQR weights [position, velocity, torque]", True),
    Setting("deadzone", (1e-3, 1e-3, 1e-2, 1e-2), "sagittal dead-zones (eq. 27) [e1 m, e2 m, e1_dot m/s, e2_dot m/s]",
            True),
    Setting("lateral_deadzone", (1e-3, 1e-3, 1e-2, 1e-2), "lateral dead-zones (eq. 27)", True),
    Setting("zeta", 0.1, "IIR constant per 2 ms tick (eq. 26)", True),
    Setting("window_samples", 30.0, "velocity moving-average window, samples (real-valued)", True),
)
COMPARE = ("time-projection", "dlqr", "open-loop")
LATE_STEPS = 3  # the residual wobble: mean landing error over the last 3 landings


def _settings(config: SweepConfig) -> dict:
    return {**{s.name: s.default for s in SETTINGS}, **config.overrides()}


def check(config: SweepConfig, build: bool = True) -> None:
    """The controller name and its overrides (``GridError`` naming a bad one); touches no JAX array."""
    if config.controller not in JAXLP_CONTROLLERS:
        raise GridError(f"unknown controller {config.controller!r} for model 3lp; choose one of {', '.join(COMPARE)}")
    check_settings("3lp", config.controller, SETTINGS, config.overrides())
    s = _settings(config)
    for name in ("deadzone", "lateral_deadzone"):
        v = np.asarray(s[name], float)
        if v.shape != (4,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise GridError(f"setting {name}={list(np.atleast_1d(v))} must be 4 positive thresholds")
    ws = np.asarray(s["lqr_weight_scale"], float)
    if ws.shape != (3,) or not np.all(np.isfinite(ws)) or np.any(ws <= 0):
        raise GridError(f"setting lqr_weight_scale={list(np.atleast_1d(ws))} must be 3 positive numbers")
    if not (math.isfinite(float(s["zeta"])) and 0 < float(s["zeta"]) <= 1):
        raise GridError(f"setting zeta={s['zeta']} must lie in (0, 1]")
    if not (math.isfinite(float(s["window_samples"])) and 1 <= float(s["window_samples"]) <= 200):
        raise GridError(f"setting window_samples={s['window_samples']} must lie in [1, 200]")
    from jaxlp.presets import get_params, robot_names

    if config.robot not in robot_names():
        raise GridError(f"unknown robot {config.robot!r}; choose one of {', '.join(robot_names())}")
    if build:
        from jaxlp.gait import check_feasible

        try:
            check_feasible(get_params(config.robot), config.step_time_s, config.speed_mps)
        except ValueError as e:
            raise GridError(str(e)) from None


def _sensing_on(config: SweepConfig) -> bool:
    return config.noise_std_m > 0 or config.bias_m != 0 or config.bias_std_m > 0


def _spec(config: SweepConfig) -> SimSpec:
    window = max(30, int(math.ceil(float(_settings(config)["window_samples"]))))
    return SimSpec(step_time_s=config.step_time_s, n_steps=config.n_steps, controller=config.controller,
                   sensing=_sensing_on(config), window=window)


def _weights(params, config: SweepConfig):
    ws = _settings(config)["lqr_weight_scale"]
    if all(float(w) == 1.0 for w in ws):
        return None
    return control.default_weights(params).scaled(ws)


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
    return host_eval(lambda p: make_plan(p, _spec(config), config.speed_mps, weights=_weights(p, config)),
                     get_params(config.robot))  # host constants, valid on every device


def _robot_and_plan(config: SweepConfig, key_data):
    params = randomized_params(get_params(config.robot), _keys(key_data)[1], config.randomize_mass_pct,
                               config.randomize_leg_pct)
    return params, make_plan(params, _spec(config), config.speed_mps, weights=_weights(params, config))


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


def _landing_norms(params, step_error):
    from sweeps.objective import landing_error_norms

    return landing_error_norms(params, step_error)


def rollout(config: SweepConfig, inputs: RolloutInputs, aux) -> RolloutOutputs:
    """One push on the 3LP model of ``config.robot`` under ``config.controller``.

    The push starts at ``(push_step + phase) * step_time_s`` and lasts
    ``push_duration_s`` with force ``impulse_ns / push_duration_s``. With
    randomisation ``aux`` holds this rollout's robot and plan. With sensing the
    measurements pass through noise (``noise_std_m``), a bias (``bias_m`` on the
    pelvis, plus ``bias_std_m`` drawn per rollout on the swing foot and pelvis)
    and the seed's filters with the controller's constants (noise and bias from
    the rollout's own PRNG stream).
    """
    if aux is None:
        params, plan = get_params(config.robot), jax.tree_util.tree_map(jnp.asarray, nominal_plan(config))
    else:
        params, plan = aux
    noise_key, robot_key = _keys(inputs.key)
    T = config.step_time_s
    dtype = params.m1.dtype
    push = Push(
        start_s=jnp.asarray((config.push_step + inputs.phase) * T, dtype),
        duration_s=jnp.asarray(config.push_duration_s, dtype),
        force_n=jnp.asarray(inputs.impulse_ns / config.push_duration_s, dtype),
        direction_rad=jnp.asarray(inputs.direction_rad, dtype),
    )
    sensing = None
    if _sensing_on(config):
        s = _settings(config)
        drawn = config.bias_std_m * jax.random.normal(jax.random.fold_in(robot_key, 1), (2,), dtype)
        bias = jnp.zeros((2, 2), dtype).at[0].set(drawn).at[0, 1].add(config.bias_m)
        sensing = make_sensing(noise_std_m=config.noise_std_m, bias_m=bias, zeta=float(s["zeta"]),
                               deadzone=np.stack([np.asarray(s["deadzone"]), np.asarray(s["lateral_deadzone"])]),
                               window_samples=float(s["window_samples"]))
    r = simulate(params, push, _spec(config), speed_mps=config.speed_mps, sensing=sensing, key=noise_key, plan=plan,
                 recover_tol=config.recover_tol)
    finite = (jnp.all(jnp.isfinite(r.pelvis_m)) & jnp.all(jnp.isfinite(r.footstep_adjustment_m))
              & jnp.all(jnp.isfinite(r.step_error)))
    return RolloutOutputs(
        fell=r.fell,
        steps_to_recover=r.steps_to_recover.astype(jnp.int32),
        max_abs_footstep_adjustment_m=jnp.max(jnp.abs(r.footstep_adjustment_m)),
        fall_time_s=r.fall_time_s,
        nan=~finite,
        extra=dict(late_error=jnp.mean(_landing_norms(params, r.step_error)[-LATE_STEPS:])),
    )


# --- tuning ----------------------------------------------------------------------------------------

TUNABLE = ("deadzone", "zeta", "window_samples", "lqr_weight_scale")


def tune_problem(tc) -> TuneProblem:
    """The differentiable 3LP objective (:mod:`sweeps.objective`) on ``tc.batch`` fixed scenarios.

    Starts from the seed's constants for the training sensors (zeta 0.1, 30 samples, Figure 9
    thresholds); the lateral thresholds stay fixed; the weight scales move with ``tc.tune_weights``.
    """
    from sweeps import objective as O

    if tc.controller not in ("time-projection", "dlqr"):
        raise ValueError(f"controller {tc.controller!r} has no constants to tune on 3lp; use time-projection or dlqr")
    params = get_params(tc.robot)
    spec = O.ObjectiveSpec(controller=tc.controller, n_steps=tc.n_steps, push_step=2, tune_weights=tc.tune_weights)
    dist = O.ScenarioDistribution(impulse_max_ns=tc.impulse_max_ns, noise_std_m=(tc.noise_min_m, tc.noise_max_m),
                                  bias_std_m=tc.bias_std_m).validate()
    scenarios = {"train": O.sample_scenarios(jax.random.PRNGKey(tc.seed), tc.batch, dist),
                 "held": O.sample_scenarios(jax.random.PRNGKey(tc.seed + 1), tc.batch, dist)}
    seed_c, lateral = jax.jit(lambda s: O.seed_constants(params, spec, s))(scenarios["train"])
    value_grad = jax.jit(jax.value_and_grad(lambda r, s: O.objective(r, params, lateral, s, spec), has_aux=True))

    def vg(raw, split):
        (loss, costs), grad = value_grad(raw, scenarios[split])
        return (loss, dict(fell=costs.fell, fall=costs.fall, error=costs.error)), grad

    def constants(raw):
        return O.from_raw(raw, spec.window_max).as_dict()

    def overrides(raw):
        c = O.from_raw(raw, spec.window_max)
        return dict(deadzone=tuple(float(v) for v in np.asarray(c.deadzone)), zeta=float(c.zeta),
                    window_samples=float(c.window_samples),
                    lqr_weight_scale=tuple(float(v) for v in np.asarray(c.weight_scale)),
                    lateral_deadzone=tuple(float(v) for v in np.asarray(lateral)))

    return TuneProblem(raw0=O.to_raw(seed_c, spec.window_max), value=lambda raw, split: vg(raw, split)[0],
                       value_and_grad=vg, constants=constants,
                       overrides=overrides,
                       info=dict(error_weight=spec.error_weight, lateral_deadzone=np.asarray(lateral).tolist(),
                                 loss_definition="mean over scenarios of a smooth fall indicator plus "
                                                 f"{spec.error_weight:g} x the footstep-error term (sweeps.objective)"))


def holdout_grid(record: dict) -> dict:
    """Held-out 3LP push grids of a tuning record: forward and backward, 16 phases x 0-14 N s, 10 steps,
    the training sensors' mean noise and bias, a fresh seed; a looser recovery tolerance (noisy walks never
    settle to the noise-free 0.02: undisturbed walks show landing errors of 0.1-0.3)."""
    cfg = record["config"]
    return dict(directions=("forward", "backward"), phases=tuple(k / 16 for k in range(16)),
                impulses_ns=tuple(float(v) for v in np.linspace(0.0, 14.0, 29)), n_steps=10, push_step=2,
                noise_std_m=0.5 * (cfg["noise_min_m"] + cfg["noise_max_m"]), bias_std_m=cfg["bias_std_m"],
                recover_tol=0.1, robot=cfg["robot"], chunk=512)


def load() -> Model:
    """The registry entry."""
    return Model(rollout, ticks_per_rollout, controllers=lambda: COMPARE, compare_default=lambda: COMPARE,
                 settings=lambda name: SETTINGS, check=check, prepare=prepare, env_step_s=env_step_s,
                 tune_problem=tune_problem, holdout_grid=holdout_grid)
