"""Closed-loop 3LP time-projection control: JAX batches against the same loop in NumPy, vectorized over the batch.

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

Baseline (``baseline_us_per_tick``, ``speedup_*``): the same closed loop as a
NumPy user would port it, float64, vectorized over the batch
(:class:`VectorizedBaseline`), run on the same batches of pushes: per call, the
plan with SciPy (``exp(G t)`` at every tick of a phase in one batched
``scipy.linalg.expm``, giving the nominal state and the eq. 18 gains in one
batched ``numpy.linalg.solve``; ``exp(G dt)`` the tick map), then a Python
loop over the ticks, each tick a dozen array operations on all rollouts, with
the per-tick pelvis, feet and torque arrays kept as JAX keeps them. Timed as
JAX is (best of ``min(--repeats, 2)`` calls, plan included). Its trajectories
are compared with JAX's: where neither fell, the final pelvis of every rollout
and the whole pelvis trajectory of the first 64; the share within
1 mm must be at least 99 % (float32 against float64: a rollout on the verge of
a fall amplifies rounding) and the rollouts that fell are counted where the
two disagree.

Per-rollout reference (``per_rollout_expm_*``; until issue 21 this was the
baseline, quoted as a 1500x speedup): the closed loop written as the algorithm
states it (seed 000, eq. 16-18), one rollout at a time: at every tick and for
each axis it recomputes ``exp(G t)`` (``scipy.linalg.expm``; it gives the
within-phase maps ``A(t)``, ``B(t)`` and the nominal state), solves
``[[A(t), B(t)], [K, I]] [E; dU] = [e; 0]`` with ``numpy.linalg.solve``,
recomputes the tick map ``exp(G dt)`` and integrates one tick. It stays as an
independent check: its pelvis trajectory under one push is compared with
JAX's (``max_pelvis_difference_m``) and with the vectorized port's (float64
both: agreement to rounding). Only the gait, the DLQR gains ``K`` and the
generators ``G`` come from :mod:`jaxlp`.

NumPy's BLAS runs on one thread (``OPENBLAS_NUM_THREADS=1`` unless set): the
per-rollout reference's matrices are 12x12, and multi-threaded OpenBLAS on
such sizes, with another process busy on the cores, was measured 500 times
slower (8 ms per ``expm`` instead of 15 us). XLA does not use OpenBLAS, so JAX
is unaffected.

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

from jaxlp.presets import get_params
from jaxlp.simulate import Push, SimSpec, simulate
from threelp_numpy import (CHECK_PUSH, N_CHECK, PELVIS_TOLERANCE_M, PUSH_DURATION_S, VECTORIZED_SHARE,  # noqa: E402
                           Baseline, VectorizedBaseline, _pushes, bench_baseline, bench_vectorized)



# ----------------------------------------------------------------------------- JAX




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
                      first_pelvis=np.asarray(res[0].pelvis_m[0]), first_fell=bool(fell[0]), fell=fell,
                      final=np.concatenate([np.asarray(r.pelvis_m[:, -1]) for r in res]),
                      pelvis=np.concatenate([np.asarray(r.pelvis_m[:N_CHECK]) for r in res])[:N_CHECK])
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

    vec = VectorizedBaseline(params, spec)
    vres = bench_vectorized(vec, spec.n_steps, batches, max(1, min(args.repeats, 2)))
    vec_us = {n: r["seconds"] * 1e6 / (n * ticks) for n, r in vres.items()}
    t0 = time.perf_counter()
    vec.plan()
    vec_plan_s = time.perf_counter() - t0
    # the vectorized port against the per-rollout one (both float64) on the check push, then against JAX (float32)
    vec_vs_expm = float(np.max(np.abs(vres[1]["pelvis"][0, :base_ticks] - base_pel)))
    mismatch, diffs = {}, []
    for n in batches:
        j, v = jres[n], vres[n]
        mismatch[n] = int(np.sum(j["fell"] != v["fell"]))
        d = np.max(np.abs(j["final"] - v["final"]), axis=-1)  # per rollout: final pelvis, whole trajectory of
        c = min(n, N_CHECK)                                     # the first N_CHECK
        d[:c] = np.maximum(d[:c], np.max(np.abs(j["pelvis"] - v["pelvis"]), axis=(1, 2)))
        diffs.append(d[~j["fell"] & ~v["fell"]])  # compared where neither fell (a fall may freeze a tick apart)
    diffs = np.concatenate(diffs)
    vec_diff = float(np.max(diffs, initial=0.0))
    vec_share = float(np.mean(diffs < PELVIS_TOLERANCE_M)) if diffs.size else 1.0

    out = {
        "us_per_tick": {str(n): r["us_per_tick"] for n, r in jres.items()},
        "baseline_us_per_tick": vec_us[largest],
        f"speedup_at_{largest}": vec_us[largest] / jres[largest]["us_per_tick"],
        "baseline_us_per_tick_by_batch": {str(n): u for n, u in vec_us.items()},
        "speedup_by_batch": {str(n): vec_us[n] / jres[n]["us_per_tick"] for n in batches},
        "baseline": "NumPy/SciPy float64, vectorized over the batch, plan (expm, eq. 18 gains) per call",
        "compile_s": {str(n): r["compile_s"] for n, r in jres.items()},
        "device": str(jax.devices()[0]),
        "max_pelvis_difference_m": max_diff,
        "pelvis_within_tolerance": bool(max_diff < PELVIS_TOLERANCE_M),
        "pelvis_tolerance_m": PELVIS_TOLERANCE_M,
        "baseline_vs_jax_max_pelvis_difference_m": vec_diff,
        "baseline_vs_jax_share_within_tolerance": vec_share,
        "baseline_vs_jax_within_tolerance": bool(vec_share >= VECTORIZED_SHARE),
        "baseline_vs_jax_fell_mismatches": {str(n): m for n, m in mismatch.items()},
        "baseline_vs_per_rollout_expm_max_pelvis_difference_m": vec_vs_expm,
        "check_push": dict(CHECK_PUSH, duration_s=PUSH_DURATION_S, fell=jres[1]["first_fell"]),
        "ticks_per_rollout": ticks,
        "dt_s": spec.dt_s,
        "baseline_ticks": ticks,
        "baseline_s": vres[largest]["seconds"],
        "baseline_seconds_by_batch": {str(n): r["seconds"] for n, r in vres.items()},
        "baseline_plan_s_per_call": vec_plan_s,
        "per_rollout_expm_us_per_tick": base_us,
        f"speedup_vs_per_rollout_expm_at_{largest}": base_us / jres[largest]["us_per_tick"],
        "per_rollout_expm_ticks": base_ticks,
        "per_rollout_expm_s": base_s,
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
    print(f"{'batch':>7} {'us/rollout-tick':>16} {'wall s':>9} {'compile s':>10} {'chunks':>7} {'fell':>6} "
          f"{'NumPy us':>9} {'speedup':>9}")
    for n, r in jres.items():
        print(f"{n:>7} {r['us_per_tick']:>16.4f} {r['seconds']:>9.3f} {r['compile_s']:>10.2f} "
              f"{r['chunks']:>7} {r['fell_fraction']:>6.2f} {vec_us[n]:>9.4f} {vec_us[n] / r['us_per_tick']:>9.2f}")
    print(f"baseline (NumPy/SciPy float64, vectorized over the batch, plan per call of {vec_plan_s * 1e3:.1f} ms): "
          f"NumPy us/rollout-tick above; pelvis within {PELVIS_TOLERANCE_M:g} m of JAX's in {vec_share:.2%} of the "
          f"rollouts where neither fell (at most {vec_diff:.3g} m), fell flags differing: {sum(mismatch.values())}")
    print(f"per-rollout baseline (4 expm + 2 solves per tick, float64): {base_us:.1f} us/tick "
          f"over {base_ticks} ticks ({base_s:.2f} s); vectorized port within {vec_vs_expm:.3g} m of it")
    print(f"plan (gait, DLQR, gain tables) inside each JAX call: {plan_s * 1e3:.2f} ms")
    print(f"max pelvis difference, JAX vs per-rollout baseline, same push: {max_diff:.3g} m "
          f"({'within' if out['pelvis_within_tolerance'] else 'OUTSIDE'} {PELVIS_TOLERANCE_M:g} m)")
    print(f"speedup at batch {largest} over the vectorized baseline: {out[f'speedup_at_{largest}']:.2f}x "
          f"(over the per-rollout one: {out[f'speedup_vs_per_rollout_expm_at_{largest}']:.0f}x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
