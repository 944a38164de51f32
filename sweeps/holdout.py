"""Held-out validation of estimation constants on push grids (the sweep's grid, outcomes and basin maps).

A held-out sweep is a :class:`sweeps.grid.SweepConfig` grid (push phase x
impulse, one direction, fresh noise seed) run on the 3LP plant with given
filter constants (:class:`sweeps.objective.Constants`): per rollout the same
outcomes as the sweep's ``3lp`` model (fell, steps to recover, footstep
adjustment), summarised and drawn by :mod:`sweeps.report`. Each rollout draws
its measurement noise and a systematic sagittal bias (swing and pelvis
positions, std ``bias_std_m``) from ``fold_in(PRNGKey(seed), index)``, so the
seed and the tuned constants meet the same pushes and the same sensors.

The registry's ``3lp`` model cannot carry other filter constants (its sensing
is fixed by the configuration), so the rollouts here are jitted and vmapped in
chunks directly rather than through :func:`sweeps.runner.run_sweep`.
"""

from __future__ import annotations

import jaxlp  # noqa: F401  (XLA CPU flags before JAX starts)

import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import control
from jaxlp.presets import get_params
from jaxlp.simulate import Push, SimSpec, simulate
from sweeps import report
from sweeps.grid import SweepConfig, grid_inputs
from sweeps.objective import Constants, landing_error_norms, sensing_of


# Noisy walks never settle to the noise-free 0.02 of jaxlp.simulate: undisturbed walks with the seed's
# constants and 1 mm noise show landing errors of 0.1-0.3 (mostly velocities), so "recovered" is looser here.
RECOVER_TOL = 0.1
LATE_STEPS = 3  # the residual wobble: mean landing error over the last 3 landings


class HoldoutRun(NamedTuple):
    """A finished held-out sweep: the grid, per-rollout results (as the sweep's) and timing."""

    config: SweepConfig
    results: dict
    timing: dict


def _rollout(config: SweepConfig, c: Constants, lateral_deadzone, bias_std_m: float, recover_tol: float, index,
             phase, impulse_ns, direction_rad):
    params = get_params(config.robot)
    dtype = params.m1.dtype
    key = jax.random.fold_in(jax.random.PRNGKey(config.seed), index)
    noise_key, bias_key = jax.random.split(key)
    bias = jnp.zeros((2, 2), dtype).at[0].set(bias_std_m * jax.random.normal(bias_key, (2,), dtype))
    T = config.step_time_s
    push = Push(start_s=jnp.asarray((config.push_step + phase) * T, dtype),
                duration_s=jnp.asarray(config.push_duration_s, dtype),
                force_n=jnp.asarray(impulse_ns / config.push_duration_s, dtype),
                direction_rad=jnp.asarray(direction_rad, dtype))
    spec = SimSpec(step_time_s=T, n_steps=config.n_steps, controller=config.controller, sensing=True, window=60)
    w = control.default_weights(params)
    weights = control.LQRWeights(w.position * c.weight_scale[0], w.velocity * c.weight_scale[1],
                                 w.torque * c.weight_scale[2])
    sensing = sensing_of(c, lateral_deadzone, jnp.asarray(config.noise_std_m, dtype), bias)
    r = simulate(params, push, spec, speed_mps=config.speed_mps, weights=weights, sensing=sensing, key=noise_key,
                 recover_tol=recover_tol)
    finite = jnp.all(jnp.isfinite(r.pelvis_m)) & jnp.all(jnp.isfinite(r.step_error))
    return dict(fell=r.fell | ~finite, steps_to_recover=r.steps_to_recover.astype(jnp.int32),
                max_abs_footstep_adjustment_m=jnp.max(jnp.abs(r.footstep_adjustment_m)),
                fall_time_s=r.fall_time_s, nan=~finite,
                late_error=jnp.mean(landing_error_norms(params, r.step_error)[-LATE_STEPS:]))


def run_holdout(config: SweepConfig, constants: Constants, lateral_deadzone, bias_std_m: float = 2e-3,
                recover_tol: float = RECOVER_TOL, chunk: int = 256) -> HoldoutRun:
    """Run the grid of ``config`` with ``constants``; results as :func:`sweeps.runner.run_sweep`'s.

    ``config.noise_std_m`` is the white noise on the relative positions;
    ``config.bias_m`` must be 0 (the bias is drawn per rollout, std ``bias_std_m``).
    A pushed walk has recovered after ``steps_to_recover`` steps when the
    error at every later landing stays under ``recover_tol`` (dimensionless:
    positions in ``h1``, velocities in ``sqrt(g h1)``, both axes).
    """
    config.validate()
    if config.model != "3lp" or config.bias_m != 0 or config.randomize_mass_pct or config.randomize_leg_pct:
        raise ValueError("held-out sweeps run --model 3lp without a fixed bias or robot randomisation")
    if not bias_std_m >= 0:
        raise ValueError(f"bias_std_m must be non-negative, got {bias_std_m}")
    t0 = time.perf_counter()
    inputs = grid_inputs(config)
    n = config.n_rollouts
    chunk = min(chunk, n)
    fn = jax.jit(jax.vmap(lambda i, p, j, d: _rollout(config, constants, lateral_deadzone, bias_std_m, recover_tol,
                                                      i, p, j, d)))
    parts = []
    for lo in range(0, n, chunk):
        idx = np.arange(lo, lo + chunk) % n  # the last chunk wraps around: same shapes, one compile
        out = fn(inputs.index[idx], inputs.phase[idx], inputs.impulse_ns[idx], inputs.direction_rad[idx])
        parts.append({k: np.asarray(v)[: min(chunk, n - lo)] for k, v in out.items()})
    res = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    res.update(index=inputs.index, phase=inputs.phase, impulse_ns=inputs.impulse_ns,
               direction_rad=inputs.direction_rad)
    res["reason"] = np.where(res["nan"], "nan", np.where(res["fell"], "fell", ""))
    ticks = SimSpec(step_time_s=config.step_time_s, n_steps=config.n_steps).ticks_per_step * config.n_steps
    wall = time.perf_counter() - t0
    return HoldoutRun(config, res, dict(wall_s=wall, rollouts=n, ticks_per_rollout=ticks,
                                        chunks=math.ceil(n / chunk)))


def summary(run: HoldoutRun) -> dict:
    """Recovery rate, steps to recover and the largest recovered impulse per phase of a held-out sweep.

    Also takes a :class:`sweeps.runner.SweepRun` (the MJX held-out sweeps of :mod:`sweeps.holdout_mjx`,
    which have no ``late_error``).
    """
    res, cfg = run.results, run.config
    ok = report.recovered(res)
    pushed = res["impulse_ns"] > 0
    steps = res["steps_to_recover"][ok & pushed]
    settled = steps[steps >= 0]
    return dict(
        direction=cfg.direction, rollouts=int(cfg.n_rollouts), recovery_rate=float(np.mean(ok)),
        pushed_recovery_rate=float(np.mean(ok[pushed])) if pushed.any() else None,
        undisturbed_fell=int(np.sum(~ok & ~pushed)),
        mean_steps_to_recover=float(np.mean(settled)) if settled.size else None,
        recovered_but_unsettled=int(np.sum(steps < 0)),
        late_error_median=float(np.median(res["late_error"][ok])) if ok.any() and "late_error" in res else None,
        per_phase=[dict(phase=r["phase"], max_recovered_impulse_ns=r["max_recovered_impulse_ns"],
                        recovery_rate=r["recovery_rate"]) for r in report.per_phase(cfg, res)],
        wall_s=run.timing.get("wall_s"),
    )


def holdout_configs(directions=("forward", "backward"), phases=tuple(k / 16 for k in range(16)),
                    impulses_ns=tuple(float(v) for v in np.linspace(0.0, 14.0, 29)), noise_std_m: float = 1e-3,
                    n_steps: int = 10, seed: int = 1001, controller: str = "time-projection") -> list[SweepConfig]:
    """The held-out grids: one per direction, 10-step walks pushed in step 2, a noise seed unlike training's."""
    return [SweepConfig(model="3lp", controller=controller, phases=tuple(phases), impulses_ns=tuple(impulses_ns),
                        direction=d, push_step=2, n_steps=n_steps, noise_std_m=noise_std_m, seed=seed).validate()
            for d in directions]


def compare(runs: dict[str, list[HoldoutRun]]) -> dict:
    """Per constant set (``"seed"``, ``"tuned"``): per direction summaries and the pooled recovery rate."""
    out = {}
    for name, lst in runs.items():
        per = [summary(r) for r in lst]
        ok = np.concatenate([report.recovered(r.results) for r in lst])
        steps = np.concatenate([r.results["steps_to_recover"][report.recovered(r.results)
                                                              & (r.results["impulse_ns"] > 0)] for r in lst])
        settled = steps[steps >= 0]
        late = np.concatenate([r.results["late_error"][report.recovered(r.results)] for r in lst
                               if "late_error" in r.results] or [np.zeros(0)])
        out[name] = dict(recovery_rate=float(np.mean(ok)), rollouts=int(ok.size),
                         mean_steps_to_recover=float(np.mean(settled)) if settled.size else None,
                         settled_within_tol=int(settled.size),
                         recover_tol=RECOVER_TOL if lst[0].config.model == "3lp" else None,
                         late_error_median=float(np.median(late)) if late.size else None,
                         per_direction=per)
    return out


def plot_holdout(path, runs: dict[str, list[HoldoutRun]]) -> None:
    """Basin maps: one row per constant set, one column per direction, written atomically as PNG."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sweeps.runner import save_bytes_atomic

    names = list(runs)
    ncol = max(len(v) for v in runs.values())
    fig, axes = plt.subplots(len(names), ncol, figsize=(5.2 * ncol, 4.2 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        for j, run in enumerate(runs[name]):
            rate = float(np.mean(report.recovered(run.results)))
            report.plot_basin(axes[i, j], run.config, run.results,
                              title=f"{name} constants: {run.config.direction} pushes, {rate:.0%} recovered")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    save_bytes_atomic(path, buf.getvalue())


_FIELDS = ("index", "phase", "impulse_ns", "direction_rad", "fell", "nan", "steps_to_recover",
           "max_abs_footstep_adjustment_m", "fall_time_s", "late_error")


def save_runs(path, runs: dict[str, list[HoldoutRun]]) -> None:
    """Per-rollout results of held-out sweeps as one ``.npz`` (atomically), configurations included."""
    import json

    from sweeps.runner import save_npz_atomic

    arrays = {}
    for name, lst in runs.items():
        for r in lst:
            tag = f"{name}/{r.config.direction}"
            arrays.update({f"{tag}/{k}": np.asarray(r.results[k]) for k in _FIELDS if k in r.results})
            arrays[f"{tag}/config"] = np.asarray(json.dumps(r.config.to_dict()))
    save_npz_atomic(path, arrays)


def load_runs(path) -> dict[str, list[HoldoutRun]]:
    """The inverse of :func:`save_runs` (timing left empty)."""
    import json

    runs: dict[str, list[HoldoutRun]] = {}
    with np.load(path) as z:
        tags = sorted({k.rsplit("/", 1)[0] for k in z.files}, key=lambda t: list(z.files).index(f"{t}/index"))
        for tag in tags:
            cfg = json.loads(str(z[f"{tag}/config"]))
            cfg["phases"], cfg["impulses_ns"] = tuple(cfg["phases"]), tuple(cfg["impulses_ns"])
            if cfg.get("deadzone") is not None:
                cfg["deadzone"] = tuple(cfg["deadzone"])
            res = {k: z[f"{tag}/{k}"] for k in _FIELDS if f"{tag}/{k}" in z.files}
            res["reason"] = np.where(res["nan"], "nan", np.where(res["fell"], "fell", ""))
            runs.setdefault(tag.split("/")[0], []).append(HoldoutRun(SweepConfig(**cfg), res, {}))
    return runs

