"""Whole-body QP solve time on qpax, per batch size, next to proxsuite on the same QPs.

    python bench/wbc_qp.py [--batch 1 64 256 1024] [--repeats 3] [--no-float32] [--quick] [--json]

The QPs are those of a standing balance tick (:func:`mjx_coman.wbc.reference.standing_tasks`) on random
standing states built with MuJoCo's C functions (:mod:`mjx_coman.wbc.reference`; every fourth state on
the left foot only), full body and with the upper body fixed. Each configuration (dtype, body, batch)
is one jitted ``vmap`` of :func:`mjx_coman.wbc.solve_qp` on the assembled QPs (assembly not timed; on
CPU the vmap runs the solves as a loop, see :func:`mjx_coman.wbc.batching.per_problem`);
compilation is timed apart and the best of ``--repeats`` runs is reported; batch 1 is the median of
``--latency-calls`` calls. proxsuite (ProxQP, dense, through ``qpsolvers.solve_qp(..., solver="proxqp")``,
so including qpsolvers' Python conversion) solves the float64 QPs one by one on one core to 1e-9.
``iterations_to_tol`` is the least qpax iteration count whose iterate passes the KKT tolerance
(:data:`mjx_coman.wbc.solver.TOLERANCES`), from one sweep over the cap at batch 64; qpax itself runs to
its cap (its own flag cannot trip below its sqrt(eps) floor, see :func:`mjx_coman.wbc.solve_qp`).
Seed 001 reports 1.2 ms per QP (0.7 ms with the upper body fixed) with CVXGEN on a Core i5 1.7 GHz.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)  # float64 QPs; the float32 ones are cast explicitly

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import qpax  # noqa: E402
import qpsolvers  # noqa: E402

import mjx_coman  # noqa: E402
from jaxlp.files import strict_json
from mjx_coman import wbc  # noqa: E402
from mjx_coman.env import standing_posture  # noqa: E402
from mjx_coman.wbc import reference as ref  # noqa: E402
from mjx_coman.wbc.plant import LEG_JOINTS, N_BASE  # noqa: E402
from mjx_coman.wbc.solver import TOLERANCES  # noqa: E402

SEED_001_MS = {"full": 1.2, "fixed_upper_body": 0.7}
TAU_LIMIT_NM = 33.0


def make_qps(n_states: int, seed: int = 0) -> dict:
    """``{body: QP}`` stacked over ``n_states`` random standing states (float64)."""
    model = mjx_coman.load_model()
    states = ref.standing_plants(model, n_states, seed=seed)
    masks = np.array([(0.0, 1.0) if i % 4 == 3 else (1.0, 1.0) for i in range(n_states)])
    com_des = []
    for (_, _, p), m in zip(states, masks):
        stance = p.contact_pos[m > 0.5].reshape(-1, 3)
        com_des.append([*stance[:, :2].mean(0), p.com[2]])
    q_ref = standing_posture()[0]
    plant = ref.stack_plants([s[2] for s in states])
    qpos, qvel = np.stack([s[0] for s in states]), np.stack([s[1] for s in states])
    lim = jnp.full(23, TAU_LIMIT_NM)

    def build(p, qp_, qv, cd, mask, fixed):
        tasks = ref.standing_tasks(p, qp_, qv, q_ref, cd, mask)
        kw = {}
        if fixed:
            kw = dict(fixed_upper_body=True, upper_acc=wbc.joint_pd(
                q_ref[LEG_JOINTS:], qp_[7 + LEG_JOINTS:], qv[N_BASE + LEG_JOINTS:], 100.0, 20.0))
        return wbc.build_qp(p, tasks, mask, -lim, lim, **kw)

    return {body: jax.jit(jax.vmap(lambda *a, f=fixed: build(*a, f)))(plant, qpos, qvel, np.array(com_des), masks)
            for body, fixed in (("full", False), ("fixed_upper_body", True))}


def _take(qp, n: int, dtype):
    """The first ``n`` QPs (tiled if fewer) in ``dtype``."""
    have = qp.Q.shape[0]
    idx = np.arange(n) % have
    return jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a)[idx], dtype), qp)


def time_qpax(qp, batch: int, dtype, repeats: int, latency_calls: int) -> dict:
    data = _take(qp, batch, dtype)
    solve = jax.jit(jax.vmap(lambda d: wbc.solve_qp(d)))
    t0 = time.perf_counter()
    x, info = jax.block_until_ready(solve(data))
    compile_s = time.perf_counter() - t0
    if batch == 1:
        ts = []
        for _ in range(latency_calls):
            t0 = time.perf_counter()
            jax.block_until_ready(solve(data))
            ts.append(time.perf_counter() - t0)
        seconds = float(np.median(ts))
    else:
        seconds = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(solve(data))
            seconds = min(seconds, time.perf_counter() - t0)
    assert np.asarray(x).dtype == dtype
    return dict(batch=batch, seconds=seconds, ms_per_solve=1e3 * seconds / batch, compile_s=compile_s,
                ok_fraction=float(np.mean(info.ok)), iterations_run=float(np.mean(info.iterations)),
                x=np.asarray(x, np.float64))


def iterations_to_tol(qp, dtype, batch: int = 64) -> dict:
    """Least qpax iteration cap whose iterate passes the KKT tolerance, per QP (one compiled sweep)."""
    data = _take(qp, batch, dtype)
    tols = TOLERANCES["float64" if dtype == np.float64 else "float32"]
    caps = np.arange(1, tols["max_iter"] + 1)

    def kkt_at(d, cap):
        x, s, z, y, _, _ = qpax.solve_qp(d.Q, d.q, d.A, d.b, d.G, d.h, solver_tol=1e-12, max_iter=cap)
        return wbc.kkt_residual(d.Q, d.q, d.A, d.b, d.G, d.h, x, z, y)

    pairs = (jax.tree_util.tree_map(lambda a: jnp.repeat(a, len(caps), axis=0), data), jnp.tile(caps, batch))
    # a loop, not a vmap: batched CPU LAPACK calls can deadlock (mjx_coman.wbc.batching.per_problem)
    kkt = jax.jit(lambda p: jax.lax.map(lambda pc: kkt_at(*pc), p))(pairs).reshape(batch, len(caps))
    passed = np.asarray(kkt) < tols["kkt"]
    first = np.where(passed.any(1), passed.argmax(1) + 1, -1)
    return dict(mean=float(np.mean(first[first > 0])) if np.any(first > 0) else None,
                max=int(first.max()), never=int(np.sum(first < 0)), cap=int(tols["max_iter"]))


def time_proxsuite(qp, n: int) -> dict:
    data = _take(qp, n, np.float64)
    xs, ts = [], []
    for j in range(n):
        e = wbc.export_qp(jax.tree_util.tree_map(lambda a: a[j], data))
        t0 = time.perf_counter()
        x = qpsolvers.solve_qp(**e, solver="proxqp", eps_abs=1e-9, eps_rel=0.0)
        ts.append(time.perf_counter() - t0)
        xs.append(x)
    return dict(n=n, ms_per_solve=1e3 * float(np.mean(ts)), x=np.stack(xs))


def bench(batch_sizes=(1, 64, 256, 1024), repeats: int = 3, float32: bool = True, latency_calls: int = 50,
          n_states: int = 128, n_proxsuite: int = 128) -> dict:
    t_start = time.perf_counter()
    qps = make_qps(n_states)
    dtypes = [np.float64] + ([np.float32] if float32 else [])
    out = dict(device=str(jax.devices()[0]), platform=platform.processor() or platform.machine(),
               cpu_count=os.cpu_count(), jax=jax.__version__, qpax=qpax.__version__ if hasattr(qpax, "__version__")
               else "0.1.4", seed_001_cvxgen_ms=SEED_001_MS, n_states=n_states, results=[])
    for body, qp in qps.items():
        n_eq, n_var = qp.A.shape[1:]
        size = dict(variables=int(n_var), equalities=int(n_eq), inequalities=int(qp.G.shape[1]))
        prox = time_proxsuite(qp, n_proxsuite)
        for dt in dtypes:
            iters = iterations_to_tol(qp, dt)
            rows = []
            for b in batch_sizes:
                r = time_qpax(qp, b, dt, repeats, latency_calls)
                m = min(b, n_proxsuite)
                r["max_abs_diff_vs_proxsuite"] = float(np.max(np.abs(r.pop("x")[:m] - prox["x"][:m])))
                r["ratio_to_proxsuite"] = r["ms_per_solve"] / prox["ms_per_solve"]
                rows.append(r)
            out["results"].append(dict(body=body, dtype=np.dtype(dt).name, size=size, iterations_to_tol=iters,
                                       proxsuite_ms_per_solve=prox["ms_per_solve"],
                                       seed_001_cvxgen_ms=SEED_001_MS[body], batches=rows))
    out["wall_s"] = time.perf_counter() - t_start
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 64, 256, 1024])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--latency-calls", type=int, default=50)
    ap.add_argument("--no-float32", action="store_true")
    ap.add_argument("--quick", action="store_true", help="batches 1 and 64, float64, fewer calls")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        out = bench((1, 64), repeats=2, float32=False, latency_calls=10, n_states=32, n_proxsuite=32)
    else:
        out = bench(tuple(args.batch), args.repeats, not args.no_float32, args.latency_calls)
    if args.json:
        print(strict_json(out, indent=2))
        return 0
    print(f"{out['device']}  ({out['cpu_count']} CPUs, jax {out['jax']}, qpax {out['qpax']}); "
          f"seed 001 (CVXGEN, Core i5 1.7 GHz): {SEED_001_MS['full']} ms full, {SEED_001_MS['fixed_upper_body']} ms "
          "fixed upper body")
    for r in out["results"]:
        s, it = r["size"], r["iterations_to_tol"]
        print(f"\n{r['body']} {r['dtype']}: {s['variables']} variables, {s['equalities']} equalities, "
              f"{s['inequalities']} inequalities; iterations to tolerance mean {it['mean']:.1f}, max {it['max']} "
              f"(cap {it['cap']}, never {it['never']}); proxsuite {r['proxsuite_ms_per_solve']:.3f} ms/solve")
        for b in r["batches"]:
            print(f"  batch {b['batch']:5d}: {b['ms_per_solve']:8.4f} ms/solve  ({b['ratio_to_proxsuite']:.2f}x "
                  f"proxsuite; ok {b['ok_fraction']:.2f}; |x - proxsuite| {b['max_abs_diff_vs_proxsuite']:.1e}; "
                  f"compile {b['compile_s']:.1f} s)")
    print(f"\nwall {out['wall_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
