"""Controllable regions on MJX: per push phase and direction, the largest recoverable impulse of any walking
controller by safeguarded Newton on a smooth margin of the walk, against bisection on the impulse grid.

The margin of a walk pushed with impulse ``J`` is the soft minimum over its records (every 10 ms) of the
ground-truth fall slack (:mod:`mjx_coman.ground_truth`: the pelvis height above the fall height and the
tilt below the fall tilt, each in units of its threshold)::

    m(J) = -tau log mean_t exp(-s_t / tau),   s_t = min((h_t - h_fall) / h_fall, (tilt_fall - tilt_t) / tilt_fall)

A walk freezes at its last good state when it falls, so ``m`` is continuous in ``J`` and negative past the
fall boundary; ``dm/dJ`` comes by forward mode (``jax.jvp``) through the contact-rich walk.
:func:`newton_search` finds its root per lane (phase x direction) with Newton steps ``J - m / m_J`` inside a
bracket kept from the ground-truth verdicts (recovered below, fell above), bisecting whenever a step leaves
it; :func:`grid_bisection` bisects the impulse grid on the verdicts alone. Both treat the grid's ends as the
bracket without evaluating them; each counts the rollouts it ran.
"""

from __future__ import annotations

import functools
import time
from typing import Callable, NamedTuple

import numpy as np


class Search(NamedTuple):
    """A boundary search's result per lane.

    Attributes:
        impulse_ns: (lanes,) the boundary: Newton's last recovered iterate within ``tol_ns`` of a fall, or the
            last recovered grid impulse.
        rollouts: rollouts evaluated (active lanes only).
        iterations: batched evaluations.
        wall_s: seconds.
    """

    impulse_ns: np.ndarray
    rollouts: int
    iterations: int
    wall_s: float


def newton_search(evaluate: Callable, lo_ns, hi_ns, tol_ns: float, start_ns=None, max_iter: int = 30) -> Search:
    """Safeguarded Newton on ``evaluate(J) -> (fell, margin, dmargin_dJ)`` (arrays over lanes).

    Each lane keeps a bracket ``[lo, hi]`` (recovered at ``lo``, fell at ``hi``, ``lo`` updated only by
    recovered evaluations); a Newton step outside the bracket, or with a non-negative slope, is replaced by
    its midpoint. A lane stops when its bracket is narrower than ``tol_ns`` or a recovered iterate's Newton
    correction is below ``tol_ns / 2``; the boundary reported is its ``lo``.
    """
    t0 = time.perf_counter()
    lo, hi = np.array(lo_ns, float), np.array(hi_ns, float)
    j = 0.5 * (lo + hi) if start_ns is None else np.clip(np.asarray(start_ns, float), lo, hi)
    active = hi - lo > tol_ns
    rollouts = iterations = 0
    while active.any() and iterations < max_iter:
        fell, m, dm = (np.asarray(v) for v in evaluate(j))
        rollouts += int(active.sum())
        iterations += 1
        fell = fell.astype(bool)
        lo = np.where(active & ~fell, np.maximum(lo, j), lo)
        hi = np.where(active & fell, np.minimum(hi, j), hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = j - m / dm
        ok = np.isfinite(step) & (dm < 0) & (step > lo) & (step < hi)
        nxt = np.where(ok, step, 0.5 * (lo + hi))
        converged = ~fell & np.isfinite(step) & (dm < 0) & (np.abs(step - j) < 0.5 * tol_ns)
        active = active & ~converged & (hi - lo > tol_ns)
        j = np.where(active, nxt, j)
    return Search(lo, rollouts, iterations, time.perf_counter() - t0)


def grid_bisection(verdict: Callable, impulses_ns, lanes: int) -> Search:
    """The last recovered impulse of the grid per lane, by bisection on ``verdict(J) -> fell`` (grid ends assumed:
    the first recovers, the last falls)."""
    t0 = time.perf_counter()
    imp = np.asarray(impulses_ns, float)
    lo, hi = np.zeros(lanes, int), np.full(lanes, imp.size - 1)
    rollouts = iterations = 0
    while (hi - lo > 1).any():
        active = hi - lo > 1
        mid = (lo + hi) // 2
        fell = np.asarray(verdict(imp[mid])).astype(bool)
        rollouts += int(active.sum())
        iterations += 1
        lo = np.where(active & ~fell, mid, lo)
        hi = np.where(active & fell, mid, hi)
    return Search(imp[lo], rollouts, iterations, time.perf_counter() - t0)


class Spec(NamedTuple):
    """Static choices of the region walks (plain values): a sweep's controller, walk and sensors."""

    controller: str = "time-projection"
    n_steps: int = 6
    push_step: int = 1
    push_duration_s: float = 0.1
    speed_mps: float = 0.0
    sensor_noise_scale: float = 0.0
    temperature: float = 0.02  # of the soft minimum, in units of the thresholds
    record_every: int = 5

    def sweep_config(self, directions=("forward",)):
        """The equivalent sweep configuration (its controller, walk, plant and judge)."""
        from sweeps.grid import SweepConfig
        from sweeps.models import check, get_model

        get_model("mjx")
        return check(SweepConfig(model="mjx", controller=self.controller, n_steps=self.n_steps,
                                 push_step=self.push_step, push_duration_s=self.push_duration_s,
                                 speed_mps=self.speed_mps, sensor_noise_scale=self.sensor_noise_scale,
                                 directions=tuple(directions)))


def slack_record(state, judge):
    """Per record: the ground-truth fall slack ``s_t`` (module docstring)."""
    import jax.numpy as jnp

    from mjx_coman import ground_truth as gt

    d = state.env.data
    h = (gt.pelvis_height_m(d, judge) - judge.fall_height_m) / judge.fall_height_m
    tilt = (judge.max_tilt_rad - gt.tilt_rad(d)) / judge.max_tilt_rad
    return jnp.minimum(h, tilt)


@functools.lru_cache(maxsize=4)
def margin_fn(spec: Spec):
    """``f(phase, impulse_ns, heading_rad, key_data) -> (fell, margin, dmargin/dJ)``, jitted and vmapped over
    lanes (host-built once per spec)."""
    import jax
    import jax.numpy as jnp

    from mjx_coman import controllers
    from mjx_coman import rollout as ro
    from sweeps.models import mjx as M

    cfg = spec.sweep_config()
    ctrl, ccfg = M.controller(cfg)
    g = ctrl.gait(ccfg)
    env = M.nominal_env(cfg.sensor_noise_scale, g.plant)
    wspec = M.walk_spec(cfg)
    save = ro.SaveAt(functools.partial(slack_record, judge=wspec.judge), spec.record_every)
    joy = controllers.joystick(cfg.speed_mps)
    tau = spec.temperature

    def one(phase, impulse, heading, key_data):
        key = jax.random.wrap_key_data(key_data, impl="threefry2x32")
        f = jnp.result_type(float)
        start = jnp.asarray(g.first_step_s + (cfg.push_step + phase) * g.step_time_s, f)

        def margin(j):
            mag = j / cfg.push_duration_s
            force = jnp.stack([mag * jnp.cos(heading), mag * jnp.sin(heading), 0.0 * mag]).astype(f)
            r = ro.walk(ctrl.core(), ccfg, env, ro.Push(start, jnp.asarray(cfg.push_duration_s, f), force), key,
                        wspec, joy, save=save)
            s = r.saved
            m = -tau * (jax.scipy.special.logsumexp(-s / tau) - jnp.log(s.shape[0]))
            return m, r.fell | r.nan

        m, dm, fell = jax.jvp(margin, (impulse,), (jnp.ones_like(impulse),), has_aux=True)
        return fell, m, dm

    return jax.jit(jax.vmap(one))


def run(spec: Spec, phases, impulses_ns, directions, tol_ns: float, seed: int = 0) -> dict:
    """Newton and bisection boundaries of every (direction, phase) lane, direction-major; and their agreement."""
    import jax

    from sweeps.axes import direction_rad

    ph = np.tile(np.asarray(phases, float), len(directions))
    head = np.repeat([direction_rad(d) for d in directions], len(phases))
    keys = np.asarray(jax.vmap(lambda i: jax.random.key_data(jax.random.fold_in(jax.random.key(seed), i)))(
        np.arange(ph.size)))
    f = margin_fn(spec)
    imp = np.asarray(impulses_ns, float)

    def evaluate(j):
        return f(ph, np.asarray(j, ph.dtype).astype(np.float32), head, keys)

    t0 = time.perf_counter()
    evaluate(np.full(ph.size, imp[0]))  # compile
    compile_s = time.perf_counter() - t0
    newton = newton_search(evaluate, np.full(ph.size, imp[0]), np.full(ph.size, imp[-1]), tol_ns)
    bisect = grid_bisection(lambda j: evaluate(j)[0], imp, ph.size)
    step = float(np.min(np.diff(imp))) if imp.size > 1 else 0.0
    agree = np.abs(newton.impulse_ns - bisect.impulse_ns) <= step + 1e-9
    return dict(
        controller=spec.controller, directions=list(directions), phases=[float(p) for p in phases],
        impulses_ns=imp.tolist(), tol_ns=tol_ns, grid_step_ns=step, compile_s=compile_s,
        newton_ns=newton.impulse_ns.reshape(len(directions), -1).tolist(),
        bisection_ns=bisect.impulse_ns.reshape(len(directions), -1).tolist(),
        newton_rollouts=newton.rollouts, bisection_rollouts=bisect.rollouts,
        newton_wall_s=newton.wall_s, bisection_wall_s=bisect.wall_s,
        full_map_rollouts=int(ph.size * imp.size), same_within_grid=int(agree.sum()), lanes=int(ph.size),
        spec=spec._asdict(),
    )
