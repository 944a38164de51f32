"""Run a sweep: jit + vmap over fixed-size chunks, sharded over devices, resumable.

Each chunk of ``config.chunk`` rollouts (the last one padded, so every call
has the same shapes and compiles once) is padded to a multiple of the local
device count, placed with ``NamedSharding(Mesh(devices, ("batch",)),
PartitionSpec("batch"))`` and run by one jitted ``vmap`` of the model's
rollout. Each finished chunk is written atomically (temporary file in the same
folder, then ``os.replace``) under ``OUT/chunks/``; ``resume=True`` skips the
chunks already there. ``OUT/config.json`` holds the configuration and its
hash: a different sweep is refused unless ``force=True``.

Under ``jax.distributed`` (several processes, one per host) process ``p`` of
``P`` runs chunks ``p, p + P, ...`` on its own local devices into the shared
``OUT`` folder; process 0 waits for the others and assembles the results.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, NamedTuple

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from sweeps.grid import SweepConfig, grid_inputs
from sweeps.models import RolloutInputs, get_model

CHUNK_DIR = "chunks"
RESULT_FILES = ("results.npz", "results.csv", "basin.png", "summary.json")
_DELAY_ENV = "COMAN_SWEEP_CHUNK_DELAY_S"  # tests only: sleep after each chunk, to kill a run mid-sweep
_FN_CACHE: dict = {}


class SweepConflict(RuntimeError):
    """The output folder holds a different sweep (the command line exits 2)."""


class SweepRun(NamedTuple):
    """A finished sweep.

    Attributes:
        config: the configuration.
        results: per-rollout arrays (inputs, outputs, ``reason``), each (n,).
        timing: wall, compile and run seconds, rollouts and ticks per second, devices.
    """

    config: SweepConfig
    results: dict
    timing: dict


def _atomic_write(path: Path, write: Callable) -> None:
    """Write through ``write(fileobj)`` to a temporary file beside ``path``, then rename."""
    fd, tmp = tempfile.mkstemp(prefix="." + path.name, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def save_npz_atomic(path: Path, arrays: dict) -> None:
    """``np.savez`` to ``path`` atomically."""
    _atomic_write(Path(path), lambda f: np.savez(f, **arrays))


def save_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    save_bytes_atomic(path, text.encode())


def save_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    _atomic_write(Path(path), lambda f: f.write(data))


def prepare_out_dir(out_dir: Path, config: SweepConfig, *, resume: bool, force: bool) -> Path:
    """Create or check ``out_dir`` for ``config``; return its chunk folder.

    Raises:
        SweepConflict: ``out_dir`` holds a different sweep and ``force`` is off.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    chunk_dir = out_dir / CHUNK_DIR
    cfg_path = out_dir / "config.json"
    fresh = not resume
    if cfg_path.exists():
        try:
            old_hash = json.loads(cfg_path.read_text()).get("hash")
        except (OSError, ValueError):
            old_hash = None
        if old_hash != config.hash():
            if not force:
                raise SweepConflict(f"{out_dir} holds a different sweep (config hash {old_hash} != {config.hash()}); "
                                    "use --force to overwrite or another --out")
            fresh = True
    elif chunk_dir.exists():
        fresh = True  # chunks of an unknown sweep
    if fresh:
        shutil.rmtree(chunk_dir, ignore_errors=True)
        for name in RESULT_FILES:
            (out_dir / name).unlink(missing_ok=True)
    chunk_dir.mkdir(exist_ok=True)
    save_text_atomic(cfg_path, json.dumps({"hash": config.hash(), "config": config.to_dict()}, indent=1))
    return chunk_dir


def _chunk_fn(config: SweepConfig, rollout: Callable, devices: tuple):
    """The jitted, sharded batch rollout of a chunk (cached per configuration and devices)."""
    key = (config, rollout, devices)
    if key not in _FN_CACHE:
        mesh = Mesh(np.asarray(devices), ("batch",))
        sharding = NamedSharding(mesh, PartitionSpec("batch"))
        batched = jax.vmap(lambda inp: rollout(config, inp))
        _FN_CACHE[key] = (jax.jit(batched, in_shardings=sharding, out_shardings=sharding), sharding)
    return _FN_CACHE[key]


def _pad(x: np.ndarray, size: int) -> np.ndarray:
    """Pad the first axis to ``size`` by repeating the first row (valid inputs, discarded)."""
    if len(x) == size:
        return x
    return np.concatenate([x, np.repeat(x[:1], size - len(x), axis=0)])


def _chunk_inputs(inputs, lo: int, hi: int, padded: int, float_dtype) -> RolloutInputs:
    return RolloutInputs(
        index=_pad(inputs.index[lo:hi], padded).astype(np.int32),
        phase=_pad(inputs.phase[lo:hi], padded).astype(float_dtype),
        impulse_ns=_pad(inputs.impulse_ns[lo:hi], padded).astype(float_dtype),
        direction_rad=_pad(inputs.direction_rad[lo:hi], padded).astype(float_dtype),
    )


def _clean(out: dict) -> dict:
    """Flag rows with non-finite outputs as ``nan`` and give them neutral values."""
    adj = np.asarray(out["max_abs_footstep_adjustment_m"], float)
    nan = np.asarray(out["nan"], bool) | ~np.isfinite(adj) | np.isnan(np.asarray(out["fall_time_s"], float))
    out["nan"] = nan
    out["max_abs_footstep_adjustment_m"] = np.where(nan, np.nan, adj)
    out["fell"] = np.asarray(out["fell"], bool) | nan
    out["steps_to_recover"] = np.where(nan, -1, np.asarray(out["steps_to_recover"], np.int32))
    return out


def failure_reason(fell: np.ndarray, nan: np.ndarray) -> np.ndarray:
    """``"nan"``, ``"fell"`` or ``""`` per rollout."""
    return np.where(nan, "nan", np.where(fell, "fell", ""))


def run_sweep(config: SweepConfig, out_dir: Path, *, resume: bool = False, force: bool = False,
              progress: bool = True, desc: str | None = None) -> SweepRun:
    """Run (or finish) a sweep into ``out_dir``; return its per-rollout results and timing.

    Raises:
        GridError: a bad configuration. ModelUnavailable: a model that cannot run yet.
        SweepConflict: ``out_dir`` holds a different sweep and ``force`` is off.
    """
    t_start = time.perf_counter()
    config.validate()
    model = get_model(config.model)
    chunk_dir = prepare_out_dir(out_dir, config, resume=resume, force=force)
    inputs = grid_inputs(config)
    n, chunk = config.n_rollouts, config.chunk
    n_chunks = math.ceil(n / chunk)
    devices = tuple(jax.local_devices())
    padded = math.ceil(chunk / len(devices)) * len(devices)
    proc, n_proc = jax.process_index(), jax.process_count()
    mine = [i for i in range(n_chunks) if i % n_proc == proc]
    path = lambda i: chunk_dir / f"chunk_{i:05d}.npz"  # noqa: E731
    todo = [i for i in mine if not path(i).exists()]
    delay_s = float(os.environ.get(_DELAY_ENV, "0") or 0)
    compile_s = run_s = 0.0
    done_rows = sum(min(chunk, n - i * chunk) for i in mine if i not in todo)
    with jax.enable_x64(config.x64):
        float_dtype = np.float64 if config.x64 else np.float32
        fn, sharding = _chunk_fn(config, model.rollout, devices)
        bar = _progress(sum(min(chunk, n - i * chunk) for i in mine), done_rows, progress, desc)
        if todo:
            t0 = time.perf_counter()
            example = jax.device_put(_chunk_inputs(inputs, 0, min(chunk, n), padded, float_dtype), sharding)
            compiled = fn.lower(example).compile()
            compile_s = time.perf_counter() - t0
        for i in todo:
            lo, hi = i * chunk, min((i + 1) * chunk, n)
            t0 = time.perf_counter()
            batch = jax.device_put(_chunk_inputs(inputs, lo, hi, padded, float_dtype), sharding)
            out = jax.tree_util.tree_map(np.asarray, compiled(batch))
            run_s += time.perf_counter() - t0
            arrays = _clean({k: np.asarray(v)[: hi - lo] for k, v in out._asdict().items()})
            save_npz_atomic(path(i), dict(arrays, lo=np.asarray(lo), hi=np.asarray(hi)))
            bar.update(hi - lo)
            if delay_s:
                time.sleep(delay_s)
        bar.close()
    if n_proc > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("sweeps: all chunks written")
    results = _assemble(inputs, [path(i) for i in range(n_chunks)], n)
    ticks = model.ticks_per_rollout(config)
    done = sum(min((i + 1) * chunk, n) - i * chunk for i in todo)
    timing = dict(
        wall_s=time.perf_counter() - t_start, compile_s=compile_s, run_s=run_s,
        rollouts_run=done, rollouts_resumed=n - done, ticks_per_rollout=ticks,
        rollouts_per_s=done / run_s if run_s > 0 else None,
        env_steps_per_s=done * ticks / run_s if run_s > 0 else None,
        device_count=len(devices), process_count=n_proc, devices=[str(d) for d in devices],
        chunk=chunk, padded_chunk=padded, n_chunks=n_chunks,
    )
    return SweepRun(config, results, timing)


def _progress(total: int, initial: int, enabled: bool, desc: str | None):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="rollout", file=sys.stderr, disable=not enabled,
                desc=desc or "sweep", dynamic_ncols=True, mininterval=0.5)


def _assemble(inputs, chunk_paths: list, n: int) -> dict:
    """Concatenate chunk files into per-rollout arrays with the inputs and reasons."""
    parts: dict[str, list] = {}
    for p in chunk_paths:
        with np.load(p) as z:
            for k in z.files:
                if k not in ("lo", "hi"):
                    parts.setdefault(k, []).append(z[k])
    out = {k: np.concatenate(v) for k, v in parts.items()}
    if any(len(v) != n for v in out.values()):
        raise RuntimeError(f"chunks hold {len(next(iter(out.values())))} rollouts, expected {n}")
    res = dict(index=inputs.index, phase=inputs.phase, impulse_ns=inputs.impulse_ns,
               direction_rad=inputs.direction_rad, **out)
    res["reason"] = failure_reason(res["fell"], res["nan"])
    return res

