"""GPU-sized MJX sweep throughput: closed-loop env steps/s at batches of 1024 to 16384 rollouts, float32.

    python bench/gpu_sweep.py [--batch 1024 2048 4096 8192 16384] [--seconds 0.4]
                              [--controller time-projection] [--repeats 2] [--budget-s 280]
                              [--compile-workers N] [--compile-share 0.6] [--json]

What runs: the sweep's own rollout (``sweeps.models.mjx``: one pushed walk of
COMAN under a registered controller of ``mjx_coman.controllers``), jitted and
vmapped over ``--batch`` rollouts, as ``coman-sweep map --model mjx`` runs a
chunk (and as ``bench/sweep_throughput.py`` timed it up to e8a675d, whose
one-push configuration :func:`sweep_config` repeats). ``--seconds`` is the
walk's length, its start-up phase included, in whole 0.4 s walking steps (at
least one): the default 0.4 s gives the shortest walk, the start-up phase
and one step (0.8 s, 400 ticks, under ``time-projection``); the output gives
the ticks and seconds actually walked.

First every batch is traced and lowered on the main thread, one after the
other, and handed to ``--compile-workers`` background threads that compile
them ahead of time (``jax.jit(...).lower(inputs).compile()``; XLA releases
the GIL while it compiles, so the compiles overlap the later tracing and each
other: five GPU compiles one after another may not fit in 5 minutes). Then,
once every compile is done, the batches are timed one after the other in
ascending order, nothing else running: ``first_run_s`` (the first call),
``run_s`` (best of ``--repeats`` calls, each waited for) and
``env_steps_per_s`` = batch x ticks / ``run_s``; one env step is one 2 ms
control tick of one robot (2 physics steps of 1 ms). Per batch, ``lower_s``
is its tracing and lowering and ``compile_s`` its XLA compile, in its own
thread (with several at once they share the CPUs); ``compile_wall_s`` is the
whole first stage. float32 throughout: JAX's default; x64 is switched off if
the environment turned it on.

Time budget: the whole run (imports included) is meant to end within
``--budget-s`` seconds (280 by default: under 5 minutes with the JSON
printed). Compiles not done by ``--compile-share`` of it (0.6) are
abandoned; before each timed batch the cost of its calls is predicted from
the previous batch's run time scaled by the batch ratio, and a batch that
would not fit is not started. Either way it is reported as
``"status": "skipped"`` with the reason, as are all larger ones. A batch
that runs out of device memory (``JaxRuntimeError`` with
``RESOURCE_EXHAUSTED``) is reported as ``"status": "oom"`` and the larger ones
are skipped; other runtime errors of XLA are reported as ``"error"``.

Nothing needs a GPU: on another backend the script prints a one-line note to
stderr and runs anyway (``--batch 4 8 --seconds 0.1`` is a quick try on CPU).
The XLA flags of the environment are kept (``XLA_FLAGS`` is reported).

MuJoCo Warp: not benchmarked. ``mujoco_warp`` (and ``warp``) are not
installed on the machine this was written on, so no Warp path could be run or
checked; the output says ``"warp": "not installed"`` (or, where it is
installed, that this bench does not use it). Beyond the install, the same
closed loop cannot be switched to Warp from a bench: the installed
``mujoco.mjx`` has ``put_model(..., impl=...)``, but COMAN's sensors and
contact forces (``mjx_coman.sensors``, ``mjx_coman.engines.native``) read the
JAX implementation's ``Data._impl.contact`` and ``_impl.efc_force``, and the
environment builds its model with the default implementation
(``mjx_coman.env``); a Warp engine belongs in ``mjx_coman.engines`` with
those reads ported, and would be timed here as a second sweep.

Prints (``--json``) ``{"env_steps_per_s": {batch: steps/s}, "best_env_steps_per_s", "best_batch",
"compile_s": {batch: s}, "compile_wall_s", "skipped": [batches], "oom": [batches], "device", "backend",
"dtype", "elapsed_s", "warp", ..., "runs": [per batch: status, lower_s, compile_s, first_run_s, run_s,
env_steps_per_s, fell, peak_bytes_in_use, ... or the reason it was skipped]}``.
"""

from __future__ import annotations

import time

T_START = time.perf_counter()  # the budget counts the imports too

from jaxlp.xla_flags import configure_cpu  # noqa: E402

configure_cpu()  # the project's XLA CPU flags, before JAX starts (jaxlp.xla_flags)

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import os  # noqa: E402
import queue  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402

import mjx_coman  # noqa: E402, F401  (imports mujoco.mjx with its stdout notice about Warp swallowed)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from jaxlp.files import strict_json  # noqa: E402
from sweeps.grid import SweepConfig  # noqa: E402
from sweeps.models import RolloutInputs  # noqa: E402
from sweeps.models import mjx as model_mjx  # noqa: E402
from sweeps.runner import rollout_keys  # noqa: E402

DEFAULT_BATCHES = (1024, 2048, 4096, 8192, 16384)
STEP_TIME_S = 0.4


def sweep_config(seconds: float, batch: int, controller: str = "time-projection") -> SweepConfig:
    """A one-push ``mjx`` sweep walking about ``seconds`` in all (the walk adds its start-up phase)."""
    n_steps = max(1, int(round(seconds / STEP_TIME_S)) - 1)
    return SweepConfig(model="mjx", controller=controller, phases=(0.5,), impulses_ns=(2.0,), n_steps=n_steps,
                       push_step=min(1, n_steps - 1), chunk=batch)


def warp_status() -> str:
    """Whether MuJoCo Warp is installed (this bench does not use it: see the module docstring)."""
    if importlib.util.find_spec("mujoco_warp") is None or importlib.util.find_spec("warp") is None:
        return "not installed"
    return "installed, not benchmarked (the closed loop reads MJX's JAX-implementation data; see bench/gpu_sweep.py)"


def batch_inputs(batch: int) -> RolloutInputs:
    """``batch`` pushes spread over phases and impulses, forward, one PRNG key each (as sweep_throughput did)."""
    idx = np.arange(batch, dtype=np.int32)
    return RolloutInputs(index=jnp.asarray(idx), key=jnp.asarray(rollout_keys(0, idx)),
                         phase=jnp.asarray(np.linspace(0.0, 0.9, batch), jnp.float32),
                         impulse_ns=jnp.asarray(np.linspace(0.0, 4.0, batch), jnp.float32),
                         direction_rad=jnp.zeros(batch, jnp.float32))


def is_oom(err: Exception) -> bool:
    text = str(err)
    return "RESOURCE_EXHAUSTED" in text or "out of memory" in text.lower()


def error_record(batch: int, err: Exception) -> dict:
    text = str(err).strip()
    return dict(batch=batch, status="oom" if is_oom(err) else "error",
                error=text.splitlines()[0][:300] if text else type(err).__name__)


def peak_bytes() -> int | None:
    stats = jax.devices()[0].memory_stats()  # None on CPU
    return None if not stats else stats.get("peak_bytes_in_use")


class Compiler:
    """Compiles lowered programs on ``workers`` daemon threads (XLA releases the GIL while it compiles).

    Daemon threads, not a ``concurrent.futures`` pool: a compile that missed the budget is abandoned, not
    waited for at exit (``__main__`` leaves with ``os._exit`` while one still runs).
    """

    def __init__(self, workers: int):
        self.queue: queue.Queue = queue.Queue()
        self.threads = [threading.Thread(target=self._work, daemon=True) for _ in range(workers)]
        for t in self.threads:
            t.start()

    def _work(self):
        while (job := self.queue.get()) is not None:
            if not job["cancelled"]:
                t0 = time.perf_counter()
                try:
                    job["compiled"] = job.pop("lowered").compile()
                except Exception as err:  # noqa: BLE001  (reported per batch)
                    job["error"] = err
                job["compile_s"] = time.perf_counter() - t0
            job["done"].set()

    def submit(self, lowered) -> dict:
        job = dict(lowered=lowered, cancelled=False, done=threading.Event())
        self.queue.put(job)
        return job

    def close(self):
        for _ in self.threads:
            self.queue.put(None)

    def busy(self) -> bool:
        return any(t.is_alive() for t in self.threads)


COMPILER: Compiler | None = None


def time_compiled(compiled, inputs, batch: int, ticks: int, repeats: int) -> dict:
    """The first call and the best of ``repeats`` calls of a compiled batch of rollouts."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(inputs))
    first_s = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(compiled(inputs))
        best = min(best, time.perf_counter() - t0)
    steps = batch * ticks / best
    return dict(first_run_s=first_s, run_s=best, env_steps_per_s=steps, physics_steps_per_s=2 * steps,
                fell=int(np.sum(np.asarray(out.fell))), nan=int(np.sum(np.asarray(out.nan))),
                peak_bytes_in_use=peak_bytes())


def predicted_run_s(prev: dict | None, batch: int, repeats: int) -> float:
    """Seconds the calls of the next batch should take, from the previous batch that ran (0 without one)."""
    return 0.0 if prev is None else (1 + repeats) * prev["run_s"] * batch / prev["batch"]


def sweep(batches, cfg, repeats: int, budget_s: float, workers: int = 1, compile_share: float = 0.6) -> dict:
    """Compile every batch (``workers`` at a time), then time them in ascending order, within the budget."""
    global COMPILER
    model = model_mjx.load()
    ticks = model.ticks_per_rollout(cfg)
    batches = sorted(set(batches))
    compile_deadline = T_START + compile_share * budget_s
    COMPILER = Compiler(workers)
    t_phase = time.perf_counter()
    jobs, stop = {}, None
    for b in batches:  # trace and lower on this thread, one batch at a time; compile in the background
        if stop is None and time.perf_counter() > compile_deadline:
            stop = f"time budget: compiles start before {compile_share:g} of --budget-s {budget_s:g}"
        if stop is not None:
            continue
        t0 = time.perf_counter()
        inputs = batch_inputs(b)
        model.prepare(cfg, inputs)
        try:
            lowered = jax.jit(jax.vmap(lambda i: model.rollout(cfg, i, None))).lower(inputs)
        except jax.errors.JaxRuntimeError as err:  # XlaRuntimeError
            jobs[b] = dict(record=error_record(b, err))
            continue
        jobs[b] = COMPILER.submit(lowered)
        jobs[b].update(inputs=inputs, lower_s=time.perf_counter() - t0)
    COMPILER.close()
    for job in jobs.values():
        if "done" in job:
            job["done"].wait(timeout=max(0.0, compile_deadline - time.perf_counter()))
            job["cancelled"] = not job["done"].is_set()
    compile_wall_s = time.perf_counter() - t_phase

    runs, prev, stop = [], None, None
    for b in batches:
        job = jobs.get(b)
        if stop is None and (job is None or job.get("cancelled")):
            stop = f"time budget: not compiled within {compile_share:g} of --budget-s {budget_s:g}"
        if stop is not None:
            runs.append(dict(batch=b, status="skipped", reason=stop))
            continue
        if "record" in job or "error" in job:
            if "error" in job and not isinstance(job["error"], jax.errors.JaxRuntimeError):
                raise job["error"]  # a bug, not the device's limits
            r = job.get("record") or error_record(b, job["error"])
        else:
            elapsed = time.perf_counter() - T_START
            guess = predicted_run_s(prev, b, repeats)
            if elapsed + guess > budget_s:
                stop = f"time budget: {elapsed:.0f} s spent, batch {b}'s calls predicted at {guess:.0f} s"
                runs.append(dict(batch=b, status="skipped", reason=stop))
                continue
            try:
                r = dict(batch=b, status="ok", lower_s=job["lower_s"], compile_s=job["compile_s"],
                         **time_compiled(job.pop("compiled"), job["inputs"], b, ticks, repeats))
                r["predicted_run_s"] = guess if prev is not None else None
                prev = r
            except jax.errors.JaxRuntimeError as err:
                r = error_record(b, err)
        if r["status"] == "oom":
            stop = f"out of device memory at batch {b}"
        runs.append(r)
        job.pop("inputs", None)
    return dict(runs=runs, ticks=ticks, compile_wall_s=compile_wall_s, compile_workers=workers)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=list(DEFAULT_BATCHES))
    ap.add_argument("--seconds", type=float, default=0.4,
                    help="walk length with its start-up phase, s (whole 0.4 s steps, at least one)")
    ap.add_argument("--controller", default="time-projection", help="a walking controller of mjx_coman.controllers")
    ap.add_argument("--repeats", type=int, default=2, help="timed calls per batch (the best counts)")
    ap.add_argument("--budget-s", type=float, default=280.0,
                    help="whole-run time budget, s: what is predicted to overrun it is skipped")
    ap.add_argument("--compile-workers", type=int, default=None,
                    help="programs compiled at once (default: the batches, at most half the CPUs)")
    ap.add_argument("--compile-share", type=float, default=0.6,
                    help="share of the budget by which every compile must be done")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    workers = args.compile_workers or max(1, min(len(set(args.batch)), (os.cpu_count() or 1) // 2))
    if min(args.batch) < 1 or args.seconds <= 0 or args.repeats < 1 or args.budget_s < 0 or workers < 1:
        ap.error("--batch, --seconds, --repeats and --compile-workers must be positive, --budget-s non-negative")
    if not 0 < args.compile_share <= 1:
        ap.error("--compile-share must be in (0, 1]")
    if args.controller not in model_mjx.controller_names():
        ap.error(f"--controller {args.controller!r} is not one of {', '.join(model_mjx.controller_names())}")
    if jax.config.jax_enable_x64:  # only when the environment asked for it (toggling it in a process costs)
        jax.config.update("jax_enable_x64", False)
    backend = jax.default_backend()
    if backend != "gpu":
        print(f"gpu_sweep: backend is {backend}, not gpu: running anyway (a quick try: --batch 4 8 --seconds 0.1)",
              file=sys.stderr)

    cfg = sweep_config(args.seconds, 1, args.controller).compiled_part()
    res = sweep(args.batch, cfg, args.repeats, args.budget_s, workers, args.compile_share)
    runs = res["runs"]
    ok = [r for r in runs if r["status"] == "ok"]
    best = max(ok, key=lambda r: r["env_steps_per_s"], default=None)
    dev = jax.devices()[0]
    out = dict(
        env_steps_per_s={str(r["batch"]): round(r["env_steps_per_s"], 1) for r in ok},
        best_env_steps_per_s=None if best is None else round(best["env_steps_per_s"], 1),
        best_batch=None if best is None else best["batch"],
        compile_s={str(r["batch"]): round(r["compile_s"], 2) for r in ok},
        compile_wall_s=round(res["compile_wall_s"], 2), compile_workers=res["compile_workers"],
        skipped=[r["batch"] for r in runs if r["status"] == "skipped"],
        oom=[r["batch"] for r in runs if r["status"] == "oom"],
        device=dev.device_kind, device_id=str(dev), device_count=jax.device_count(), backend=backend,
        dtype=str(jnp.zeros(()).dtype), x64=bool(jax.config.jax_enable_x64),
        controller=args.controller, ticks_per_rollout=res["ticks"], walk_s=res["ticks"] * model_mjx.env_step_s(cfg),
        env_step="one 2 ms control tick of one robot (2 physics steps of 1 ms)",
        repeats=args.repeats, budget_s=args.budget_s, elapsed_s=round(time.perf_counter() - T_START, 1),
        warp=warp_status(), engine=f"MJX (JAX implementation), mujoco {mujoco.__version__}",
        versions=dict(jax=jax.__version__, mujoco=mujoco.__version__, numpy=np.__version__),
        xla_flags=os.environ.get("XLA_FLAGS", ""), cpu_count=os.cpu_count(),
        runs=runs,
    )
    if args.json:
        print(strict_json(out, indent=1))
        return 0
    print(f"MJX sweep rollouts, {args.controller}, {res['ticks']} ticks ({out['walk_s']:.2f} s), {out['dtype']}, "
          f"{out['device']} ({backend})")
    for r in runs:
        if r["status"] == "ok":
            print(f"batch {r['batch']:6d}: {r['env_steps_per_s']:14.0f} env steps/s  run {r['run_s']:.3f} s  "
                  f"compile {r['compile_s']:.1f} s")
        else:
            print(f"batch {r['batch']:6d}: {r['status']}: {r.get('reason') or r.get('error')}")
    print(f"compiles {out['compile_wall_s']:.0f} s ({workers} at a time); elapsed {out['elapsed_s']:.0f} s "
          f"of a {args.budget_s:g} s budget; Warp: {out['warp']}")
    return 0


if __name__ == "__main__":
    rc = main()
    if COMPILER is not None and COMPILER.busy():  # a compile abandoned at the budget: do not wait for it
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)
    raise SystemExit(rc)
