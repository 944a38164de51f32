"""Batching of the QP's dense linear algebra: a loop on CPU, a vmap elsewhere."""

from __future__ import annotations

import jax


def per_problem(fn):
    """``fn`` batched as a loop over the problems on CPU (``jax.custom_batching.sequential_vmap``), as a
    ``vmap`` elsewhere.

    jaxlib 0.10.2 spreads a batched CPU LAPACK call (``potrf``, ``trsm``) over the intra-op thread pool
    and blocks its own pool thread until the pieces finish (``ParallelBatchMap`` -> ``BlockingCounter::Wait``);
    when the thunk executor runs as many such calls at once as the pool has threads (2 on this machine),
    every thread waits and the program hangs. Measured here: a vmapped qpax solve of 256 or 1024 QPs hung
    within one to three calls (gdb: both Eigen threads in ``ParallelBatchMap`` under ``lapack_dtrsm_ffi``).
    A loop issues one unbatched call at a time and is as fast on CPU (measured, bench/wbc_qp.py).
    """
    if jax.default_backend() != "cpu":
        return fn
    return jax.custom_batching.sequential_vmap(fn)
