"""Run a sweep: jit + vmap over fixed-size chunks, sharded over every device, resumable.

Each chunk of ``config.chunk`` rollouts (the last one padded, so every call
has the same shapes and compiles once) is padded to a multiple of the device
count and laid out as a global array over ``Mesh(jax.devices(), ("batch",))``
with ``PartitionSpec("batch")``: each device runs its slice of the chunk in one
jitted ``vmap`` of the model's rollout. The few scalars a rollout returns are
gathered to the host (across processes with ``process_allgather``). Several
CPU host devices run their slices at once in one shared intra-op thread pool,
which :mod:`jaxlp.xla_flags` sizes so that a batched LAPACK call (MJX's
Cholesky factorisations) waiting on every device still leaves threads to run
the pieces they wait for.

Each finished chunk is written atomically (temporary file in the same folder,
then ``os.replace``) under ``OUT/chunks/``. ``OUT/config.json`` holds the
configuration and its hash. A rerun of the same sweep keeps every readable
finished chunk (results are deterministic, so nothing is lost or mixed); an
unreadable one (a truncated or corrupt file) is recomputed, with one line
on stderr. A folder holding a different sweep's finished work is refused
unless ``force=True``; one holding only the ``config.json`` of a run that
died before its first chunk is taken over. Ctrl-C raises
:class:`SweepInterrupted` with the chunks finished so far (kept on disk).

Several processes (``jax.distributed``, one per host): every process runs this
same function with the same configuration. ``jax.devices()`` is then the
global device list, so the mesh spans every host and each chunk is one SPMD
call in which each process feeds the rows of its own devices
(``jax.make_array_from_callback``). Only process 0 touches ``OUT``: it checks
and prepares the folder, decides which chunks are left (broadcast to the
others), writes the chunk files and, in :mod:`sweeps.cli`, the results. Other
processes return ``results=None``.
"""

from __future__ import annotations

import functools
import json
import math
import os
import shutil
import sys
import time
import zipfile
from pathlib import Path
from typing import Callable, NamedTuple

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxlp.files import save_npz_atomic, save_text_atomic, strict_json
from sweeps.grid import SweepConfig, grid_inputs, scenario_columns
from sweeps.models import RolloutInputs, check, get_model

CHUNK_DIR = "chunks"
RESULT_FILES = ("results.npz", "results.csv", "basin.png", "summary.json")
DELAY_ENV = "COMAN_SWEEP_CHUNK_DELAY_S"  # tests only: sleep after each chunk, to kill a run mid-sweep
_FN_CACHE: dict = {}


class SweepConflict(RuntimeError):
    """The output folder holds a different sweep (the command line exits 2)."""


class SweepInterrupted(Exception):
    """Ctrl-C during a sweep; ``done`` of ``total`` chunks are finished in ``out_dir`` and kept."""

    def __init__(self, out_dir: Path, done: int, total: int):
        super().__init__(f"after {done} of {total} chunks in {out_dir}; "
                         "rerun the same command to finish (finished chunks are kept)")
        self.out_dir, self.done, self.total = out_dir, done, total

    def __reduce__(self):  # back from a worker process (sweeps.parallel)
        return SweepInterrupted, (self.out_dir, self.done, self.total)


class SweepRun(NamedTuple):
    """A finished sweep.

    Attributes:
        config: the configuration.
        results: per-rollout arrays (inputs, outputs, ``reason``), each (n,); ``None`` on processes other than 0.
        timing: wall, first-chunk (compile) and run seconds, rollouts and env steps per second, devices, chunks.
    """

    config: SweepConfig
    results: dict | None
    timing: dict


def stored_hash(out_dir: Path) -> str | None:
    """The config hash recorded in ``out_dir/config.json`` (``None``: none or unreadable)."""
    try:
        return json.loads((Path(out_dir) / "config.json").read_text()).get("hash")
    except (OSError, ValueError, AttributeError):
        return None


def _finished_work(out_dir: Path) -> bool:
    chunk_dir = out_dir / CHUNK_DIR
    return any(chunk_dir.glob("chunk_*.npz")) or any((out_dir / n).exists() for n in RESULT_FILES)


def prepare_out_dir(out_dir: Path, config: SweepConfig, *, resume: bool = True, force: bool) -> Path:
    """Create or check ``out_dir`` for ``config``; return its chunk folder.

    The same sweep keeps its finished chunks (``resume`` is accepted for the
    command line's ``--resume`` and changes nothing: results are
    deterministic). A different sweep's finished work (or results with no
    ``config.json``) is refused unless ``force``, which wipes it; a
    ``config.json`` with no finished work (a run that died before its first
    chunk) is replaced.

    Raises:
        SweepConflict: ``out_dir`` holds a different sweep's finished work and ``force`` is off.
    """
    del resume
    out_dir = Path(out_dir)
    chunk_dir = out_dir / CHUNK_DIR
    known = (out_dir / "config.json").exists()
    old = stored_hash(out_dir) if known else None
    fresh = old != config.hash()  # another sweep's folder, or an unknown one: replaced once allowed
    if fresh and _finished_work(out_dir) and not force:
        raise SweepConflict(f"{out_dir} holds a different sweep (config hash {old} != {config.hash()}); "
                            "use --force to overwrite it or another --out" if known else
                            f"{out_dir} holds results of an unknown sweep (no config.json); "
                            "use --force to overwrite them or another --out")
    out_dir.mkdir(parents=True, exist_ok=True)
    if fresh:
        shutil.rmtree(chunk_dir, ignore_errors=True)
        for name in RESULT_FILES:
            (out_dir / name).unlink(missing_ok=True)
    chunk_dir.mkdir(exist_ok=True)
    save_text_atomic(out_dir / "config.json", strict_json({"hash": config.hash(), "config": config.to_dict()}))
    return chunk_dir


def read_chunk(path: Path) -> dict | None:
    """A chunk file's arrays, or ``None`` when it is missing or not whole: every array is read (the zip
    checks its CRCs) and ``lo < hi``."""
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        return arrays if int(arrays["lo"]) < int(arrays["hi"]) else None
    except (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile):
        return None


def _finished_chunks(chunk_dir: Path, n_chunks: int) -> dict[int, dict]:
    """The finished chunks' arrays by index, each file read once; an unreadable chunk file is removed (to be
    recomputed), with one line."""
    done = {}
    for i in range(n_chunks):
        path = chunk_path(chunk_dir, i)
        arrays = read_chunk(path)
        if arrays is not None:
            done[i] = arrays
        elif path.exists():
            print(f"{path}: unreadable (truncated or corrupt): recomputing it", file=sys.stderr)
            path.unlink()
    return done


def chunk_path(chunk_dir: Path, i: int) -> Path:
    """The file of chunk ``i``."""
    return Path(chunk_dir) / f"chunk_{i:05d}.npz"


def sweep_devices(config: SweepConfig) -> tuple:
    """The devices a sweep's chunks are laid out over: every device, or the first alone for the native
    engine (its physics runs on the host's threads, from one callback per step)."""
    devices = tuple(jax.devices())
    return devices[:1] if config.engine == "native" else devices


def _chunk_fn(config: SweepConfig, rollout: Callable, devices: tuple):
    """The jitted, sharded batch rollout of a chunk (cached per configuration and devices)."""
    key = (config, rollout, devices)
    if key not in _FN_CACHE:
        mesh = Mesh(np.asarray(devices), ("batch",))
        batch = NamedSharding(mesh, PartitionSpec("batch"))
        # Outputs stay sharded: no collective inside the call (on a small CPU the 4 host-platform
        # "devices" share 2 cores and an in-call all-gather was seen to deadlock).
        fn = jax.jit(jax.vmap(lambda inp, aux: rollout(config, inp, aux)), in_shardings=batch,
                     out_shardings=batch)
        _FN_CACHE[key] = (fn, batch)
    return _FN_CACHE[key]


def _pad(x: np.ndarray, size: int) -> np.ndarray:
    """Pad the first axis to ``size`` by repeating the first row (valid inputs, discarded)."""
    if len(x) == size:
        return x
    return np.concatenate([x, np.repeat(x[:1], size - len(x), axis=0)])


@functools.partial(jax.jit, static_argnums=0)
def _rollout_keys(seed: int, index):
    base = jax.random.PRNGKey(seed)
    return jax.vmap(lambda i: jax.random.key_data(jax.random.fold_in(base, i)))(index)


def rollout_keys(seed: int, index: np.ndarray) -> np.ndarray:
    """Per-rollout PRNG key data ``key_data(fold_in(PRNGKey(seed), index))``, uint32 (n, 2)."""
    return np.asarray(_rollout_keys(int(seed), np.asarray(index, np.int32)))


def _chunk_inputs(inputs, keys, lo: int, hi: int, padded: int, float_dtype) -> RolloutInputs:
    return RolloutInputs(
        index=_pad(inputs.index[lo:hi], padded).astype(np.int32),
        key=_pad(keys[lo:hi], padded),
        phase=_pad(inputs.phase[lo:hi], padded).astype(float_dtype),
        impulse_ns=_pad(inputs.impulse_ns[lo:hi], padded).astype(float_dtype),
        direction_rad=_pad(inputs.direction_rad[lo:hi], padded).astype(float_dtype),
    )


def _global(x: np.ndarray, sharding) -> jax.Array:
    """A global array from the same host array on every process (each feeds its own devices)."""
    return jax.make_array_from_callback(x.shape, sharding, lambda idx: x[idx])


def _to_host(tree):
    """Every row of sharded outputs as NumPy arrays, on every process."""
    if jax.process_count() == 1:
        return jax.tree_util.tree_map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return jax.tree_util.tree_map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))


def _clean(out: dict) -> dict:
    """Flag rows with non-finite outputs as ``nan`` and give them neutral values."""
    adj = np.asarray(out["max_abs_footstep_adjustment_m"], float)
    nan = np.asarray(out["nan"], bool) | ~np.isfinite(adj) | np.isnan(np.asarray(out["fall_time_s"], float))
    out["nan"] = nan
    out["max_abs_footstep_adjustment_m"] = np.where(nan, np.nan, adj)
    out["fell"] = np.asarray(out["fell"], bool) & ~nan  # one meaning: fell is a finite rollout that fell
    out["steps_to_recover"] = np.where(nan, -1, np.asarray(out["steps_to_recover"], np.int32))
    return out


def failure_reason(fell: np.ndarray, nan: np.ndarray, solve_failed: np.ndarray | None = None) -> np.ndarray:
    """``"nan"`` (numerically bad), ``"solve_failed"`` (the controller's solve failed, which ends the walk:
    ``fell`` is set too), ``"fell"`` or ``""`` (recovered) per rollout."""
    failed = np.zeros(np.shape(fell), bool) if solve_failed is None else np.asarray(solve_failed, bool)
    return np.where(nan, "nan", np.where(failed & fell, "solve_failed", np.where(fell, "fell", "")))


def _broadcast_from_0(x: np.ndarray) -> np.ndarray:
    if jax.process_count() == 1:
        return x
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.broadcast_one_to_all(x))


def _barrier(name: str) -> None:
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def run_sweep(config: SweepConfig, out_dir: Path, *, resume: bool = False, force: bool = False,
              progress: bool = True, desc: str | None = None, position: int | None = None) -> SweepRun:
    """Run (or finish) a sweep into ``out_dir``; return its per-rollout results and timing (``position``: the
    progress bar's row, when several sweeps show theirs at once).

    Raises:
        GridError: a bad configuration. ModelUnavailable: a model that cannot run yet.
        SweepConflict: ``out_dir`` holds a different sweep and ``force`` is off.
    """
    t_start = time.perf_counter()
    check(config)
    model = get_model(config.model)
    writer = jax.process_index() == 0
    n, chunk = config.n_rollouts, config.chunk
    n_chunks = math.ceil(n / chunk)
    chunk_dir = Path(out_dir) / CHUNK_DIR
    status = np.zeros(n_chunks + 1, np.int32)  # [conflict, done per chunk]
    conflict, resumed = None, {}
    if writer:
        try:
            chunk_dir = prepare_out_dir(out_dir, config, resume=resume, force=force)
            resumed = _finished_chunks(chunk_dir, n_chunks)
            status[1:] = [i in resumed for i in range(n_chunks)]
        except SweepConflict as e:
            conflict, status[0] = e, 1
    status = _broadcast_from_0(status)
    if status[0]:
        raise conflict or SweepConflict(f"{out_dir} holds a different sweep (see process 0)")
    todo = [i for i in range(n_chunks) if not status[1 + i]]
    inputs = grid_inputs(config)
    devices = sweep_devices(config)
    padded = math.ceil(chunk / len(devices)) * len(devices)
    rows = lambda i: min(chunk, n - i * chunk)  # noqa: E731
    delay_s = float(os.environ.get(DELAY_ENV, "0") or 0)
    first_s = run_s = 0.0
    computed: dict[int, dict] = {}
    with jax.enable_x64(config.x64):
        float_dtype = np.float64 if config.x64 else np.float32
        keys = rollout_keys(config.seed, inputs.index)
        fn, sharding = _chunk_fn(config.compiled_part(), model.rollout, devices)
        bar = _progress(n, n - sum(rows(i) for i in todo), progress and writer, desc, position)
        try:
            for k, i in enumerate(todo):
                lo, hi = i * chunk, i * chunk + rows(i)
                t0 = time.perf_counter()
                host = _chunk_inputs(inputs, keys, lo, hi, padded, float_dtype)
                aux = None if model.prepare is None else model.prepare(config.compiled_part(), host)
                batch, aux = jax.tree_util.tree_map(lambda x: _global(np.asarray(x), sharding), (host, aux))
                out = _to_host(fn(batch, aux))
                dt = time.perf_counter() - t0
                if k == 0:
                    first_s = dt
                else:
                    run_s += dt
                flat = {name: v for name, v in out._asdict().items() if name != "extra"}
                flat.update(out.extra)
                arrays = _clean({name: np.asarray(v)[: hi - lo] for name, v in flat.items()})
                computed[i] = arrays
                if writer:
                    save_npz_atomic(chunk_path(chunk_dir, i), dict(arrays, lo=np.asarray(lo), hi=np.asarray(hi)))
                bar.update(hi - lo)
                if delay_s:
                    time.sleep(delay_s)
        except KeyboardInterrupt:
            bar.close()
            raise SweepInterrupted(Path(out_dir), n_chunks - len(todo) + len(computed), n_chunks) from None
        bar.close()
    _barrier("sweeps: all chunks written")
    results = _assemble(inputs, [computed.get(i) or resumed[i] for i in range(n_chunks)], n, config) \
        if writer else None
    ticks = model.ticks_per_rollout(config)
    done = sum(rows(i) for i in todo)
    # Throughput over the chunks after the first (the first call also compiles); one chunk: it alone.
    timed_rows, timed_s = (done - rows(todo[0]), run_s) if len(todo) > 1 else (done, first_s)
    rate = timed_rows / timed_s if timed_s > 0 and timed_rows > 0 else None
    timing = dict(
        wall_s=time.perf_counter() - t_start, first_chunk_s=first_s, run_s=run_s + first_s,
        rollouts_run=done, rollouts_resumed=n - done, chunks_run=len(todo), chunks_resumed=n_chunks - len(todo),
        ticks_per_rollout=ticks, env_step_s=None if model.env_step_s is None else model.env_step_s(config),
        rollouts_per_s=rate, env_steps_per_s=None if rate is None else rate * ticks,
        rate_includes_compile=len(todo) == 1,
        device_count=len(devices), process_count=jax.process_count(), backend=jax.default_backend(),
        devices=[str(d) for d in devices], chunk=chunk, padded_chunk=padded, n_chunks=n_chunks,
    )
    return SweepRun(config, results, timing)


def _progress(total: int, initial: int, enabled: bool, desc: str | None, position: int | None = None):
    """A tqdm bar on stderr: rollouts done, rollouts per second, time left."""
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="rollout", file=sys.stderr, disable=not enabled,
                desc=desc or "sweep", dynamic_ncols=True, mininterval=0.5, smoothing=0.1, position=position)


def _assemble(inputs, chunks: list, n: int, config: SweepConfig | None = None) -> dict:
    """Concatenate chunk outcomes (computed or read back) into per-rollout arrays (with the scenario of
    each row, ``scenario_index`` and one column per axis, when the sweep has scenario axes)."""
    parts: dict[str, list] = {}
    for c in chunks:
        for k, v in c.items():
            if k not in ("lo", "hi"):
                parts.setdefault(k, []).append(v)
    out = {k: np.concatenate(v) for k, v in parts.items()}
    if any(len(v) != n for v in out.values()):
        raise RuntimeError(f"chunks hold {len(next(iter(out.values())))} rollouts, expected {n}")
    res = dict(index=inputs.index, phase=inputs.phase, impulse_ns=inputs.impulse_ns,
               direction_rad=inputs.direction_rad, **out)
    if config is not None and config.scenario:
        res["scenario_index"] = np.asarray(inputs.scenario_index, np.int32)
        res.update(scenario_columns(config, inputs.scenario_index))
    res["reason"] = failure_reason(res["fell"], res["nan"], res.get("solve_failed"))
    return res
