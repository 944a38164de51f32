"""sweeps.runner in process: NaN rollouts, same seed same results, the output folder's identity."""

import dataclasses
import json

import jax.numpy as jnp
import numpy as np
import pytest

from sweeps import models, report
from sweeps.grid import SweepConfig
from sweeps.runner import SweepConflict, chunk_path, prepare_out_dir, run_sweep


def _fake(config, inp, aux):
    """Recovers below 2 N s, falls above, goes NaN above 4 N s (through its output or its own flag)."""
    adj = jnp.where(inp.impulse_ns > 4.0, jnp.nan, 0.01 * inp.impulse_ns)
    return models.RolloutOutputs(fell=inp.impulse_ns > 2.0, steps_to_recover=jnp.int32(2),
                                 max_abs_footstep_adjustment_m=adj, fall_time_s=jnp.float32(jnp.inf),
                                 nan=inp.impulse_ns > 6.0)


@pytest.fixture
def fake_model(monkeypatch):
    monkeypatch.setitem(models.MODELS, "fake", models.Model(_fake, lambda c: 100))


def _fake_solver(config, inp, aux):
    """Falls above 2 N s; the falls above 4 N s are the controller's failed solves."""
    fell = inp.impulse_ns > 2.0
    return models.RolloutOutputs(fell=fell, steps_to_recover=jnp.int32(2), max_abs_footstep_adjustment_m=jnp.float32(0.0),
                                 fall_time_s=jnp.float32(jnp.inf), nan=jnp.zeros((), bool),
                                 extra=dict(solve_failed=fell & (inp.impulse_ns > 4.0)))


def test_failed_solves_are_their_own_reason_and_count(tmp_path, monkeypatch):
    monkeypatch.setitem(models.MODELS, "fake", models.Model(_fake_solver, lambda c: 100))
    cfg = SweepConfig(model="fake", phases=(0.0,), impulses_ns=(1.0, 3.0, 5.0, 7.0), chunk=4)
    run = run_sweep(cfg, tmp_path, progress=False)
    assert list(run.results["reason"]) == ["", "fell", "solve_failed", "solve_failed"]
    summary = report.write_outputs(tmp_path, run)
    assert (summary["fell"], summary["solve_failed"], summary["nan"]) == (1, 2, 0)
    assert summary["recovery_rate"] == pytest.approx(0.25)  # a failed solve did not recover
    assert "solve_failed" in (tmp_path / "results.csv").read_text().splitlines()[0]


def test_nan_rollouts_are_failures_with_a_reason_not_statistics(tmp_path, fake_model):
    cfg = SweepConfig(model="fake", phases=(0.0, 0.5), impulses_ns=(0.0, 1.0, 3.0, 5.0, 7.0), chunk=3)
    run = run_sweep(cfg, tmp_path, progress=False)
    assert list(run.results["reason"][:5]) == ["", "", "fell", "nan", "nan"]
    assert list(run.results["steps_to_recover"][:5]) == [2, 2, 2, -1, -1]
    summary = report.write_outputs(tmp_path, run)
    assert summary["nan"] == 4 and summary["fell"] == 2 and summary["recovery_rate"] == pytest.approx(4 / 6)
    assert summary["per_phase"][0]["recovery_rate"] == pytest.approx(2 / 3)  # NaN rows left out of every rate
    assert not np.any(run.results["fell"] & run.results["nan"])  # one meaning of fell in rows and summary
    assert int(run.results["fell"].sum()) == summary["fell"]
    assert summary["per_phase"][0]["max_recovered_impulse_ns"] == 1.0
    assert summary["per_phase"][0]["recovered_up_to_ns"] == 1.0
    assert summary["max_abs_footstep_adjustment_m"] == pytest.approx(0.01)
    rows = [line.split(",") for line in (tmp_path / "results.csv").read_text().splitlines()[1:]]
    assert [r[-1] for r in rows[:5]] == ["", "", "fell", "nan", "nan"]
    assert [r[5] for r in rows[:5]] == ["0", "0", "1", "0", "0"]  # the csv's fell column: the same meaning
    assert "NaN" not in (tmp_path / "summary.json").read_text()


@pytest.fixture(scope="module")
def noisy_config():
    # sensor noise and robot randomisation: the seed decides every rollout
    return SweepConfig(phases=(0.25, 0.75), impulses_ns=(0.0, 5.0), n_steps=4, noise_std_m=2e-3,
                       randomize_mass_pct=10.0, randomize_leg_pct=5.0, chunk=2)


def test_same_config_and_seed_same_results_another_seed_differs(tmp_path, noisy_config):
    a = run_sweep(noisy_config, tmp_path / "a", progress=False).results
    b = run_sweep(noisy_config, tmp_path / "b", progress=False).results
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    c = run_sweep(dataclasses.replace(noisy_config, seed=1), tmp_path / "c", progress=False).results
    assert np.all(a["max_abs_footstep_adjustment_m"] != c["max_abs_footstep_adjustment_m"])
    assert np.all(a["max_abs_footstep_adjustment_m"][::2] > 1e-4)  # unpushed robots still step off-nominal


def test_out_dir_identity(tmp_path):
    a = SweepConfig(phases=(0.0,), impulses_ns=(1.0,))
    b = SweepConfig(phases=(0.0,), impulses_ns=(1.0,), seed=1)
    chunks = prepare_out_dir(tmp_path, a, force=False)
    chunk_path(chunks, 0).write_bytes(b"x")
    (tmp_path / "results.csv").write_text("finished")
    assert json.loads((tmp_path / "config.json").read_text())["hash"] == a.hash() != b.hash()
    for resume in (True, False):  # the same sweep again, resumed or not: nothing finished is deleted
        prepare_out_dir(tmp_path, a, resume=resume, force=False)
        assert chunk_path(chunks, 0).exists() and (tmp_path / "results.csv").read_text() == "finished"
    with pytest.raises(SweepConflict, match="different sweep"):
        prepare_out_dir(tmp_path, b, force=False)
    assert chunk_path(chunks, 0).exists() and (tmp_path / "results.csv").exists()
    prepare_out_dir(tmp_path, b, force=True)
    assert not chunk_path(chunks, 0).exists()  # forced: the other sweep's chunks are gone
    assert not (tmp_path / "results.csv").exists()
    prepare_out_dir(tmp_path, a, force=False)  # b died before its first chunk: its config.json blocks nothing
    assert json.loads((tmp_path / "config.json").read_text())["hash"] == a.hash()
    (tmp_path / "config.json").unlink()
    (tmp_path / "results.npz").write_bytes(b"x")
    with pytest.raises(SweepConflict, match="unknown sweep"):
        prepare_out_dir(tmp_path, a, force=False)
    chunk_path(chunks, 0).write_bytes(b"x")
    prepare_out_dir(tmp_path, a, force=True)  # forced over an unknown sweep: none of its work is kept
    assert not (tmp_path / "results.npz").exists() and not chunk_path(chunks, 0).exists()


def test_unreadable_chunks_are_found_and_removed(tmp_path, capsys):
    from jaxlp.files import save_npz_atomic
    from sweeps.runner import _finished_chunks, read_chunk

    good = dict(fell=np.zeros(4, bool), lo=np.asarray(0), hi=np.asarray(4))
    for i in range(4):
        save_npz_atomic(chunk_path(tmp_path, i), good)
    whole = chunk_path(tmp_path, 1).read_bytes()
    chunk_path(tmp_path, 1).write_bytes(whole[: len(whole) // 2])  # truncated
    chunk_path(tmp_path, 2).write_bytes(b"")  # empty
    flipped = bytearray(whole)
    flipped[60] ^= 0xFF  # a flipped byte inside the first array's data: the zip CRC catches it
    chunk_path(tmp_path, 3).write_bytes(bytes(flipped))
    assert read_chunk(chunk_path(tmp_path, 0))["hi"] == 4 and read_chunk(tmp_path / "missing.npz") is None
    assert list(_finished_chunks(tmp_path, 5)) == [0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chunk_00000.npz"]
    err = capsys.readouterr().err
    assert err.count("\n") == err.count("recomputing it\n") == 3
