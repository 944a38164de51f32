"""Environment steps per second of the simulated COMAN, per batch size.

    python bench/coman_step.py [--batch 1 16 256 1024] [--ticks 50] [--repeats 3] [--json]

One "step" is one 2 ms control tick (two 1 ms physics substeps, actuators,
delay line and sensors) of one robot. Each batch runs ``--ticks`` ticks in one
jitted ``lax.scan`` over a ``vmap`` of :func:`mjx_coman.env.step`, with
different spring stiffnesses per rollout; compilation is timed separately and
the best of ``--repeats`` timed runs is reported.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.files import strict_json
from mjx_coman import env
from mjx_coman.actuators import make_actuator_params


def _batched(params: env.EnvParams, state: env.EnvState, n: int):
    acts = [make_actuator_params(spring_stiffness_nm_per_rad=k) for k in np.linspace(300.0, 480.0, n)]
    params = dataclasses.replace(
        params,
        actuator=jax.tree_util.tree_map(lambda *x: jnp.stack(x), *acts),
        sensor=jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,) + x.shape), params.sensor),
    )
    state = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,) + x.shape), state)
    return params, state


def bench(batch_sizes=(1, 16, 256, 1024), ticks: int = 50, repeats: int = 3) -> dict:
    """Time ``ticks`` control ticks for each batch size; return steps/s and compile times."""
    params = env.make_env_params()
    state0 = jax.jit(env.reset)(jax.random.PRNGKey(0), params)
    cmd = env.make_command(env.standing_posture()[0])
    results = []
    for n in batch_sizes:
        p, s = _batched(params, state0, n)

        @jax.jit
        def run(p, s):
            def one(pp, ss):
                return jax.lax.scan(lambda c, _: (env.step(pp, c, cmd), None), ss, None, length=ticks)[0]

            return jax.vmap(one, in_axes=(env.batch_axes(p), 0))(p, s)

        t0 = time.perf_counter()
        jax.block_until_ready(run(p, s))
        compile_s = time.perf_counter() - t0
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(run(p, s))
            best = min(best, time.perf_counter() - t0)
        results.append(dict(batch=n, ticks=ticks, seconds=best, compile_s=compile_s,
                            env_steps_per_s=n * ticks / best,
                            sim_seconds_per_wall_second=n * ticks * float(params.control_period_s) / best))
    return dict(device=str(jax.devices()[0]), platform=platform.processor() or platform.machine(),
                cpu_count=os.cpu_count(), jax=jax.__version__, control_period_s=float(params.control_period_s),
                substeps=params.n_substeps, results=results)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 16, 256, 1024])
    ap.add_argument("--ticks", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out = bench(tuple(args.batch), args.ticks, args.repeats)
    if args.json:
        print(strict_json(out, indent=2))
    else:
        print(f"{out['device']}  ({out['cpu_count']} CPUs, jax {out['jax']})")
        for r in out["results"]:
            print(f"batch {r['batch']:5d}: {r['env_steps_per_s']:10.0f} steps/s  "
                  f"({r['sim_seconds_per_wall_second']:.2f} sim s per s; compile {r['compile_s']:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
