"""Closed-loop 3LP time-projection control: JAX batches against a per-tick NumPy/SciPy baseline.

    python bench/3lp_closed_loop.py [--json] [--batches 1,1024,16384] [--steps 5]
                                    [--baseline-steps N] [--repeats 3] [--chunk 0]

JAX: one jitted call of ``jax.vmap`` over :func:`jaxlp.simulate.simulate`
(``SimSpec(controller="time-projection", n_steps=--steps)``, 2 ms ticks, JAX's
default float32), each rollout a different push (start time, force, heading).
The first call is timed as compile time; then the best of ``--repeats`` calls,
each waited for with ``block_until_ready``. The call includes everything
``simulate`` does: its plan (gait, DLQR, gain tables, about 1 ms to tens of ms,
paid once per call whatever the batch) and the full per-tick result arrays.
Reported as microseconds per rollout-tick: wall / (batch * ticks).

Baseline: the same closed loop written as the algorithm states it (seed 000,
eq. 16-18), in NumPy/SciPy, float64, one rollout: at every tick and for each
axis it recomputes ``exp(G t)`` (``scipy.linalg.expm``; it gives the
within-phase maps ``A(t)``, ``B(t)`` and the nominal state), solves
``[[A(t), B(t)], [K, I]] [E; dU] = [e; 0]`` with ``numpy.linalg.solve``,
recomputes the tick map ``exp(G dt)`` and integrates one tick. Only the gait,
the DLQR gains ``K`` and the generators ``G`` come from :mod:`jaxlp`. Its
pelvis trajectory is checked against the JAX one of the same push.

The baseline's BLAS runs on one thread (``OPENBLAS_NUM_THREADS=1`` unless
set): its matrices are 12x12, and multi-threaded OpenBLAS on such sizes, with
another process busy on the cores, was measured 500 times slower (8 ms per
``expm`` instead of 15 us), which would inflate the speedup. XLA does not use
OpenBLAS, so JAX is unaffected.

``--chunk C`` (0: none) runs large batches as several calls of at most C
rollouts each, timed together; the output says when it did.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads; see the module docstring

from jaxlp.files import strict_json
from jaxlp.xla_flags import configure_cpu

configure_cpu()  # the project's XLA CPU flags, before JAX starts (jaxlp.xla_flags)
import jax
import jax.numpy as jnp
import numpy as np
import scipy
import scipy.linalg

from jaxlp import control, gait as gait_mod
from jaxlp.dynamics import N_AUG, N_Q, generator
from jaxlp.presets import get_params
from jaxlp.simulate import Push, SimSpec, make_limits, simulate

PUSH_DURATION_S = 0.1
# The push of the baseline and of batch 1: mid-phase (step 1, 0.3 of it), off the tick grid, both axes.
CHECK_PUSH = dict(start_s=0.5213, force_n=90.0, direction_rad=0.6)
PELVIS_TOLERANCE_M = 1e-3


# ----------------------------------------------------------------------------- JAX


def _pushes(n: int, total_s: float):
    """``n`` pushes spread over start times, forces and headings (the first is CHECK_PUSH)."""
    rng = np.random.default_rng(0)
    start = rng.uniform(0.0, max(total_s - PUSH_DURATION_S, 0.0), n)
    force = rng.uniform(0.0, 150.0, n)
    direction = rng.uniform(-np.pi, np.pi, n)
    start[0], force[0], direction[0] = CHECK_PUSH["start_s"], CHECK_PUSH["force_n"], CHECK_PUSH["direction_rad"]
    return start, force, direction


def _runner(spec: SimSpec):
    def one(params, start, force, direction):
        push = Push(start, jnp.asarray(PUSH_DURATION_S, start.dtype), force, direction)
        return simulate(params, push, spec)

    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0)))


def bench_jax(params, spec: SimSpec, batches, repeats: int, chunk: int) -> dict:
    run = _runner(spec)
    ticks = spec.n_steps * spec.ticks_per_step
    out = {}
    for n in batches:
        start, force, direction = _pushes(n, spec.n_steps * spec.step_time_s)
        size = n if chunk <= 0 else min(n, chunk)
        pieces = [tuple(jnp.asarray(a[i:i + size]) for a in (start, force, direction)) for i in range(0, n, size)]

        def call():
            res = [run(params, *p) for p in pieces]
            jax.block_until_ready(res)
            return res

        t0 = time.perf_counter()
        res = call()  # compile (one shape per chunk size; a ragged last chunk compiles again)
        compile_s = time.perf_counter() - t0
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = call()
            best = min(best, time.perf_counter() - t0)
        fell = np.concatenate([np.asarray(r.fell) for r in res])
        out[n] = dict(seconds=best, compile_s=compile_s, us_per_tick=best * 1e6 / (n * ticks),
                      chunks=len(pieces), chunk_size=size, fell_fraction=float(fell.mean()),
                      finite=bool(all(np.isfinite(np.asarray(r.pelvis_m)).all() for r in res)),
                      first_pelvis=np.asarray(res[0].pelvis_m[0]), first_fell=bool(fell[0]))
        del res
    return out


def time_plan(params, spec: SimSpec) -> float:
    """Seconds of the plan alone (gait, DLQR, gain tables), jitted, best of 3: a fixed cost per call."""
    from jaxlp.simulate import make_plan

    f = jax.jit(lambda p: make_plan(p, spec))
    jax.block_until_ready(f(params))
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        jax.block_until_ready(f(params))
        best = min(best, time.perf_counter() - t0)
    return best


# ------------------------------------------------------------------------ baseline


M_ERR = np.asarray(control.M_ERR, float)
M_HAT = np.asarray(control.M_HAT, float)


class Baseline:
    """The time-projection closed loop, recomputed from matrix exponentials at every tick (one rollout)."""

    def __init__(self, params, spec: SimSpec):
        self.spec = spec
        g = gait_mod.periodic_gait(params, spec.step_time_s, 0.0, None)
        self.q0 = np.asarray(g.q0, float)  # (2, 6)
        self.u_nom = np.asarray(g.u, float)  # (2, 2)
        self.K = np.stack([np.asarray(control.constrained_dlqr(params, spec.step_time_s, lateral=lat).K, float)
                           for lat in (False, True)])  # (2, 2, 4)
        self.G = np.stack([np.asarray(generator(params, lat), float) for lat in (False, True)])  # (2, 12, 12)
        lim = make_limits()
        self.max_tau = float(lim.max_hip_torque_nm)
        self.max_lean = float(lim.max_lean_ratio) * float(params.h1)
        self.max_step = float(lim.max_step_ratio) * float(params.h1)

    def run(self, start_s, force_n, direction_rad, n_steps: int) -> np.ndarray:
        """Pelvis positions (n_steps * ticks, 2) after each tick."""
        sp = self.spec
        n, dt, T = sp.ticks_per_step, sp.dt_s, sp.step_time_s
        q = self.q0.copy()
        d = 1.0
        fallen = False
        pelvis = np.empty((n_steps * n, 2))
        heading = np.array([math.cos(direction_rad), math.sin(direction_rad)])
        eye2, zeros24 = np.eye(2), np.zeros((2, 4))
        for step in range(n_steps):
            for k in range(n):
                t = k * dt
                now = step * T + t
                sign = np.array([1.0, d])
                q_new = np.empty((2, N_Q))
                tau_all = np.empty(2)
                for ax in range(2):
                    # within-phase map from the phase start to now (seed 000, eq. 5, 16)
                    phi = scipy.linalg.expm(self.G[ax] * t)
                    A_t, B_t = phi[:N_Q, :N_Q], phi[:N_Q, 6:8]
                    nominal = (A_t @ self.q0[ax] + B_t @ self.u_nom[ax] + phi[:N_Q, 11]) * sign[ax]
                    e = sign[ax] * (M_ERR @ (q[ax] - nominal))
                    # time projection (seed 000, eq. 18)
                    system = np.block([[M_ERR @ A_t @ M_HAT, M_ERR @ B_t], [self.K[ax], eye2]])
                    sol = np.linalg.solve(system, np.concatenate([e, np.zeros(2)]))
                    dU = sol[4:6] * sign[ax]
                    tau = sign[ax] * (self.u_nom[ax, 0] + t * self.u_nom[ax, 1]) + dU[0] + t * dU[1]
                    rate = sign[ax] * self.u_nom[ax, 1] + dU[1]
                    if abs(tau) > self.max_tau:
                        tau, rate = math.copysign(self.max_tau, tau), 0.0
                    overlap = min(max(min(now + dt, start_s + PUSH_DURATION_S) - max(now, start_s), 0.0), dt)
                    z = np.zeros(N_AUG)
                    z[:N_Q], z[6], z[7] = q[ax], tau, rate
                    z[10], z[11] = force_n * overlap / dt * heading[ax], d
                    q_new[ax] = (scipy.linalg.expm(self.G[ax] * dt) @ z)[:N_Q]  # tick map
                    tau_all[ax] = tau
                bad = bool(np.any(np.abs(q_new[:, 1] - q_new[:, 2]) > self.max_lean) or not np.all(np.isfinite(q_new)))
                fallen = fallen or bad
                if not fallen:
                    q = q_new
                pelvis[step * n + k] = q[:, 1]
            # landing: the feet swap roles
            was_fallen = fallen
            if abs(q[0, 0] - q[0, 2]) > self.max_step:
                fallen = True
            if not was_fallen:
                q = np.stack([q[:, 2], q[:, 1], q[:, 0], np.zeros(2), q[:, 4], np.zeros(2)], axis=1)
            d = -d
        return pelvis


def bench_baseline(base: Baseline, n_steps: int, repeats: int):
    best, pel = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        pel = base.run(CHECK_PUSH["start_s"], CHECK_PUSH["force_n"], CHECK_PUSH["direction_rad"], n_steps)
        best = min(best, time.perf_counter() - t0)
    return best, pel


# ---------------------------------------------------------------------------- main


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batches", default="1,1024,16384", help="comma-separated batch sizes")
    ap.add_argument("--steps", type=int, default=5, help="phases per rollout (200 ticks each)")
    ap.add_argument("--baseline-steps", type=int, default=None, help="phases of the baseline (default --steps)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chunk", type=int, default=0, help="largest batch per call (0: whole batch)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    batches = sorted({int(b) for b in args.batches.split(",") if b.strip()})
    if 1 not in batches:
        batches = [1] + batches  # the trajectory check uses the batch-1 rollout
    spec = SimSpec(controller="time-projection", n_steps=args.steps).validate()
    ticks = spec.n_steps * spec.ticks_per_step
    base_steps = min(args.baseline_steps or args.steps, args.steps)
    params = get_params("coman")

    jres = bench_jax(params, spec, batches, args.repeats, args.chunk)
    plan_s = time_plan(params, spec)
    base = Baseline(params, spec)
    base_s, base_pel = bench_baseline(base, base_steps, max(1, min(args.repeats, 2)))
    base_ticks = base_steps * spec.ticks_per_step
    base_us = base_s * 1e6 / base_ticks
    jax_pel = jres[1]["first_pelvis"][:base_ticks]
    max_diff = float(np.max(np.abs(jax_pel - base_pel)))
    largest = max(batches)

    out = {
        "us_per_tick": {str(n): r["us_per_tick"] for n, r in jres.items()},
        "baseline_us_per_tick": base_us,
        f"speedup_at_{largest}": base_us / jres[largest]["us_per_tick"],
        "compile_s": {str(n): r["compile_s"] for n, r in jres.items()},
        "device": str(jax.devices()[0]),
        "max_pelvis_difference_m": max_diff,
        "pelvis_within_tolerance": bool(max_diff < PELVIS_TOLERANCE_M),
        "pelvis_tolerance_m": PELVIS_TOLERANCE_M,
        "check_push": dict(CHECK_PUSH, duration_s=PUSH_DURATION_S, fell=jres[1]["first_fell"]),
        "ticks_per_rollout": ticks,
        "dt_s": spec.dt_s,
        "baseline_ticks": base_ticks,
        "baseline_s": base_s,
        "jax_seconds": {str(n): r["seconds"] for n, r in jres.items()},
        "chunks": {str(n): r["chunks"] for n, r in jres.items()},
        "fell_fraction": {str(n): r["fell_fraction"] for n, r in jres.items()},
        "all_finite": all(r["finite"] for r in jres.values()),
        "plan_s_per_call": plan_s,
        "dtype": str(jnp.zeros(()).dtype),
        "cpu_count": os.cpu_count(),
        "platform": platform.processor() or platform.machine(),
        "versions": {"jax": jax.__version__, "numpy": np.__version__, "scipy": scipy.__version__},
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }
    if args.json:
        print(strict_json(out, indent=2))
        return 0
    print(f"3LP closed loop, time projection: {ticks} ticks per rollout ({spec.n_steps} steps, "
          f"{spec.dt_s * 1e3:g} ms), {out['dtype']}, {out['device']} ({out['cpu_count']} CPUs, jax {jax.__version__})")
    print(f"{'batch':>7} {'us/rollout-tick':>16} {'wall s':>9} {'compile s':>10} {'chunks':>7} {'fell':>6} {'speedup':>9}")
    for n, r in jres.items():
        print(f"{n:>7} {r['us_per_tick']:>16.4f} {r['seconds']:>9.3f} {r['compile_s']:>10.2f} "
              f"{r['chunks']:>7} {r['fell_fraction']:>6.2f} {base_us / r['us_per_tick']:>9.1f}")
    print(f"baseline (NumPy/SciPy, 4 expm + 2 solves per tick, float64): {base_us:.1f} us/tick "
          f"over {base_ticks} ticks ({base_s:.2f} s)")
    print(f"plan (gait, DLQR, gain tables) inside each JAX call: {plan_s * 1e3:.2f} ms")
    print(f"max pelvis difference, JAX vs baseline, same push: {max_diff:.3g} m "
          f"({'within' if out['pelvis_within_tolerance'] else 'OUTSIDE'} {PELVIS_TOLERANCE_M:g} m)")
    print(f"speedup at batch {largest}: {out[f'speedup_at_{largest}']:.1f}x (goal: 1000x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
