"""Host constants computed by one jitted program, even when first asked for inside a trace."""

from __future__ import annotations

import concurrent.futures

import jax
import numpy as np


def host_eval(fn, *args):
    """``jax.jit(fn)(*args)`` of concrete ``args`` as NumPy arrays (a pytree of them).

    Runs in a thread of its own, in the caller's float width: a caller's trace and a
    ``jax.ensure_compile_time_eval`` context are thread-local, so neither reaches it. Called from inside a
    trace, ``jax.jit`` alone would stage the program into that trace (no concrete result); under
    ``ensure_compile_time_eval`` it would be traced op by op, each small op compiled on its own (a few
    seconds for a 3LP plan, against one compilation).
    """
    x64 = bool(jax.config.jax_enable_x64)

    def run():
        with jax.enable_x64(x64):
            return jax.tree_util.tree_map(np.asarray, jax.jit(fn)(*args))

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(run).result()
