"""XLA settings that keep CPU runs from hanging.

On the small CPU machines this project is tested on, XLA's CPU runtime with
its concurrency-optimised thunk scheduler deadlocked at random (all worker
threads idle, the result never ready) on the closed-loop scans of
:mod:`jaxlp.simulate`: 2 hangs in 5 runs of the same program. With the
scheduler off: 0 in 14. :func:`configure_cpu` appends that flag to
``XLA_FLAGS``; it takes effect only if it runs before JAX starts its backend.

Several host devices (``--xla_force_host_platform_device_count=N``) share one
intra-op thread pool of ``max(cores, N)`` threads. jaxlib 0.10.2's batched
LAPACK kernels (Cholesky, triangular solve, LU, ...; MJX factors its mass
matrix and its Newton solver's Hessian with them) split a large enough batch
into pieces queued on that pool and block their own thread until the pieces
are done. When each of the N device programs runs such a call on a pool
thread at once and the pool has no more than N threads, every thread waits
and none runs the pieces: the program hangs with all threads idle.
:func:`configure_cpu` therefore sizes the pool (``PJRT_NPROC``, read by XLA's
CPU client when it starts) to ``cores + N`` whenever there are several host
devices: N threads may block, the others still do the work.

This is the one place the flags are set: the packages ``jaxlp``,
``mjx_coman`` and ``sweeps`` call it when they are imported, before any of
their modules, so every entry point (command lines, tests, notebooks,
benchmarks) gets them without importing anything for the side effect.
"""

from __future__ import annotations

import os
import re

CPU_FLAGS = ("--xla_cpu_enable_concurrency_optimized_scheduler=false",)
POOL_ENV = "PJRT_NPROC"  # XLA's CPU client: threads of its intra-op pool (then NPROC, then the cores)
_DEVICE_COUNT_FLAG = re.compile(r"--xla_force_host_platform_device_count=(\d+)")


def cpu_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def host_device_count(flags: str | None = None) -> int:
    """The CPU devices JAX will make: ``JAX_NUM_CPU_DEVICES`` if set, else the last
    ``--xla_force_host_platform_device_count`` in ``flags`` (default ``XLA_FLAGS``), else 1."""
    env = os.environ.get("JAX_NUM_CPU_DEVICES", "").strip()
    if env.lstrip("-").isdigit() and int(env) >= 0:
        return max(1, int(env))
    counts = _DEVICE_COUNT_FLAG.findall(os.environ.get("XLA_FLAGS", "") if flags is None else flags)
    return max(1, int(counts[-1])) if counts else 1


def intra_op_pool_size(n_devices: int, cores: int | None = None) -> int:
    """Threads the intra-op pool needs so that ``n_devices`` programs, each blocked in a batched LAPACK call,
    still leave a thread per core to run the pieces they wait for."""
    return (cpu_cores() if cores is None else cores) + n_devices


def configure_cpu() -> str:
    """Append :data:`CPU_FLAGS` to ``XLA_FLAGS`` (unless already there) and, with several host devices, raise
    ``PJRT_NPROC`` to at least :func:`intra_op_pool_size`; return ``XLA_FLAGS``."""
    flags = os.environ.get("XLA_FLAGS", "")
    for flag in CPU_FLAGS:
        name = flag.split("=")[0]
        if name not in flags:
            flags = f"{flags} {flag}".strip()
    os.environ["XLA_FLAGS"] = flags
    n_devices = host_device_count(flags)
    if n_devices > 1:
        current = next((os.environ[k] for k in (POOL_ENV, "NPROC") if os.environ.get(k, "").isdigit()), "")
        need = intra_op_pool_size(n_devices)
        if not current or int(current) < need:  # a larger pool asked for is kept
            os.environ[POOL_ENV] = str(need)
    return flags
