"""bench/gpu_sweep.py: background compiles, the time budget and out-of-memory records, on a stand-in model.

The real MJX rollout takes about a minute to compile on CPU, so these tests swap in a tiny JAX rollout.
"""

import sys
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import pytest

sys.path.insert(0, str(Path(__file__).parents[2] / "bench"))
import gpu_sweep  # noqa: E402


class _Out(NamedTuple):
    fell: jax.Array
    nan: jax.Array


class _Model(NamedTuple):
    ticks_per_rollout: object = lambda cfg: 10
    prepare: object = lambda cfg, inputs: None
    rollout: object = lambda cfg, i, aux: _Out(fell=i.impulse_ns > 3.0, nan=jnp.isnan(i.phase))


@pytest.fixture
def model(monkeypatch):
    monkeypatch.setattr(gpu_sweep.model_mjx, "load", lambda: _Model())


def test_batches_compile_in_the_background_then_run_in_ascending_order(model):
    res = gpu_sweep.sweep([8, 4], None, repeats=1, budget_s=1e9, workers=2)
    assert [r["batch"] for r in res["runs"]] == [4, 8] and res["ticks"] == 10
    for r in res["runs"]:
        assert r["status"] == "ok" and r["compile_s"] > 0 and r["run_s"] > 0 and r["nan"] == 0
        assert r["env_steps_per_s"] == pytest.approx(r["batch"] * 10 / r["run_s"])
    assert res["runs"][1]["fell"] == 2  # impulses spread over 0-4 N s: the last two of 8 are over 3
    assert res["runs"][1]["predicted_run_s"] == pytest.approx(2 * res["runs"][0]["run_s"] * 2)


def test_out_of_memory_is_recorded_and_larger_batches_skipped(model, monkeypatch):
    timed = gpu_sweep.time_compiled

    def oom_from_8(compiled, inputs, batch, ticks, repeats):
        if batch >= 8:
            raise jax.errors.JaxRuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 1 bytes.")
        return timed(compiled, inputs, batch, ticks, repeats)

    monkeypatch.setattr(gpu_sweep, "time_compiled", oom_from_8)
    runs = gpu_sweep.sweep([4, 8, 16], None, repeats=1, budget_s=1e9)["runs"]
    assert [r["status"] for r in runs] == ["ok", "oom", "skipped"]
    assert runs[1]["error"].startswith("RESOURCE_EXHAUSTED") and "batch 8" in runs[2]["reason"]


def test_nothing_runs_past_the_budget(model):
    runs = gpu_sweep.sweep([4, 8], None, repeats=1, budget_s=0.0)["runs"]
    assert [r["status"] for r in runs] == ["skipped", "skipped"] and "budget" in runs[0]["reason"]
