"""Several sweeps at once, one worker process each (``coman-sweep compare``, held-out validation).

On a CPU an MJX sweep runs on one host device unless ``XLA_FLAGS`` asks for more (several host devices need
the larger intra-op pool that :mod:`jaxlp.xla_flags` sets), and its whole-body QPs loop over the problems, so
one core does most of the work while the others idle. Separate processes put every core to use: each worker
runs :func:`sweeps.runner.run_sweep` into its own folder, so a killed run resumes as a serial one does, and
the results do not depend on the number of workers.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import NamedTuple


class SweepJob(NamedTuple):
    """One sweep to run: its configuration, folder and progress-bar label."""

    config: object  # sweeps.grid.SweepConfig
    out_dir: Path
    desc: str


def cpu_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def default_workers(n_jobs: int) -> int:
    """One worker per core (at most one per sweep) on a single-process CPU backend; else 1: an accelerator runs
    the sweeps in turn (they would share its memory), and so does ``jax.distributed``."""
    import jax

    if jax.process_count() > 1 or jax.default_backend() != "cpu":
        return 1
    return max(1, min(n_jobs, cpu_cores()))


def _run_one(job: SweepJob, resume: bool, force: bool, progress: bool, position: int | None):
    from sweeps.runner import run_sweep

    return run_sweep(job.config, job.out_dir, resume=resume, force=force, progress=progress, desc=job.desc,
                     position=position)


def run_sweeps(jobs: list[SweepJob], *, workers: int = 1, resume: bool = False, force: bool = False,
               progress: bool = True, on_done=None, cost=None) -> list:
    """Run every job; return their :class:`sweeps.runner.SweepRun` in the order of ``jobs``.

    Args:
        workers: processes at once (1: in this process, one after the other).
        cost: an estimate of each job's work (e.g. env steps): with several workers the costliest start first,
            so that a long one does not start last while the other workers idle.
        on_done: called as ``on_done(index, run)`` in this process as each sweep finishes.

    Raises:
        what :func:`sweeps.runner.run_sweep` raises, from the first job that raised it (the other workers finish
        the sweep they are in first; their chunks are kept).
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    runs: dict[int, object] = {}
    if workers == 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            runs[i] = _run_one(job, resume, force, progress, None)
            if on_done is not None:
                on_done(i, runs[i])
        return [runs[i] for i in range(len(jobs))]
    todo = list(enumerate(jobs))
    if cost is not None:
        todo.sort(key=lambda t: -cost[t[0]])
    free = list(range(min(workers, len(jobs))))  # progress-bar rows
    running = {}
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no forked JAX runtime
    with ProcessPoolExecutor(max_workers=len(free), mp_context=ctx) as pool:
        try:
            while todo or running:
                while todo and free:
                    i, job = todo.pop(0)
                    slot = free.pop(0)
                    running[pool.submit(_run_one, job, resume, force, progress, slot)] = (i, slot)
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in finished:
                    i, slot = running.pop(fut)
                    free.append(slot)
                    runs[i] = fut.result()
                    if on_done is not None:
                        on_done(i, runs[i])
        except BaseException:
            todo.clear()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return [runs[i] for i in range(len(jobs))]
