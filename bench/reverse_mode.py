"""What reverse mode through MJX costs in accuracy: one constraint-solver iteration against the model's own.

    python bench/reverse_mode.py [--seconds 3] [--grad] [--json]

``jax.grad`` through a rollout needs MJX's solver at ``opt.iterations == 1`` (no ``lax.while_loop``:
:func:`mjx_coman.env.solver_iterations`). This runs the same walks (same keys, same pushes) at the
model's 4 iterations and at 1, and prints per controller the RMS and largest difference of the pelvis
and CoM trajectories, the final CoM difference, and whether each fell. Walks: ``wbc-stand`` pushed
forward (3 N s at 0.5 s) and ``time-projection`` walking in place, pushed backward (3 N s in its 3rd step).

``--grad`` also times the gradient of a pushed 0.3 s ``wbc-stand`` walk's CoM sway with respect to the
CoM stiffness, reverse mode (checkpointed) against forward mode: compile and run seconds, and XLA's
temporary memory of each compiled gradient (``memory_analysis``).
"""

from __future__ import annotations

import argparse
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.files import strict_json
from mjx_coman import controllers
from mjx_coman import rollout as ro
from mjx_coman.env import solver_iterations

WALKS = {  # controller: (push start s, impulse N s, direction rad)
    "wbc-stand": (0.5, 3.0, 0.0),
    "time-projection": (None, 3.0, np.pi),
}


def _walk(name: str, seconds: float, iterations: int | None):
    ctrl, cfg = controllers.load(name, {})
    g = ctrl.gait(cfg)
    env = ro.plant_env_params(g.plant)
    if iterations is not None:
        env = solver_iterations(env, iterations)
    start, imp, ang = WALKS[name]
    start = g.first_step_s + 2.3 * g.step_time_s if start is None else start
    push = ro.make_push(start, 0.1, impulse_ns=imp, direction_rad=ang)
    fn = ro.jit_walk(ctrl, ro.WalkSpec(seconds=seconds), ro.SaveAt(ro.pelvis_and_com, every=5))
    t0 = time.perf_counter()
    r = jax.tree_util.tree_map(np.asarray, fn(cfg, env, push, jax.random.PRNGKey(0), controllers.joystick(0.0)))
    return r, time.perf_counter() - t0


def accuracy(seconds: float) -> dict:
    out = {}
    for name in WALKS:
        (a, ta), (b, tb) = _walk(name, seconds, None), _walk(name, seconds, 1)
        n = len(a.time_s)
        if a.fell or b.fell:
            n = int(np.sum(a.time_s <= min(a.fall_time_s, b.fall_time_s)))
        row = {"fell_default": bool(a.fell), "fell_one_iteration": bool(b.fell), "compared_s": float(a.time_s[n - 1])}
        for key in ("pelvis_m", "com_m"):
            d = np.linalg.norm(a.saved[key][:n] - b.saved[key][:n], axis=-1)
            row[f"{key[:-2]}_rms_diff_m"] = float(np.sqrt(np.mean(d ** 2)))
            row[f"{key[:-2]}_max_diff_m"] = float(d.max())
        row["final_com_diff_m"] = float(np.linalg.norm(a.saved["com_m"][n - 1] - b.saved["com_m"][n - 1]))
        row["touchdowns"] = [int(a.touchdowns), int(b.touchdowns)]
        row["wall_s_incl_compile"] = [round(ta, 1), round(tb, 1)]
        out[name] = row
    return out


def gradients() -> dict:
    ctrl, cfg = controllers.load("wbc-stand", {})
    env = solver_iterations(ro.plant_env_params("torque-ideal"), 1)
    push = ro.make_push(0.02, 0.1, impulse_ns=3.0)
    save = ro.SaveAt(ro.pelvis_and_com, every=10)

    def sway(kp, spec):
        r = ro.walk(ctrl.core(), cfg.replace(com_kp_per_s2=kp), env, push, jax.random.PRNGKey(0), spec, None, save)
        x = r.saved["com_m"][:, 0]
        return jnp.mean((x - x[0]) ** 2) * 1e4

    spec = ro.WalkSpec(seconds=0.3, checkpoint=True)
    fns = {"reverse": jax.grad(lambda k: sway(k, spec)),
           "forward": lambda k: jax.jvp(lambda k: sway(k, spec), (k,), (jnp.ones_like(k),))[1]}
    out = {}
    for mode, fn in fns.items():
        t0 = time.perf_counter()
        compiled = jax.jit(fn).lower(cfg.com_kp_per_s2).compile()
        t1 = time.perf_counter()
        val = float(compiled(cfg.com_kp_per_s2))
        t2 = time.perf_counter()
        mem = compiled.memory_analysis()
        out[mode] = {"d_sway_d_com_kp": val, "compile_s": round(t1 - t0, 1), "run_s": round(t2 - t1, 2),
                     "temp_bytes": None if mem is None else int(mem.temp_size_in_bytes)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="length of each walk, s")
    ap.add_argument("--grad", action="store_true", help="also time reverse against forward mode (minutes)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args(argv)
    if not (np.isfinite(args.seconds) and 0.5 <= args.seconds <= 60):
        ap.error(f"--seconds {args.seconds} must lie in [0.5, 60]")
    out = {"machine": platform.processor() or platform.machine(), "backend": jax.default_backend(),
           "dtype": str(jnp.result_type(float)), "seconds": args.seconds, "accuracy": accuracy(args.seconds)}
    if args.grad:
        out["gradient"] = gradients()
    if args.json:
        print(strict_json(out, indent=2))
    else:
        for name, row in out["accuracy"].items():
            print(name, row)
        for mode, row in out.get("gradient", {}).items():
            print(mode, row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
