"""Controllable regions: the largest recoverable impulse per push timing, by safeguarded Newton vs plain bisection.

For a push of impulse ``J`` (N s) starting at ``phase`` of step ``push_step``,
the failure margin ``m(phase, J)`` of :func:`sweeps.objective.failure_margin`
(soft minimum of the validity slack, in ``h1``; rollouts run on past a fall so
``m`` is continuous) is negative when the walk falls. The boundary of the
region at a timing is the root ``J*(phase)`` of ``m``.

* :func:`newton_boundary` walks along the push timings: at each timing it
  starts from the previous root moved along the boundary's tangent
  (``dJ*/dphase = -m_phase / m_J``, both from ``jax.value_and_grad``), takes
  Newton steps ``J - m / m_J`` and falls back to bisection of the bracket it
  keeps (recovered below, fell above) whenever a step leaves it. It stops
  when the Newton correction is below ``tol_ns``; one rollout (with its
  gradient) per evaluation.
* :func:`bisection_boundary` bisects the impulse grid for the last recovered
  grid impulse (``fell`` only, no gradient), all timings at once.

Both treat ``[impulses[0], impulses[-1]]`` as the bracket without evaluating
its ends (the first recovers, the last falls); the count of rollouts is what
each evaluated. Lanes (push directions, sensor draws) run side by side in one
batch; finished lanes ride along as padding, not counted.
"""

from __future__ import annotations

import functools
import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control
from jaxlp.params import ThreeLPParams
from jaxlp.simulate import Push, SimSpec, simulate
from sweeps.objective import Constants, failure_margin, sensing_of


class RegionSpec(NamedTuple):
    """Static choices of the region rollouts (plain values).

    Attributes:
        controller: walking controller.
        step_time_s, n_steps: phase duration and phases per rollout.
        push_step: step during which the push starts.
        push_duration_s: push duration, s.
        temperature: soft-minimum temperature of the margin, in ``h1`` (its
            root lies at most ``temperature log(n_ticks) / |dm/dJ|`` below the fall boundary).
        sensing: measurements through noise, bias and the filters (needs constants).
        weight_scale: multipliers of the DLQR weights ``(position, velocity, torque)`` of exact sensing
            (with sensing, the constants' own scales).
    """

    controller: str = "time-projection"
    step_time_s: float = 0.4
    n_steps: int = 10
    push_step: int = 2
    push_duration_s: float = 0.1
    temperature: float = 1e-4
    sensing: bool = False
    weight_scale: tuple = (1.0, 1.0, 1.0)

    def sim_spec(self) -> SimSpec:
        return SimSpec(step_time_s=self.step_time_s, n_steps=self.n_steps, controller=self.controller,
                       sensing=self.sensing, window=60, freeze_on_fall=False).validate()


class Lanes(NamedTuple):
    """Independent boundary searches run side by side (leading axis: lanes).

    Attributes:
        direction_rad: push heading.
        noise_std_m: sensor white noise std, m (used with sensing).
        bias_m: (lanes, 2, 2) sensor bias, m.
        key: (lanes, 2) noise keys; the same for every timing and impulse of a lane.
    """

    direction_rad: jax.Array
    noise_std_m: jax.Array
    bias_m: jax.Array
    key: jax.Array


def make_lanes(directions_rad, noise_std_m=0.0, bias_std_m=0.0, draws: int = 1, seed: int = 0) -> Lanes:
    """``len(directions) x draws`` lanes, direction-major; sensor biases drawn on the sagittal positions."""
    dirs = np.repeat(np.asarray(directions_rad, float), draws)
    n = dirs.size
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    bias = jnp.zeros((n, 2, 2)).at[:, 0, :].set(bias_std_m * jax.random.normal(k1, (n, 2)))
    return Lanes(jnp.asarray(dirs), jnp.full(n, noise_std_m), bias, jax.random.split(k2, n))


def _rollout(params: ThreeLPParams, spec: RegionSpec, constants, lateral, lane: Lanes, phase, impulse_ns):
    dtype = params.m1.dtype
    push = Push(start_s=(spec.push_step + phase) * spec.step_time_s, duration_s=jnp.asarray(spec.push_duration_s, dtype),
                force_n=impulse_ns / spec.push_duration_s, direction_rad=lane.direction_rad.astype(dtype))
    sensing = sensing_of(constants, lateral, lane.noise_std_m, lane.bias_m) if spec.sensing else None
    scale = constants.weight_scale if spec.sensing else jnp.asarray(spec.weight_scale, dtype)
    weights = control.default_weights(params).scaled(scale)
    r = simulate(params, push, spec.sim_spec(), weights=weights, sensing=sensing, key=lane.key)
    return failure_margin(params, r, spec, temperature=spec.temperature), r.fell


class Evaluators(NamedTuple):
    """Batched, jitted evaluations over lanes.

    Attributes:
        margin_grad: ``(lanes, phase, J) -> (m, dm/dJ, dm/dphase)``, each (lanes,).
        fell: ``(lanes, phase, J) -> fell`` (lanes,), a plain rollout.
    """

    margin_grad: object
    fell: object


@functools.lru_cache(maxsize=8)
def preset_evaluators(robot: str, spec: RegionSpec) -> Evaluators:
    """:func:`make_evaluators` of a parameter preset without sensing, cached (compiled once per process)."""
    from jaxlp.presets import get_params

    if spec.sensing:
        raise ValueError("cached evaluators are for exact sensing; use make_evaluators with constants")
    return make_evaluators(get_params(robot), spec)


def make_evaluators(params: ThreeLPParams, spec: RegionSpec, constants: Constants | None = None,
                    lateral_deadzone=None) -> Evaluators:
    """The jitted evaluators of ``spec`` (constants and lateral thresholds needed with sensing)."""
    if spec.sensing and constants is None:
        raise ValueError("sensing needs the filter constants")

    def margin(lane, phase, j):
        return _rollout(params, spec, constants, lateral_deadzone, lane, phase, j)[0]

    def value_grad(lane, phase, j):
        m, (g_phase, g_j) = jax.value_and_grad(margin, argnums=(1, 2))(lane, phase, j)
        return m, g_j, g_phase

    fell = jax.jit(jax.vmap(lambda lane, p, j: _rollout(params, spec, constants, lateral_deadzone, lane, p, j)[1]))
    return Evaluators(jax.jit(jax.vmap(value_grad)), fell)


class Boundary(NamedTuple):
    """A region boundary per lane and timing.

    Attributes:
        phases: (P,) push timings.
        impulse_ns: (lanes, P) largest recoverable impulse.
        evaluations: (lanes, P) rollouts evaluated per search.
        rollouts: total rollouts evaluated.
        calls: batched calls made.
        wall_s: wall time, s (compilation included on a first call).
        bracket_ns: (lanes, P, 2) Newton: last bracket; bisection: the grid cell around the boundary.
    """

    phases: np.ndarray
    impulse_ns: np.ndarray
    evaluations: np.ndarray
    rollouts: int
    calls: int
    wall_s: float
    bracket_ns: np.ndarray


def _lane_rows(lanes: Lanes, rows: np.ndarray) -> Lanes:
    return jax.tree_util.tree_map(lambda x: x[rows], lanes)


def bisection_boundary(ev: Evaluators, lanes: Lanes, phases, impulses_ns) -> Boundary:
    """Plain bisection on the impulse grid: the last recovered grid impulse per lane and timing."""
    t0 = time.perf_counter()
    grid = np.asarray(impulses_ns, float)
    phases = np.asarray(phases, float)
    n_lanes, P = len(lanes.direction_rad), phases.size
    rows = np.repeat(np.arange(n_lanes), P)
    batch = _lane_rows(lanes, rows)
    ph = np.tile(phases, n_lanes)
    lo, hi = np.zeros(rows.size, int), np.full(rows.size, grid.size - 1)
    evals = np.zeros(rows.size, int)
    calls = 0
    dtype = lanes.direction_rad.dtype
    while np.any(hi - lo > 1):
        active = hi - lo > 1
        mid = (lo + hi) // 2
        fell = np.asarray(ev.fell(batch, jnp.asarray(ph, dtype), jnp.asarray(grid[mid], dtype)))
        calls += 1
        evals += active
        hi = np.where(active & fell, mid, hi)
        lo = np.where(active & ~fell, mid, lo)
    shape = (n_lanes, P)
    return Boundary(phases, grid[lo].reshape(shape), evals.reshape(shape), int(evals.sum()), calls,
                    time.perf_counter() - t0, np.stack([grid[lo], grid[hi]], -1).reshape(*shape, 2))


def newton_boundary(ev: Evaluators, lanes: Lanes, phases, impulse_range_ns, tol_ns: float = 0.1,
                    margin_tol: float = 0.05, max_evaluations: int = 12, continuation: bool = True,
                    curvature: bool = False) -> Boundary:
    """Safeguarded Newton on the margin along the push timings (see the module docstring).

    Args:
        ev: evaluators (:func:`make_evaluators`).
        lanes: independent searches side by side.
        phases: (P,) push timings, searched in this order.
        impulse_range_ns: ``(low, high)`` bracket: ``low`` recovers, ``high`` falls (not evaluated).
        tol_ns: stop when a Newton correction is smaller than this (N s) ...
        margin_tol: ... and the margin is within this of zero (``h1``): far past a fall the
            linear model diverges and the margin's slope grows steep, so a small step
            there is no sign of a root.
        max_evaluations: per timing and lane.
        continuation: start from the previous timing's root along the boundary's tangent
            (``False``: from the middle of the bracket at every timing).
        curvature: bend that start by the curvature the two previous roots and the slope imply.
    """
    t0 = time.perf_counter()
    phases = np.asarray(phases, float)
    j_lo, j_hi = map(float, impulse_range_ns)
    n_lanes, P = len(lanes.direction_rad), phases.size
    dtype = lanes.direction_rad.dtype
    out = np.zeros((n_lanes, P))
    brackets = np.zeros((n_lanes, P, 2))
    evals = np.zeros((n_lanes, P), int)
    calls = 0
    prev_root = prev_slope = None
    for i, phase in enumerate(phases):
        lo, hi = np.full(n_lanes, j_lo), np.full(n_lanes, j_hi)
        x = np.full(n_lanes, 0.5 * (j_lo + j_hi))
        if continuation and prev_root is not None:
            d = phase - phases[i - 1]
            x = prev_root + prev_slope * d
            if curvature and i >= 2:
                d2 = phases[i - 2] - phases[i - 1]
                c = (out[:, i - 2] - prev_root - prev_slope * d2) / d2**2
                x = x + c * d**2
            x = np.where(np.isfinite(x) & (x > lo) & (x < hi), x, 0.5 * (lo + hi))
        root = np.full(n_lanes, np.nan)
        slope = np.zeros(n_lanes)
        active = np.ones(n_lanes, bool)
        for _ in range(max_evaluations):
            m, m_j, m_p = (np.asarray(v, float) for v in
                           ev.margin_grad(lanes, jnp.full(n_lanes, phase, dtype), jnp.asarray(x, dtype)))
            calls += 1
            evals[:, i] += active
            ok = np.isfinite(m) & (m >= 0)
            lo = np.where(active & ok, x, lo)
            hi = np.where(active & ~ok, x, hi)
            good = np.isfinite(m) & np.isfinite(m_j) & (m_j < 0)
            step = np.where(good, -m / np.where(good, m_j, -1.0), np.nan)
            cand = x + step
            inside = good & (cand >= lo) & (cand < hi)
            nxt = np.where(inside, cand, 0.5 * (lo + hi))  # the safeguard: bisect the bracket
            done = active & ((inside & (np.abs(step) < tol_ns) & (np.abs(m) < margin_tol)) | (hi - lo < tol_ns))
            root = np.where(done, np.where(inside, cand, 0.5 * (lo + hi)), root)
            slope = np.where(done & good, -m_p / np.where(good, m_j, -1.0), slope)
            active &= ~done
            x = np.where(active, nxt, x)
            if not active.any():
                break
        root = np.where(np.isnan(root), 0.5 * (lo + hi), root)
        out[:, i], brackets[:, i, 0], brackets[:, i, 1] = root, lo, hi
        prev_root, prev_slope = root, slope
    return Boundary(phases, out, evals, int(evals.sum()), calls, time.perf_counter() - t0, brackets)


def same_within_grid(newton: Boundary, bisection: Boundary, slack_ns: float = 0.05) -> np.ndarray:
    """Per lane and timing: Newton's root lies in bisection's grid cell (with ``slack_ns`` for the soft margin)."""
    lo, hi = bisection.bracket_ns[..., 0], bisection.bracket_ns[..., 1]
    return (newton.impulse_ns >= lo - slack_ns) & (newton.impulse_ns <= hi + slack_ns)


def grid_rollouts(n_lanes: int, phases, impulses_ns) -> int:
    """Rollouts of the full basin map of the same grid (what ``coman-sweep map`` runs)."""
    return n_lanes * len(phases) * len(impulses_ns)


def bisection_evaluations_per_search(n_impulses: int) -> int:
    """Evaluations plain bisection needs on a grid of ``n_impulses`` (bracket ends given): ceil(log2(n - 1))."""
    return math.ceil(math.log2(max(n_impulses - 1, 1)))
