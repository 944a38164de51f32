"""Closed-loop environment steps per second: MJX, the native engine, the peer, and the physics alone.

    python bench/sweep_throughput.py [--batch 64 256 1024] [--seconds 0.8] [--repeats 1] [--no-twin] [--json]

Every closed loop runs the same walks: :func:`mjx_coman.rollout.batched_walk` of the registered
``time-projection`` controller on its plant (jitted once per engine and batch, vmapped over the batch), each
robot pushed forward with its own impulse (0-4 N s) and timing. Compilation is timed apart (``first_call_s``);
the best of ``--repeats`` timed calls counts.

* ``mjx_steps_per_s``: physics in MuJoCo MJX, by batch;
* ``native_steps_per_s``: physics in MuJoCo C (:mod:`mjx_coman.engines.native`) on every core, by batch, and on
  one thread at the largest batch (``native_1_thread_steps_per_s``);
* ``peer_steps_per_s``: what a user writes without this tool: one robot at a time, ``mj_step`` and the same
  jitted controller once per tick, one thread (the native engine at batch 1 on one thread; its two host
  callbacks a tick cost ``callback_overhead_us`` each, measured apart);
* ``physics_only_steps_per_s``: MuJoCo C replaying a walk's recorded link torques (each held over its tick's
  2 physics steps), no controller, motors or sensors, one thread and all threads (best of 3): the limit no
  closed loop beats;
* ``numpy_twin_steps_per_s`` (unless ``--no-twin``): the former peer, the controller's own source executed by
  NumPy (``bench/numpy_twin_loop.py``), one robot: what a line-by-line NumPy port costs.

The ratios: the best closed loop against the peer and against the all-threads physics-only limit.
One environment step = one 2 ms control tick of one robot (2 physics steps of 1 ms).
"""

from __future__ import annotations

from jaxlp.xla_flags import configure_cpu

configure_cpu()  # the project's XLA CPU flags, before JAX starts (jaxlp.xla_flags)

import argparse  # noqa: E402
import concurrent.futures  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from jaxlp.files import strict_json  # noqa: E402
from mjx_coman import controllers, env as env_mod, rollout as ro  # noqa: E402
from mjx_coman.engines.native import default_threads  # noqa: E402

CONTROLLER = "time-projection"


def link_torque(state):
    """A save function: the link torques of the tick's last physics step."""
    return state.env.data.ctrl


def _walk_inputs(batch: int, seconds: float):
    ctrl, cfg = controllers.load(CONTROLLER)
    g = ctrl.gait(cfg)
    start = g.first_step_s + (1.0 + np.linspace(0.0, 0.9, batch)) * g.step_time_s
    force = np.zeros((batch, 3), np.float32)
    force[:, 0] = np.linspace(0.0, 40.0, batch)
    push = ro.Push(start_s=jnp.asarray(start, jnp.float32), duration_s=jnp.full(batch, 0.1, jnp.float32),
                   force_n=jnp.asarray(force))
    keys = jax.random.split(jax.random.key(0), batch)
    return ctrl, cfg, g, push, keys, ro.WalkSpec(seconds=seconds)


def env_for(engine: str, threads: int | None = None):
    ctrl, cfg = controllers.load(CONTROLLER)
    env = ro.plant_env_params(ctrl.gait(cfg).plant)
    return env if engine == "mjx" else env_mod.use_engine(env, "native", n_threads=threads)


def closed_loop(engine: str, batch: int, seconds: float, repeats: int, threads: int | None = None) -> dict:
    """Env steps/s of ``batch`` walks on ``engine`` (compilation apart)."""
    ctrl, cfg, g, push, keys, spec = _walk_inputs(batch, seconds)
    env = env_for(engine, threads)
    fn = ro.batched_walk(ctrl, spec)
    joy = controllers.joystick(0.0)
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(cfg, env, push, keys, joy))
    first = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(cfg, env, push, keys, joy))
        best = min(best, time.perf_counter() - t0)
    ticks = ro.n_ticks(spec, g.control_period_s)
    return dict(engine=engine, threads=None if engine == "mjx" else env.engine.n_threads, batch=batch, ticks=ticks,
                first_call_s=first, seconds=best, env_steps_per_s=batch * ticks / best,
                fell=int(np.sum(np.asarray(out.fell))))


def callback_overhead_us(n: int = 2000) -> float:
    """Time of one ``jax.pure_callback`` returning its input (one packed array of the engine's size) in a
    jitted scan, us."""
    size = 1000

    def body(c, _):
        return jax.pure_callback(lambda x: np.asarray(x), jax.ShapeDtypeStruct(c.shape, c.dtype), c,
                                 vmap_method="broadcast_all"), None

    f = jax.jit(lambda c: jax.lax.scan(body, c, None, length=n)[0])
    x = jnp.zeros(size)
    jax.block_until_ready(f(x))
    t0 = time.perf_counter()
    jax.block_until_ready(f(x))
    return (time.perf_counter() - t0) / n * 1e6


def recorded_torques(seconds: float) -> np.ndarray:
    """(ticks, nu) link torques of one unpushed walk (native engine, one thread)."""
    ctrl, cfg, g, push, keys, spec = _walk_inputs(1, seconds)
    fn = ro.jit_walk(ctrl, spec, ro.SaveAt(link_torque, 1))
    r = fn(cfg, env_for("native", 1), ro.no_push(), keys[0], controllers.joystick(0.0))
    return np.asarray(r.saved, np.float64)


def physics_only(torques: np.ndarray, robots: int, threads: int) -> float:
    """Env steps/s of ``robots`` robots replaying ``torques`` in MuJoCo C on ``threads`` threads."""
    from mjx_coman.env import standing_posture

    env = env_for("native", 1)
    m = env.engine.mj_model
    q0, root = standing_posture()
    n_sub = int(env.n_substeps)

    def replay(count: int) -> None:
        d = mujoco.MjData(m)
        for _ in range(count):
            mujoco.mj_resetData(m, d)
            d.qpos[:7], d.qpos[7:] = root, q0
            for tau in torques:
                d.ctrl[:] = tau
                for _ in range(n_sub):
                    mujoco.mj_step(m, d)

    parts = [robots * (k + 1) // threads - robots * k // threads for k in range(threads)]
    best = float("inf")
    with concurrent.futures.ThreadPoolExecutor(threads) as pool:
        for _ in range(3):  # best of 3: one replay lasts about a second
            t0 = time.perf_counter()
            list(pool.map(replay, parts))
            best = min(best, time.perf_counter() - t0)
    return robots * len(torques) / best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--seconds", type=float, default=0.8, help="walk length, s")
    ap.add_argument("--peer-seconds", type=float, default=2.0, help="walk length of the peer and the replay, s")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--no-twin", action="store_true", help="skip the NumPy-twin loop")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if min(args.batch) < 1 or args.seconds <= 0 or args.peer_seconds <= 0 or args.repeats < 1:
        ap.error(f"--batch, --seconds, --peer-seconds and --repeats must be positive, got {args.batch}, "
                 f"{args.seconds}, {args.peer_seconds}, {args.repeats}")
    cores = default_threads()
    mjx_runs = [closed_loop("mjx", b, args.seconds, args.repeats) for b in args.batch]
    native_runs = [closed_loop("native", b, args.seconds, args.repeats) for b in args.batch]
    native_1 = closed_loop("native", max(args.batch), args.seconds, args.repeats, threads=1)
    peer = closed_loop("native", 1, args.peer_seconds, max(args.repeats, 3), threads=1)  # short: best of 3
    torques = recorded_torques(args.peer_seconds)
    robots = max(8 * cores, 16)
    phys = {"1": physics_only(torques, robots, 1), str(cores): physics_only(torques, robots, cores)}
    twin = None
    if not args.no_twin:
        import numpy_twin_loop  # noqa: E402  (bench/: run as python bench/sweep_throughput.py)

        twin = numpy_twin_loop.twin_throughput(args.peer_seconds, args.repeats)
    best_run = max(mjx_runs + native_runs + [native_1], key=lambda r: r["env_steps_per_s"])
    best = best_run["env_steps_per_s"]
    by_batch = lambda runs: {str(r["batch"]): round(r["env_steps_per_s"], 1) for r in runs}  # noqa: E731
    out = dict(
        mjx_steps_per_s=by_batch(mjx_runs),
        native_steps_per_s=by_batch(native_runs),
        native_1_thread_steps_per_s={str(native_1["batch"]): round(native_1["env_steps_per_s"], 1)},
        peer_steps_per_s=round(peer["env_steps_per_s"], 1),
        physics_only_steps_per_s={k: round(v, 1) for k, v in phys.items()},
        numpy_twin_steps_per_s=None if twin is None else round(twin["env_steps_per_s"], 1),
        best=dict(engine=best_run["engine"], threads=best_run["threads"], batch=best_run["batch"],
                  env_steps_per_s=round(best, 1)),
        ratio_best_to_peer=round(best / peer["env_steps_per_s"], 3),
        ratio_best_to_physics_only_all_threads=round(best / phys[str(cores)], 3),
        ratio_native_to_mjx={str(a["batch"]): round(b["env_steps_per_s"] / a["env_steps_per_s"], 3)
                             for a, b in zip(mjx_runs, native_runs)},
        callback_overhead_us=round(callback_overhead_us(), 1),
        threads=cores, controller=CONTROLLER,
        env_step="one 2 ms control tick of one robot (2 physics steps of 1 ms)",
        backend=f"JAX {jax.__version__} {jax.default_backend()}", device=str(jax.devices()[0]),
        machine=platform.machine(), mujoco=mujoco.__version__,
        runs=dict(mjx=mjx_runs, native=native_runs, native_1_thread=native_1, peer=peer, numpy_twin=twin),
    )
    if args.json:
        print(strict_json(out, indent=1))
    else:
        for name in ("mjx_steps_per_s", "native_steps_per_s", "native_1_thread_steps_per_s", "peer_steps_per_s",
                     "physics_only_steps_per_s", "numpy_twin_steps_per_s", "ratio_best_to_peer",
                     "ratio_best_to_physics_only_all_threads"):
            print(f"{name}: {out[name]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
