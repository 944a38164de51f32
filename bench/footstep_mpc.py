"""footstep-mpc's costs: the footstep MPC solve (seed 001, eq. 16) per problem, and closed-loop env-steps per second.

    python bench/footstep_mpc.py [--batch 1 256 1024] [--walk-batch 8] [--walk-seconds 1.0] [--repeats 3] [--json]

MPC: :func:`jaxlp.footsteps.plan_footsteps` on random measured CoM states around the in-place reference plan
(``N = 5``, ``dt = 0.4 s``, the controller's ``tau``), in the closed form (one linear solve) and with qpax (the
``|mu z0|`` bound; the controller's iteration cap), each one jitted ``vmap`` per batch size; compilation is
timed apart, the best of ``--repeats`` runs is reported, batch 1 is the median of 50 calls. Seed 001 solved it
in 0.2 ms with CVXGEN. The whole-body QP's solve time is ``bench/wbc_qp.py``'s (fixed upper body, float32:
the same 42-unknown QP the controller solves; seed 001: 0.7 ms).

Closed loop: ``--walk-batch`` walks of ``footstep-mpc`` at 0.2 m/s (:func:`mjx_coman.rollout.batched_walk`,
one compilation), env-steps (control ticks) per second of the second call.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp import footsteps as fs
from jaxlp import lipm
from jaxlp.files import strict_json

SEED_001_MPC_MS = 0.2
SEED_001_QP_FIXED_UPPER_BODY_MS = 0.7


def _problems(n: int, seed: int = 0):
    """``n`` measured CoM states near the in-place plan, right support, mid-step."""
    rng = np.random.default_rng(seed)
    com = np.concatenate([rng.normal(0.0, 0.02, (n, 2)) + [0.0, 0.07], rng.normal(0.0, 0.15, (n, 2))], axis=1)
    return jnp.asarray(com, jnp.float32)


def _mpc_fn(solver: str):
    from mjx_coman.controllers.footstep_mpc.controller import _mpc_qp_solver  # the controller's qpax call

    z0, T = 0.533, 0.4
    tau = lipm.time_constant_s(z0)
    plan = fs.reference_plan(jnp.zeros(2), 0.0, 1.0, 0.0, 0.0, 0.0, T, 0.08, 5)
    kw = dict(max_com_offset_m=0.7 * z0, qp_solver=_mpc_qp_solver) if solver == "qpax" else {}

    def one(com):
        return fs.plan_footsteps(com, jnp.zeros(2), 0.2, plan, fs.default_weights(), T, tau, solver=solver, **kw)

    return jax.jit(jax.vmap(one))


def time_mpc(solver: str, batch: int, repeats: int) -> dict:
    fn = _mpc_fn(solver)
    x = _problems(batch)
    t0 = time.perf_counter()
    jax.block_until_ready(fn(x))
    compile_s = time.perf_counter() - t0
    if batch == 1:
        calls = []
        for _ in range(50):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(x))
            calls.append(time.perf_counter() - t0)
        per = float(np.median(calls))
    else:
        runs = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(x))
            runs.append(time.perf_counter() - t0)
        per = min(runs) / batch
    ok = float(np.mean(np.asarray(fn(x).ok)))
    return dict(solver=solver, batch=batch, ms_per_problem=1e3 * per, compile_s=compile_s, ok_fraction=ok,
                ratio_to_seed_001=1e3 * per / SEED_001_MPC_MS)


def time_walk(batch: int, seconds: float) -> dict:
    from mjx_coman import controllers
    from mjx_coman import rollout as ro

    ctrl, cfg = controllers.load("footstep-mpc")
    env = ro.plant_env_params(ctrl.gait(cfg).plant)
    fn = ro.batched_walk(ctrl, ro.WalkSpec(seconds=seconds))
    push = jax.tree_util.tree_map(lambda a: jnp.stack([a] * batch), ro.no_push())
    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    joy = controllers.joystick(0.2)
    t0 = time.perf_counter()
    jax.block_until_ready(fn(cfg, env, push, keys, joy))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = jax.block_until_ready(fn(cfg, env, push, keys, joy))
    wall = time.perf_counter() - t0
    ticks = ro.n_ticks(ro.WalkSpec(seconds=seconds), ctrl.gait(cfg).control_period_s)
    return dict(batch=batch, seconds=seconds, env_steps_per_s=batch * ticks / wall, wall_s=wall,
                compile_and_first_s=first, fell=int(np.sum(np.asarray(res.fell))))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, nargs="+", default=[1, 256, 1024])
    p.add_argument("--walk-batch", type=int, default=8)
    p.add_argument("--walk-seconds", type=float, default=1.0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    if any(b < 1 for b in a.batch) or a.walk_batch < 1 or not 0 < a.walk_seconds <= 60 or a.repeats < 1:
        p.error("batches, --walk-batch and --repeats must be >= 1, --walk-seconds in (0, 60]")
    out = dict(device=str(jax.devices()[0]), cpu_count=os.cpu_count(), machine=platform.machine(),
               mpc=[time_mpc(s, b, a.repeats) for s in ("closed-form", "qpax") for b in a.batch],
               wbc_qp="bench/wbc_qp.py (fixed upper body, float32)",
               seed_001_ms=dict(mpc=SEED_001_MPC_MS, qp_fixed_upper_body=SEED_001_QP_FIXED_UPPER_BODY_MS),
               walk=time_walk(a.walk_batch, a.walk_seconds))
    if a.json:
        print(strict_json(out, indent=2))
    else:
        for r in out["mpc"]:
            print(f"MPC {r['solver']:11s} batch {r['batch']:5d}: {r['ms_per_problem']:.4f} ms/problem "
                  f"({r['ratio_to_seed_001']:.2f}x seed 001's 0.2 ms), ok {r['ok_fraction']:.2f}")
        w = out["walk"]
        print(f"closed loop: {w['env_steps_per_s']:.0f} env-steps/s at batch {w['batch']} ({w['fell']} fell)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
