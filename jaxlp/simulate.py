"""Closed-loop 3LP walking at fixed control ticks, with pushes, noisy sensing and falls.

The plant is the 3LP model itself (single support, both axes), integrated
exactly over each tick (``lax.scan``) with the closed form of the augmented
system; the hip torque is the nominal gait's plus the controller's correction,
saturated. A push is a horizontal force on the torso. At the end of each
phase the swing foot lands where it is and the feet swap roles.

Falls are results, not errors: the model is valid while the pelvis stays within
``max_lean`` of the stance foot and steps are no longer than ``max_step``; a
rollout that leaves that range (or goes non-finite) is frozen and flagged.

Everything is a pure function of array pytrees, so ``jax.vmap`` runs batches
of pushes or of robots and ``jax.grad`` reaches every parameter.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control, filters, gait as gait_mod, projection
from jaxlp.controllers import ControllerPlan, Measurement, get_controller
from jaxlp.dynamics import N_AUG, N_Q, flow
from jaxlp.params import ThreeLPParams, _check_positive, _is_concrete


class SimSpec(NamedTuple):
    """Static choices of a simulation (plain Python values).

    Attributes:
        step_time_s: phase duration, s.
        n_steps: number of phases simulated.
        dt_s: control tick, s (2 ms as on COMAN).
        controller: ``"open-loop"``, ``"dlqr"`` or ``"time-projection"``.
        sensing: pass measurements through noise, filters and dead-zones.
        window: moving-average window of the velocity estimate, samples (the
            ring buffer's length; a real-valued ``Sensing.filter.window_samples``
            up to this length overrides it).
        freeze_on_fall: freeze a rollout where it left the valid range (the
            default). ``False`` lets the linear model run on past that point
            (``fell`` and ``fall_time_s`` are still those of the first
            violation), so a failure margin measured on the trajectories is a
            continuous function of the push across the recovered/fell boundary.
    """

    step_time_s: float = 0.4
    n_steps: int = 10
    dt_s: float = 0.002
    controller: str = "time-projection"
    sensing: bool = False
    window: int = 30
    freeze_on_fall: bool = True

    @property
    def ticks_per_step(self) -> int:
        return int(round(self.step_time_s / self.dt_s))

    def validate(self) -> "SimSpec":
        get_controller(self.controller)
        _check_positive("step_time_s", self.step_time_s)
        _check_positive("dt_s", self.dt_s)
        if abs(self.ticks_per_step * self.dt_s - self.step_time_s) > 1e-9:
            raise ValueError(f"step_time_s={self.step_time_s} is not a whole number of dt_s={self.dt_s} ticks")
        if self.n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {self.n_steps}")
        if self.window < 1:
            raise ValueError(f"window must be >= 1, got {self.window}")
        return self


class Push(NamedTuple):
    """A push on the torso CoM.

    Attributes:
        start_s: start time since the simulation start, s.
        duration_s: duration, s.
        force_n: force magnitude, N.
        direction_rad: heading, 0 forward (+x), pi/2 to the left (+y).
    """

    start_s: jax.Array
    duration_s: jax.Array
    force_n: jax.Array
    direction_rad: jax.Array


def make_push(start_s=0.0, duration_s=0.1, force_n=0.0, direction_rad=0.0) -> Push:
    """A validated push (negative duration or force raise ``ValueError``)."""
    for name, val in (("duration_s", duration_s), ("force_n", force_n), ("start_s", start_s)):
        if _is_concrete(val) and np.any(np.asarray(val, float) < 0):
            raise ValueError(f"{name} must be non-negative, got {np.asarray(val).tolist()}")
    return Push(*(jnp.asarray(v, float) for v in (start_s, duration_s, force_n, direction_rad)))


NO_PUSH = Push(*(jnp.zeros(()) for _ in range(4)))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Limits:
    """Where the model stops being valid, and actuator limits.

    Attributes:
        max_hip_torque_nm: hip torque saturation, N m.
        max_lean_ratio: largest pelvis-stance distance per axis, in ``h1``.
        max_step_ratio: longest step (swing-stance distance at landing), in ``h1``.
    """

    max_hip_torque_nm: jax.Array
    max_lean_ratio: jax.Array
    max_step_ratio: jax.Array


def make_limits(max_hip_torque_nm=30.0, max_lean_ratio=0.35, max_step_ratio=0.7) -> Limits:
    """Validated limits (defaults sized for COMAN)."""
    for name, val in (("max_hip_torque_nm", max_hip_torque_nm), ("max_lean_ratio", max_lean_ratio),
                      ("max_step_ratio", max_step_ratio)):
        _check_positive(name, val)
    return Limits(*(jnp.asarray(v, float) for v in (max_hip_torque_nm, max_lean_ratio, max_step_ratio)))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Sensing:
    """Measurement imperfections and the filters that clean them.

    Attributes:
        noise_std_m: white noise on each relative position, m.
        bias_m: (2, 2) constant bias of ``[swing, pelvis]`` relative positions per axis, m.
        filter: IIR constant and dead-zone thresholds (:class:`jaxlp.filters.FilterParams`).
    """

    noise_std_m: jax.Array
    bias_m: jax.Array
    filter: filters.FilterParams


def make_sensing(noise_std_m=1e-3, bias_m=np.zeros((2, 2)), zeta=0.1,
                 deadzone=(1e-3, 1e-3, 1e-2, 1e-2), window_samples=None) -> Sensing:
    """Validated sensing constants (see :func:`jaxlp.filters.make_filter_params`)."""
    if _is_concrete(noise_std_m) and float(noise_std_m) < 0:
        raise ValueError(f"noise_std_m must be non-negative, got {float(noise_std_m)}")
    return Sensing(jnp.asarray(noise_std_m, float), jnp.asarray(bias_m, float).reshape(2, 2),
                   filters.make_filter_params(zeta, deadzone, window_samples))


class Plan(NamedTuple):
    """Everything precomputed from the parameters before the tick loop (differentiable)."""

    tick_flow: jax.Array  # (2, 12, 12) per axis, exp(G dt)
    nominal: jax.Array  # (ticks, 2, 6) nominal relative state per tick (d = +1)
    gait: gait_mod.Gait
    ctrl: ControllerPlan


def make_plan(params: ThreeLPParams, spec: SimSpec, speed_mps=0.0, step_width_m=None,
              weights: control.LQRWeights | None = None) -> Plan:
    """Gait, tick transitions, DLQR gains and time-projection tables for a simulation."""
    n = spec.ticks_per_step
    g = gait_mod.periodic_gait(params, spec.step_time_s, speed_mps, step_width_m)
    ts = jnp.arange(n) * spec.dt_s
    nominal = jax.vmap(lambda t: gait_mod.nominal_state(params, g, t))(ts)
    Ks, tables = [], []
    for lateral in (False, True):
        ctrl = control.constrained_dlqr(params, spec.step_time_s, weights, lateral=lateral)
        Ks.append(ctrl.K)
        tables.append(projection.gain_table(params, ctrl, spec.step_time_s, n, lateral).projection)
    tick_flow = jnp.stack([flow(params, spec.dt_s, False), flow(params, spec.dt_s, True)])
    return Plan(tick_flow=tick_flow, nominal=nominal, gait=g,
                ctrl=ControllerPlan(K=jnp.stack(Ks), projection=jnp.stack(tables, axis=1)))


class Result(NamedTuple):
    """Outcome of one rollout.

    Attributes:
        pelvis_m: (n_ticks, 2) pelvis position per tick.
        swing_m, stance_m: (n_ticks, 2) feet positions per tick.
        footsteps_m: (n_steps, 2) where each step landed.
        step_error: (n_steps, 2, 4) error at each landing (after the swap), d = +1 frame.
        hip_torque_nm: (n_ticks, 2) applied hip torque.
        footstep_adjustment_m: (n_steps,) sagittal landing position minus the nominal one, relative to the pelvis.
        fell: whether the rollout left the model's valid range.
        fall_time_s: when it did (``inf`` if never).
        steps_to_recover: steps after the push until the error stays small (-1: never, or fell).
    """

    pelvis_m: jax.Array
    swing_m: jax.Array
    stance_m: jax.Array
    footsteps_m: jax.Array
    step_error: jax.Array
    hip_torque_nm: jax.Array
    footstep_adjustment_m: jax.Array
    fell: jax.Array
    fall_time_s: jax.Array
    steps_to_recover: jax.Array


class _Carry(NamedTuple):
    q: jax.Array  # (2, 6) absolute [s, p, a, sd, pd, ad] per axis
    d: jax.Array
    ctrl: object
    filt: filters.FilterState
    fallen: jax.Array
    fall_time: jax.Array


def _relative(q):
    """(2, 2) positions and velocities of [swing, pelvis] relative to the stance foot."""
    pos = jnp.stack([q[:, 0] - q[:, 2], q[:, 1] - q[:, 2]], axis=-1)
    vel = jnp.stack([q[:, 3] - q[:, 5], q[:, 4] - q[:, 5]], axis=-1)
    return pos, vel


def _push_force(push: Push, t0, dt):
    """Mean push force over the tick [t0, t0 + dt] per axis (exact impulse)."""
    overlap = jnp.clip(jnp.minimum(t0 + dt, push.start_s + push.duration_s) - jnp.maximum(t0, push.start_s), 0.0, dt)
    mag = push.force_n * overlap / dt
    return mag * jnp.stack([jnp.cos(push.direction_rad), jnp.sin(push.direction_rad)])


def _error_norm(params: ThreeLPParams, e):
    """Dimensionless size of a (2, 4) error: positions in h1, velocities in sqrt(g h1)."""
    scale = jnp.array([1.0, 1.0, 0.0, 0.0]) / params.h1 + jnp.array([0.0, 0.0, 1.0, 1.0]) / jnp.sqrt(params.g * params.h1)
    return jnp.sqrt(jnp.sum((e * scale) ** 2))


def simulate(
    params: ThreeLPParams,
    push: Push,
    spec: SimSpec,
    *,
    speed_mps=0.0,
    step_width_m=None,
    weights: control.LQRWeights | None = None,
    sensing: Sensing | None = None,
    limits: Limits | None = None,
    key: jax.Array | None = None,
    recover_tol: float = 0.02,
    plan: Plan | None = None,
) -> Result:
    """Simulate closed-loop 3LP walking for ``spec.n_steps`` phases.

    Args:
        params: 3LP parameters.
        push: the push on the torso (:data:`NO_PUSH` for none).
        spec: static choices (controller, step time, ticks, sensing on/off).
        speed_mps: commanded speed of the periodic gait.
        step_width_m: step width (``None``: minimal lateral hip torque).
        weights: DLQR weights (defaults of the brief).
        sensing: noise, bias and filter constants; used when ``spec.sensing``.
        limits: saturation and validity limits (:func:`make_limits` defaults).
        key: PRNG key for the measurement noise (needed when sensing).
        recover_tol: dimensionless error size under which a step counts as recovered.
        plan: ``make_plan(params, spec, speed_mps, step_width_m, weights)`` computed beforehand
            (``None``: computed here). Sweeps pass it so that the batched linear algebra of the
            plan stays out of their sharded rollouts.

    Returns:
        A :class:`Result`.
    """
    spec.validate()
    limits = make_limits() if limits is None else limits
    if spec.sensing:
        sensing = make_sensing() if sensing is None else sensing
        key = jax.random.PRNGKey(0) if key is None else key
    if plan is None:
        plan = make_plan(params, spec, speed_mps, step_width_m, weights)
    controller = get_controller(spec.controller)
    n_ticks, dt = spec.ticks_per_step, spec.dt_s
    T = spec.step_time_s
    u_nom = plan.gait.u  # (2, 2)

    q0 = plan.gait.q0  # stance foot at origin, d = +1
    carry0 = _Carry(
        q=q0, d=jnp.ones(()), ctrl=controller.init(plan.ctrl),
        filt=filters.filter_init((2, 2), spec.window, q0.dtype),
        fallen=jnp.zeros((), bool), fall_time=jnp.full((), jnp.inf),
    )
    axis_sign = lambda d: jnp.stack([jnp.ones_like(d), d])  # mirror of the lateral axis  # noqa: E731

    def tick(carry: _Carry, inputs):
        step_idx, k = inputs
        t = k * dt
        time = step_idx * T + t
        sign = axis_sign(carry.d)
        nom = plan.nominal[k] * sign[:, None]
        nom_pos, nom_vel = _relative(nom)
        pos, vel = _relative(carry.q)
        filt = carry.filt
        if spec.sensing:
            tick_key = jax.random.fold_in(key, step_idx * n_ticks + k)
            obs = pos + sensing.noise_std_m * jax.random.normal(tick_key, pos.shape, pos.dtype) + sensing.bias_m
            filt, pos, vel = filters.filter_step(filt, obs, sensing.filter.zeta, dt, sensing.filter.window_samples)
        err = jnp.concatenate([pos - nom_pos, vel - nom_vel], axis=-1) * sign[:, None]
        if spec.sensing:
            err = filters.smooth_deadzone(err, sensing.filter.deadzone)
        ctrl_state, dU = controller.step(plan.ctrl, carry.ctrl, Measurement(tick=k, error=err))
        dU = dU * sign[:, None]
        tau = sign * (u_nom[:, 0] + t * u_nom[:, 1]) + dU[:, 0] + t * dU[:, 1]
        rate = sign * u_nom[:, 1] + dU[:, 1]
        saturated = jnp.abs(tau) > limits.max_hip_torque_nm
        tau = jnp.clip(tau, -limits.max_hip_torque_nm, limits.max_hip_torque_nm)
        rate = jnp.where(saturated, 0.0, rate)
        force = _push_force(push, time, dt)
        z = jnp.zeros((2, N_AUG), carry.q.dtype)
        z = z.at[:, :N_Q].set(carry.q).at[:, 6].set(tau).at[:, 7].set(rate)
        z = z.at[:, 10].set(force).at[:, 11].set(carry.d)
        q_new = jnp.einsum("aij,aj->ai", plan.tick_flow, z)[:, :N_Q]
        lean = jnp.abs(q_new[:, 1] - q_new[:, 2])
        bad = jnp.any(lean > limits.max_lean_ratio * params.h1) | ~jnp.all(jnp.isfinite(q_new))
        fallen = carry.fallen | bad
        q_out = jnp.where(fallen, carry.q, q_new) if spec.freeze_on_fall else q_new
        fall_time = jnp.where(bad & ~carry.fallen, time + dt, carry.fall_time)
        new = carry._replace(q=q_out, ctrl=ctrl_state, filt=filt, fallen=fallen, fall_time=fall_time)
        return new, (q_out[:, 1], q_out[:, 0], q_out[:, 2], tau)

    def phase(carry: _Carry, step_idx):
        carry, (pel, sw, st, tau) = jax.lax.scan(tick, carry, (jnp.full(n_ticks, step_idx), jnp.arange(n_ticks)))
        q = carry.q
        landing = q[:, 0]
        step_len = jnp.abs(landing[0] - q[0, 2])
        too_long = step_len > limits.max_step_ratio * params.h1
        fall_time = jnp.where(too_long & ~carry.fallen, (step_idx + 1) * T, carry.fall_time)
        fallen = carry.fallen | too_long
        # nominal landing of the swing foot relative to the pelvis, sagittal
        nom_end = gait_mod.nominal_state(params, plan.gait, T)[0]
        adjust = (q[0, 0] - q[0, 1]) - (nom_end[0] - nom_end[1])
        swapped = jnp.stack([q[:, 2], q[:, 1], q[:, 0], jnp.zeros(2), q[:, 4], jnp.zeros(2)], axis=1)
        q_next = jnp.where(carry.fallen, q, swapped) if spec.freeze_on_fall else swapped
        d_next = -carry.d
        pos, vel = _relative(q_next)
        nom_pos, nom_vel = _relative(plan.gait.q0 * axis_sign(d_next)[:, None])
        step_err = jnp.concatenate([pos - nom_pos, vel - nom_vel], axis=-1) * axis_sign(d_next)[:, None]
        filt = filters.filter_swap(carry.filt) if spec.sensing else carry.filt
        carry = carry._replace(q=q_next, d=d_next, filt=filt, fallen=fallen, fall_time=fall_time)
        return carry, (pel, sw, st, tau, landing, step_err, adjust)

    carry, (pel, sw, st, tau, landings, step_err, adjust) = jax.lax.scan(phase, carry0, jnp.arange(spec.n_steps))
    flat = lambda x: x.reshape(-1, *x.shape[2:])  # noqa: E731

    norms = jax.vmap(lambda e: _error_norm(params, e))(step_err)
    push_end_step = jnp.floor((push.start_s + push.duration_s) / T).astype(jnp.int32)
    steps = jnp.arange(spec.n_steps)
    ok_after = jnp.flip(jnp.cumprod(jnp.flip(norms < recover_tol))).astype(bool)  # small from here on
    candidates = jnp.where(ok_after & (steps >= push_end_step), steps, spec.n_steps)
    first = jnp.min(candidates)
    steps_to_recover = jnp.where((first < spec.n_steps) & ~carry.fallen, first - push_end_step + 1, -1)
    steps_to_recover = jnp.where(push.force_n > 0, steps_to_recover, jnp.where(carry.fallen, -1, 0))
    return Result(
        pelvis_m=flat(pel), swing_m=flat(sw), stance_m=flat(st), footsteps_m=landings,
        step_error=step_err, hip_torque_nm=flat(tau), footstep_adjustment_m=adjust,
        fell=carry.fallen, fall_time_s=carry.fall_time, steps_to_recover=steps_to_recover,
    )
