"""A differentiable push-recovery objective of the estimation constants (3LP plant with the sensor model).

The constants tuned are those the seed chose by hand or by fitting (seed 000,
"State Estimation"): the four sagittal dead-zone thresholds (eq. 27, set to the
standard deviations of Figure 9), the IIR constant ``zeta`` (eq. 26, 0.1), the
velocity moving-average window (30 samples; here a real number, see
:func:`jaxlp.filters.window_weights`) and, optionally, scales of the DLQR
weights behind the time-projection tables (eq. 11-18).

The objective averages, over a fixed sample of scenarios (push timing,
magnitude and direction; sensor noise, quantisation and systematic bias as in
Figure 9), a smooth fall indicator ``sigmoid(-margin / fall_scale)`` and the
footstep error at the landings from the pushed step on. The failure margin is
the soft minimum over the rollout of the model's validity slack (pelvis lean
within ``0.35 h1`` of the stance foot, steps shorter than ``0.7 h1``), in
units of ``h1``, measured on rollouts that run on past a fall
(``SimSpec.freeze_on_fall=False``) so it is continuous across the
recovered/fell boundary. Everything is a pure function of array pytrees:
``jax.grad`` of :func:`objective` gives exact gradients of all constants.

Optimiser steps act on :class:`RawConstants` (unconstrained): thresholds and
weight scales through ``exp``, ``zeta`` through a sigmoid into (0, 1), the
window through a scaled sigmoid into (1, ``window_max``), so any step keeps
the constants valid.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control, filters, gait
from jaxlp.params import ThreeLPParams
from jaxlp.simulate import Limits, Push, Result, Sensing, SimSpec, make_limits, simulate

SEED_ZETA = 0.1  # seed 000, eq. 26
SEED_WINDOW_SAMPLES = 30.0  # seed 000, "State Estimation"
CONSTANT_NAMES = ("deadzone_swing_position_m", "deadzone_pelvis_position_m", "deadzone_swing_velocity_mps",
                  "deadzone_pelvis_velocity_mps", "zeta", "window_samples",
                  "weight_scale_position", "weight_scale_velocity", "weight_scale_torque")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Constants:
    """The tuned estimation constants, in physical units.

    Attributes:
        deadzone: (4,) sagittal dead-zone thresholds ``[swing position (m),
            pelvis position (m), swing velocity (m/s), pelvis velocity (m/s)]`` (eq. 27).
        zeta: IIR constant per 2 ms tick (eq. 26).
        window_samples: velocity moving-average window, samples (real-valued).
        weight_scale: (3,) multipliers of the default DLQR weights
            ``[position, velocity, torque]`` (1: the defaults).
    """

    deadzone: jax.Array
    zeta: jax.Array
    window_samples: jax.Array
    weight_scale: jax.Array

    def as_dict(self) -> dict[str, float]:
        vals = np.concatenate([np.asarray(self.deadzone, float), [float(self.zeta), float(self.window_samples)],
                               np.asarray(self.weight_scale, float)])
        return dict(zip(CONSTANT_NAMES, (float(v) for v in vals)))


def make_constants(deadzone, zeta=SEED_ZETA, window_samples=SEED_WINDOW_SAMPLES, weight_scale=(1.0, 1.0, 1.0),
                   window_max: float = 60.0) -> Constants:
    """Validated constants. Raises ``ValueError`` naming a bad value."""
    dz = np.asarray(deadzone, float)
    if dz.shape != (4,) or not np.all(np.isfinite(dz)) or np.any(dz <= 0):
        raise ValueError(f"deadzone must be 4 positive thresholds, got {dz.tolist()}")
    if not 0.0 < float(zeta) < 1.0:
        raise ValueError(f"zeta must lie in (0, 1), got {float(zeta)}")
    if not 1.0 < float(window_samples) < window_max:
        raise ValueError(f"window_samples must lie in (1, {window_max:g}), got {float(window_samples)}")
    ws = np.asarray(weight_scale, float)
    if ws.shape != (3,) or np.any(ws <= 0):
        raise ValueError(f"weight_scale must be 3 positive numbers, got {ws.tolist()}")
    return Constants(jnp.asarray(dz), jnp.asarray(float(zeta)), jnp.asarray(float(window_samples)), jnp.asarray(ws))


def constants_from_dict(d: dict, window_max: float = 60.0) -> Constants:
    """The inverse of :meth:`Constants.as_dict` (validated)."""
    try:
        return make_constants([d[n] for n in CONSTANT_NAMES[:4]], d["zeta"], d["window_samples"],
                              [d[n] for n in CONSTANT_NAMES[6:]], window_max)
    except KeyError as e:
        raise ValueError(f"constants lack {e.args[0]!r}") from None


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RawConstants:
    """Unconstrained coordinates of :class:`Constants` (what the optimiser moves)."""

    log_deadzone: jax.Array
    logit_zeta: jax.Array
    logit_window: jax.Array
    log_weight_scale: jax.Array


def to_raw(c: Constants, window_max: float) -> RawConstants:
    """Physical to unconstrained coordinates."""
    u = (c.window_samples - 1.0) / (window_max - 1.0)
    return RawConstants(jnp.log(c.deadzone), jnp.log(c.zeta) - jnp.log1p(-c.zeta),
                        jnp.log(u) - jnp.log1p(-u), jnp.log(c.weight_scale))


def from_raw(raw: RawConstants, window_max: float) -> Constants:
    """Unconstrained to physical coordinates (always valid constants)."""
    return Constants(jnp.exp(raw.log_deadzone), jax.nn.sigmoid(raw.logit_zeta),
                     1.0 + (window_max - 1.0) * jax.nn.sigmoid(raw.logit_window), jnp.exp(raw.log_weight_scale))


class ObjectiveSpec(NamedTuple):
    """Static choices of the objective (plain Python values).

    Attributes:
        controller: the walking controller (time projection in the seed).
        step_time_s, n_steps: phase duration and phases per rollout.
        push_step: index of the step during which pushes start.
        push_duration_s: push duration, s.
        window_max: ring-buffer length of the velocity average, samples (upper bound of the window).
        margin_temperature: soft-minimum temperature of the margin, in ``h1``.
        fall_scale: width of the smooth fall indicator, in ``h1`` of margin.
        error_scale: dimensionless footstep-error size where its cost turns logarithmic.
        error_weight: weight of the footstep-error term against the fall term.
        tune_weights: let the DLQR weights move (otherwise their scales stay 1).
    """

    controller: str = "time-projection"
    step_time_s: float = 0.4
    n_steps: int = 7
    push_step: int = 2
    push_duration_s: float = 0.1
    window_max: int = 60
    margin_temperature: float = 0.005
    fall_scale: float = 0.02
    error_scale: float = 0.02
    error_weight: float = 0.1
    tune_weights: bool = False

    def sim_spec(self) -> SimSpec:
        return SimSpec(step_time_s=self.step_time_s, n_steps=self.n_steps, controller=self.controller,
                       sensing=True, window=self.window_max, freeze_on_fall=False).validate()


@dataclasses.dataclass(frozen=True)
class ScenarioDistribution:
    """Where pushes and sensor imperfections are drawn from (plain values).

    Attributes:
        impulse_max_ns: impulses uniform in ``[0, impulse_max_ns]`` N s.
        zero_push_fraction: share of undisturbed walks.
        directions_rad: headings drawn with equal odds (forward and backward).
        direction_spread_rad: uniform jitter of the heading.
        noise_std_m: (low, high) of the white noise on relative positions, m.
        quantisation_m: encoder quantisation step seen in the relative positions, m
            (added as its uniform-noise equivalent, ``q / sqrt(12)``).
        bias_std_m: std of the per-rollout systematic bias of the sagittal swing and pelvis positions, m.
    """

    impulse_max_ns: float = 12.0
    zero_push_fraction: float = 0.2
    directions_rad: tuple[float, ...] = (0.0, float(np.pi))
    direction_spread_rad: float = 0.2
    noise_std_m: tuple[float, float] = (0.5e-3, 1.5e-3)
    quantisation_m: float = 0.5e-3
    bias_std_m: float = 2e-3

    def validate(self) -> "ScenarioDistribution":
        if not self.impulse_max_ns >= 0:
            raise ValueError(f"impulse_max_ns must be non-negative, got {self.impulse_max_ns}")
        if not 0.0 <= self.zero_push_fraction <= 1.0:
            raise ValueError(f"zero_push_fraction must lie in [0, 1], got {self.zero_push_fraction}")
        lo, hi = self.noise_std_m
        if not 0.0 <= lo <= hi:
            raise ValueError(f"noise_std_m must be 0 <= low <= high, got {self.noise_std_m}")
        for name in ("quantisation_m", "bias_std_m", "direction_spread_rad"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not self.directions_rad:
            raise ValueError("directions_rad is empty")
        return self


class Scenarios(NamedTuple):
    """A batch of scenarios (leading axis: rollouts).

    Attributes:
        phase: push start as a fraction of step ``push_step``.
        impulse_ns: push impulse, N s.
        direction_rad: push heading.
        noise_std_m: white noise std on the relative positions, m.
        bias_m: (n, 2, 2) bias of ``[swing, pelvis]`` positions per axis, m.
        key: (n, 2) PRNG keys of the measurement noise.
    """

    phase: jax.Array
    impulse_ns: jax.Array
    direction_rad: jax.Array
    noise_std_m: jax.Array
    bias_m: jax.Array
    key: jax.Array


def sample_scenarios(key, n: int, dist: ScenarioDistribution = ScenarioDistribution()) -> Scenarios:
    """``n`` scenarios drawn from ``dist`` (same key, same scenarios)."""
    dist.validate()
    if n < 1:
        raise ValueError(f"the number of scenarios must be >= 1, got {n}")
    k = jax.random.split(key, 8)
    impulse = jax.random.uniform(k[0], (n,), maxval=dist.impulse_max_ns)
    impulse = jnp.where(jax.random.uniform(k[1], (n,)) < dist.zero_push_fraction, 0.0, impulse)
    heading = jnp.asarray(dist.directions_rad)[jax.random.randint(k[2], (n,), 0, len(dist.directions_rad))]
    heading = heading + dist.direction_spread_rad * jax.random.uniform(k[3], (n,), minval=-1.0, maxval=1.0)
    white = jax.random.uniform(k[4], (n,), minval=dist.noise_std_m[0], maxval=dist.noise_std_m[1])
    noise = jnp.sqrt(white**2 + dist.quantisation_m**2 / 12.0)
    bias = jnp.zeros((n, 2, 2)).at[:, 0, :].set(dist.bias_std_m * jax.random.normal(k[5], (n, 2)))
    return Scenarios(phase=jax.random.uniform(k[6], (n,)), impulse_ns=impulse, direction_rad=heading,
                     noise_std_m=noise, bias_m=bias, key=jax.random.split(k[7], n))


def sensing_of(c: Constants, lateral_deadzone, noise_std_m, bias_m) -> Sensing:
    """The simulator's :class:`~jaxlp.simulate.Sensing` of constants, fixed lateral thresholds and a sensor draw."""
    deadzone = jnp.stack([c.deadzone, jnp.broadcast_to(lateral_deadzone, (4,))])
    return Sensing(noise_std_m, bias_m, filters.FilterParams(c.zeta, deadzone, c.window_samples))


def rollout(params: ThreeLPParams, c: Constants, lateral_deadzone, scenario: Scenarios, spec: ObjectiveSpec,
            limits: Limits | None = None) -> Result:
    """One rollout of a scenario (unbatched fields) under the constants ``c``; runs on past a fall."""
    dtype = params.m1.dtype
    push = Push(start_s=((spec.push_step + scenario.phase) * spec.step_time_s).astype(dtype),
                duration_s=jnp.asarray(spec.push_duration_s, dtype),
                force_n=(scenario.impulse_ns / spec.push_duration_s).astype(dtype),
                direction_rad=scenario.direction_rad.astype(dtype))
    weights = control.default_weights(params).scaled(c.weight_scale)
    return simulate(params, push, spec.sim_spec(), weights=weights,
                    sensing=sensing_of(c, lateral_deadzone, scenario.noise_std_m, scenario.bias_m),
                    limits=limits, key=scenario.key)


def validity_slack(params: ThreeLPParams, result: Result, spec: SimSpec | ObjectiveSpec,
                   limits: Limits | None = None) -> tuple[jax.Array, jax.Array]:
    """Distance to the model's validity limits, in ``h1``.

    Returns:
        ``(lean, step)``: per tick and axis ``max_lean_ratio - |pelvis - stance| / h1``
        (n_ticks, 2), and per landing ``max_step_ratio - |sagittal step| / h1`` (n_steps,).
    """
    limits = make_limits() if limits is None else limits
    lean = limits.max_lean_ratio - jnp.abs(result.pelvis_m - result.stance_m) / params.h1
    stance_at_landing = result.stance_m.reshape(spec.n_steps, -1, 2)[:, -1, 0]
    step = limits.max_step_ratio - jnp.abs(result.footsteps_m[:, 0] - stance_at_landing) / params.h1
    return lean, step


def failure_margin(params: ThreeLPParams, result: Result, spec: SimSpec | ObjectiveSpec,
                   limits: Limits | None = None, temperature: float | None = None) -> jax.Array:
    """The failure margin of a rollout, in ``h1``: negative exactly when it fell.

    The minimum over the rollout of :func:`validity_slack`, or with a
    ``temperature`` its soft minimum ``-t logsumexp(-slack / t)``, smooth and
    at most ``t log(n_ticks)`` below the minimum. Meaningful on rollouts run
    with ``freeze_on_fall=False``: then it is continuous in the push and the
    constants across the boundary (a frozen rollout stops just before the
    violation).
    """
    lean, step = validity_slack(params, result, spec, limits)
    slack = jnp.concatenate([lean.ravel(), step])
    if temperature is None:
        return jnp.min(slack)
    return -temperature * jax.nn.logsumexp(-slack / temperature)


def landing_error_norms(params: ThreeLPParams, step_error):
    """(n_steps,) dimensionless error size at each landing (positions in h1, velocities in sqrt(g h1))."""
    scale = jnp.concatenate([jnp.full(2, 1.0 / params.h1), jnp.full(2, 1.0 / jnp.sqrt(params.g * params.h1))])
    return jnp.sqrt(jnp.sum((step_error * scale) ** 2, axis=(-2, -1)))


class RolloutCost(NamedTuple):
    """Per-rollout pieces of the objective.

    Attributes:
        loss: ``fall + error_weight * error``.
        fall: smooth fall indicator ``sigmoid(-margin / fall_scale)`` in (0, 1).
        error: mean ``log1p((|E_k| / error_scale)^2)`` over the landings from the push step on.
        margin: the soft failure margin, ``h1``.
        hard_margin: the failure margin without smoothing (negative exactly when it fell), ``h1``.
        fell: the rollout left the valid range (hard outcome).
    """

    loss: jax.Array
    fall: jax.Array
    error: jax.Array
    margin: jax.Array
    hard_margin: jax.Array
    fell: jax.Array


def rollout_cost(params: ThreeLPParams, c: Constants, lateral_deadzone, scenario: Scenarios,
                 spec: ObjectiveSpec) -> RolloutCost:
    """The objective's terms for one scenario."""
    r = rollout(params, c, lateral_deadzone, scenario, spec)
    margin = failure_margin(params, r, spec, temperature=spec.margin_temperature)
    fall = jax.nn.sigmoid(-margin / spec.fall_scale)
    norms = landing_error_norms(params, r.step_error)[spec.push_step:]
    error = jnp.mean(jnp.log1p((norms / spec.error_scale) ** 2))
    hard = failure_margin(params, r, spec)
    return RolloutCost(fall + spec.error_weight * error, fall, error, margin, hard, r.fell)


def objective(raw: RawConstants, params: ThreeLPParams, lateral_deadzone, scenarios: Scenarios,
              spec: ObjectiveSpec) -> tuple[jax.Array, RolloutCost]:
    """Mean cost over ``scenarios`` of the constants ``from_raw(raw)``; returns ``(loss, per-rollout costs)``.

    With ``spec.tune_weights`` off the DLQR weight scales are held at their
    current values (no gradient reaches them).
    """
    c = from_raw(raw, spec.window_max)
    if not spec.tune_weights:
        c = dataclasses.replace(c, weight_scale=jax.lax.stop_gradient(c.weight_scale))
    costs = jax.vmap(lambda s: rollout_cost(params, c, lateral_deadzone, s, spec))(scenarios)
    return jnp.mean(costs.loss), costs


def open_loop_filtered_errors(params: ThreeLPParams, spec: ObjectiveSpec, zeta, window_samples, noise_std_m,
                              bias_m, key) -> jax.Array:
    """Filtered errors (before the dead-zones) of open-loop in-place walking under sensor noise and bias.

    The seed's Figure 9 experiment on the model: open loop, the true state is
    the nominal gait, so the errors are what the filters make of the
    measurement noise, the bias and the filter lag. Same measurement pipeline
    as :func:`jaxlp.simulate.simulate`.

    Returns:
        (n_steps, ticks, 2, 4) errors per tick, axis and component.
    """
    sim = spec.sim_spec()
    n, dt = sim.ticks_per_step, sim.dt_s
    g = gait.periodic_gait(params, sim.step_time_s, 0.0)
    nominal = jax.vmap(lambda t: gait.nominal_state(params, g, t))(jnp.arange(n) * dt)  # as in make_plan

    def rel(q):
        pos = jnp.stack([q[:, 0] - q[:, 2], q[:, 1] - q[:, 2]], axis=-1)
        vel = jnp.stack([q[:, 3] - q[:, 5], q[:, 4] - q[:, 5]], axis=-1)
        return pos, vel

    def tick(filt, inp):
        step_idx, k = inp
        sign = jnp.stack([1.0, jnp.where(step_idx % 2 == 0, 1.0, -1.0)])
        nom_pos, nom_vel = rel(nominal[k] * sign[:, None])
        noise = noise_std_m * jax.random.normal(jax.random.fold_in(key, step_idx * n + k), nom_pos.shape)
        filt, pos, vel = filters.filter_step(filt, nom_pos + noise + bias_m, zeta, dt, window_samples)
        return filt, jnp.concatenate([pos - nom_pos, vel - nom_vel], axis=-1) * sign[:, None]

    def phase(filt, step_idx):
        filt, errs = jax.lax.scan(tick, filt, (jnp.full(n, step_idx), jnp.arange(n)))
        return filters.filter_swap(filt), errs

    filt0 = filters.filter_init((2, 2), sim.window, nominal.dtype)
    return jax.lax.scan(phase, filt0, jnp.arange(sim.n_steps))[1]


def figure9_thresholds(params: ThreeLPParams, spec: ObjectiveSpec, scenarios: Scenarios,
                       zeta=SEED_ZETA, window_samples=SEED_WINDOW_SAMPLES) -> jax.Array:
    """Dead-zone thresholds by the seed's recipe (Figure 9): the spread of filtered errors in open-loop walking.

    Runs :func:`open_loop_filtered_errors` for each scenario's sensor draw
    (noise, bias, key; its push is ignored), drops the first step (the
    filters settling) and fits a zero-mean Gaussian to the pooled errors of
    each axis and component ("these values should be zero in ideal
    conditions"): its standard deviation, the root mean square about zero.

    Returns:
        (2, 4) thresholds, rows sagittal and lateral.
    """
    errs = jax.vmap(lambda s: open_loop_filtered_errors(params, spec, zeta, window_samples, s.noise_std_m,
                                                        s.bias_m, s.key))(scenarios)
    errs = errs[:, 1:]
    return jnp.sqrt(jnp.mean(errs**2, axis=(0, 1, 2)))


def seed_constants(params: ThreeLPParams, spec: ObjectiveSpec, scenarios: Scenarios) -> tuple[Constants, jax.Array]:
    """The seed's constants for a sensor distribution: zeta 0.1, 30 samples, Figure 9 thresholds.

    Returns:
        The constants (sagittal thresholds) and the lateral thresholds (4,),
        which stay fixed while tuning.
    """
    th = figure9_thresholds(params, spec, scenarios)
    return (Constants(th[0], jnp.asarray(SEED_ZETA), jnp.asarray(SEED_WINDOW_SAMPLES), jnp.ones(3)), th[1])
