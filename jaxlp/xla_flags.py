"""XLA settings that keep CPU runs from hanging.

On the small CPU machines this project is tested on, XLA's CPU runtime with
its concurrency-optimised thunk scheduler deadlocked at random (all worker
threads idle, the result never ready) on the closed-loop scans of
:mod:`jaxlp.simulate`: 2 hangs in 5 runs of the same program. With the
scheduler off: 0 in 14. :func:`configure_cpu` appends that flag to
``XLA_FLAGS``; it takes effect only if it runs before JAX starts its backend.
This is the one place the flags are set: the packages ``jaxlp``,
``mjx_coman`` and ``sweeps`` call it when they are imported, before any of
their modules, so every entry point (command lines, tests, notebooks,
benchmarks) gets them without importing anything for the side effect.
"""

from __future__ import annotations

import os

CPU_FLAGS = ("--xla_cpu_enable_concurrency_optimized_scheduler=false",)


def configure_cpu() -> str:
    """Append :data:`CPU_FLAGS` to ``XLA_FLAGS`` (unless already there); return the result."""
    flags = os.environ.get("XLA_FLAGS", "")
    for flag in CPU_FLAGS:
        name = flag.split("=")[0]
        if name not in flags:
            flags = f"{flags} {flag}".strip()
    os.environ["XLA_FLAGS"] = flags
    return flags
