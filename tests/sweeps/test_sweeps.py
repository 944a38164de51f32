"""coman-sweep end to end (subprocesses): outputs and physics of a small 3LP map, refusal to overwrite,
resume after a kill, 4 host devices, the controller comparison; bad arguments (in process)."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
# 4 phases x 6 impulses (0-10 N s) of 0.1 s forward pushes during step 2 of 6 steps; 6 chunks of 4.
GRID = ["--phases", "4", "--impulses", "0:10:6", "--n-steps", "6", "--no-progress"]
SMALL = [*GRID, "--chunk", "4"]


_CACHE: dict = {}


@pytest.fixture(scope="module", autouse=True)
def _compile_cache(tmp_path_factory):
    """One persistent JAX compilation cache for this module's subprocesses (same sweep, no recompiling)."""
    _CACHE["dir"] = str(tmp_path_factory.mktemp("jax-cache"))
    yield
    _CACHE.clear()


def _env(**extra):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("XLA_FLAGS", None)  # the CLI must add the CPU scheduler flag itself
    if "dir" in _CACHE:
        env.update(JAX_COMPILATION_CACHE_DIR=_CACHE["dir"], JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    env.update(extra)
    return env


def _sweep(args, timeout=240, **env):
    return subprocess.run([sys.executable, "-m", "sweeps", *args], cwd=ROOT, env=_env(**env),
                          capture_output=True, text=True, timeout=timeout)


def _results(out: Path) -> dict:
    with np.load(out / "results.npz") as z:
        return {k: z[k] for k in z.files}


@pytest.mark.parametrize("args, names", [
    (["map", "--impulses", "0:10:0"], "empty grid"),
    (["map", "--impulses=-1,2"], "non-negative"),
    (["map", "--phases", "0"], "--phases"),
    (["map", "--phases", "0.5,1.5"], "[0, 1)"),
    (["map", "--controller", "pid"], "'pid'"),
    (["compare", "--controllers", "dlqr,pid"], "'pid'"),
    (["compare", "--jobs", "0"], "--jobs must be > 0, got '0'"),
    (["map", "--model", "bullet"], "unknown model 'bullet'"),
    (["map", "--model", "3lp", "--controller", "no-deadzone"], "'no-deadzone' for model 3lp"),
    (["map", "--randomize-spring", "5"], "--randomize-spring applies to --model mjx"),
    (["map", "--push-step", "12"], "push_step"),
    (["map", "--noise", "-0.1"], "--noise"),
    (["map", "--set", "zeta"], "KEY=VALUE"),
    (["map", "--set", "zeta=0"], "zeta"),
    (["map", "--model", "mjx", "--controller", "open-loop", "--set", "hip_attack=1.5"], "hip_attack"),
    (["compare", "--model", "mjx", "--controllers", "open-loop,pid"], "'pid'"),
    (["map", "--model", "mjx", "--axis", "gravity=1"], "'gravity'"),
    (["map", "--model", "mjx", "--axis", "payload_kg"], "NAME=V1"),
    (["map", "--model", "mjx", "--axis", "payload_kg=0,heavy"], "'heavy'"),
    (["map", "--model", "mjx", "--axis", "payload_kg=0,40"], "payload_kg"),
    (["map", "--model", "mjx", "--axis", "slope_deg=0,0"], "repeats"),
    (["map", "--model", "mjx", "--axis", "delay_ms=0,500"], "delay_ms"),
    (["map", "--model", "mjx", "--axis", "terrain=flat,bumpy"], "bumpy"),
    (["map", "--model", "mjx", "--axis", "actuator=ideal,hydraulic"], "'hydraulic'"),
    (["map", "--model", "mjx", "--slope-deg", "5", "--axis", "slope_deg=0,5"], "both give slope_deg"),
    (["map", "--model", "mjx", "--imu-noise-deg", "1,3"], "one value"),
    (["map", "--model", "3lp", "--payload-kg", "1"], "--model mjx only"),
    (["map", "--preset", "default", "--payload-kg", "1"], "--preset"),
    (["map", "--model", "mjx", "--direction", "up"], "'up'"),
    (["map", "--model", "mjx", "--direction", "forward,left"], "--directions"),
    (["compare", "--model", "mjx", "--directions", "forward,0"], "heading twice"),
])
def test_bad_arguments_exit_2_with_one_line(args, names, tmp_path, capsys):
    from sweeps.cli import main

    with pytest.raises(SystemExit) as exc:
        main([*args, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and names in err, err
    assert not (tmp_path / "out").exists()


def test_bad_argument_from_the_installed_entry_point(tmp_path):
    r = _sweep(["map", "--model", "bullet", "--out", str(tmp_path)], timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == ["coman-sweep: error: unknown model 'bullet'; choose one of 3lp, mjx"]


def test_cli_appends_the_xla_cpu_flag_to_user_flags():
    code = "import sweeps.cli, os; print(os.environ['XLA_FLAGS'])"
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       env=_env(XLA_FLAGS="--xla_force_host_platform_device_count=4"))
    flags = r.stdout.split()
    assert "--xla_force_host_platform_device_count=4" in flags
    assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in flags


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small map, uninterrupted, on one device."""
    out = tmp_path_factory.mktemp("ref")
    r = _sweep(["map", *SMALL, "--out", str(out)])
    assert r.returncode == 0, r.stderr
    return out


def test_map_writes_outputs_and_the_basin_is_physical(reference):
    for name in ("results.npz", "results.csv", "basin.png", "summary.json"):
        assert (reference / name).stat().st_size > 0
    for name in ("summary.json", "config.json"):  # strict JSON: no NaN or Infinity tokens
        json.loads((reference / name).read_text(), parse_constant=lambda c: pytest.fail(f"{name} holds {c}"))
    summary = json.loads((reference / "summary.json").read_text())
    assert summary["rollouts"] == 24 and summary["device_count"] == 1 and summary["chunks_run"] == 6
    assert len(summary["per_phase"]) == 4 and summary["env_steps_per_s"] > 0 and summary["env_step_s"] == 0.002
    lines = (reference / "results.csv").read_text().strip().splitlines()
    assert len(lines) == 25 and lines[0].startswith("index,phase,impulse_ns,force_n")
    res = _results(reference)
    fell = res["fell"].reshape(4, 6)
    # no push never falls; per phase, falls are monotone in the impulse (once it falls, larger pushes fall)
    assert not fell[:, 0].any()
    assert all(np.all(np.diff(row.astype(int)) >= 0) for row in fell)
    # the largest push (10 N s = 100 N for 0.1 s) falls at some phase but not at all (60-140 N recovered)
    assert fell[:, -1].any() and not fell[:, -1].all()
    # pushes later in the step are recovered at least as well (time projection reacts within the step)
    best = [row["max_recovered_impulse_ns"] for row in summary["per_phase"]]
    assert [row["recovered_up_to_ns"] for row in summary["per_phase"]] == best  # monotone: no islands here
    assert best[2] >= best[0] and best[3] >= best[0]
    # the footstep moves with the push: none unpushed, growing with the impulse while recovered
    adj = res["max_abs_footstep_adjustment_m"].reshape(4, 6)
    assert np.all(adj[:, 0] < 1e-4)
    ok = ~fell
    assert all(np.all(np.diff(a[o]) > 0) for a, o in zip(adj[:, 1:], ok[:, 1:]))
    steps = res["steps_to_recover"].reshape(4, 6)
    assert np.all(steps[fell] == -1) and np.all(steps[:, 0] == 0) and np.all(steps[ok & (steps >= 0)] <= 5)
    assert set(res["reason"][res["fell"]]) == {"fell"} and set(res["reason"][~res["fell"]]) == {""}


def test_other_sweep_refused_without_force(reference):
    before = (reference / "results.npz").read_bytes()
    r = _sweep(["map", *SMALL, "--seed", "1", "--out", str(reference)], timeout=60)
    assert r.returncode == 2 and "different sweep" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert (reference / "results.npz").read_bytes() == before


def test_resume_after_kill_matches_uninterrupted(reference, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "sweeps", "map", *SMALL, "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(COMAN_SWEEP_CHUNK_DELAY_S="3"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 180
        while not list((out / "chunks").glob("chunk_*.npz")) and time.time() < deadline:
            time.sleep(0.1)
        proc.kill()
    finally:
        proc.wait()
    done = sorted((out / "chunks").glob("chunk_*.npz"))
    assert 1 <= len(done) < 6 and not (out / "results.npz").exists()
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    r = _sweep(["map", *SMALL, "--out", str(out), "--resume"])
    assert r.returncode == 0, r.stderr
    assert all((out / "chunks" / k).stat().st_mtime_ns == v for k, v in stamps.items())  # not rewritten
    summary = json.loads((out / "summary.json").read_text())
    assert summary["chunks_resumed"] == len(done) and summary["chunks_run"] == 6 - len(done)
    assert summary["rollouts_resumed"] == 4 * len(done)
    a, b = _results(out), _results(reference)
    assert set(a) == set(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    again = _sweep(["map", *SMALL, "--out", str(out), "--resume"], timeout=60)  # nothing left to run
    assert again.returncode == 0 and json.loads((out / "summary.json").read_text())["chunks_run"] == 0


def test_ctrl_c_one_line_then_a_plain_rerun_recomputes_a_corrupt_chunk_and_keeps_the_rest(reference, tmp_path):
    import signal

    out = tmp_path / "interrupted"
    cmd = [sys.executable, "-m", "sweeps", "map", *SMALL, "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(COMAN_SWEEP_CHUNK_DELAY_S="1"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 180
        while len(list((out / "chunks").glob("chunk_*.npz"))) < 2 and time.time() < deadline:
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err.count("\n") == 1 and err.startswith("coman-sweep: interrupted after ") and "of 6 chunks" in err
    done = sorted((out / "chunks").glob("chunk_*.npz"))
    assert 2 <= len(done) < 6
    whole = done[0].read_bytes()
    done[0].write_bytes(whole[: len(whole) // 3])  # a chunk file cut short (a full disk, a copy gone wrong)
    stamp = done[1].stat().st_mtime_ns
    r = _sweep(["map", *SMALL, "--out", str(out)])  # no --resume: the finished chunks are kept all the same
    assert r.returncode == 0, r.stderr
    assert f"{done[0]}: unreadable" in r.stderr and done[1].stat().st_mtime_ns == stamp
    summary = json.loads((out / "summary.json").read_text())
    assert summary["chunks_resumed"] == len(done) - 1 and summary["chunks_run"] == 6 - len(done) + 1
    a, b = _results(out), _results(reference)
    for k in b:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    again = _sweep(["map", *SMALL, "--out", str(out)], timeout=60)  # a finished sweep run again: nothing lost
    assert again.returncode == 0 and json.loads((out / "summary.json").read_text())["chunks_run"] == 0
    for k, v in _results(out).items():
        np.testing.assert_array_equal(v, b[k], err_msg=k)


def test_four_devices_match_one(reference, tmp_path):
    # chunks of 6 padded to 8 rows: 2 rollouts per device, other chunk boundaries than the reference
    r = _sweep(["map", *GRID, "--chunk", "6", "--out", str(tmp_path)], XLA_FLAGS="--xla_force_host_platform_device_count=4")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["device_count"] == 4 and summary["chunk"] == 6 and summary["chunks_run"] == 4
    a, b = _results(tmp_path), _results(reference)
    for k in ("fell", "nan", "steps_to_recover", "reason", "phase", "impulse_ns"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    for k in ("max_abs_footstep_adjustment_m", "fall_time_s"):
        np.testing.assert_allclose(a[k], b[k], rtol=0, atol=1e-5, err_msg=k)


def test_compare_time_projection_recovers_late_pushes_dlqr_does_not(tmp_path):
    r = _sweep(["compare", "--controllers", "time-projection,dlqr", "--phases", "0.5,0.625,0.75,0.875",
                "--impulses", "0:8:5", "--n-steps", "6", "--no-progress", "--out", str(tmp_path)])
    assert r.returncode == 0, r.stderr
    from sweeps.parallel import cpu_cores

    assert ("2 sweeps, 2 at once" in r.stdout) == (cpu_cores() >= 2)  # one worker process per controller
    table = json.loads((tmp_path / "compare.json").read_text())
    assert table["controllers"] == ["time-projection", "dlqr"] and len(table["per_phase"]) == 4
    for row in table["per_phase"]:
        tp = row["time-projection_max_recovered_impulse_ns"] or 0.0
        dl = row["dlqr_max_recovered_impulse_ns"] or 0.0
        assert tp >= dl + 2.0, row  # at least one grid step more at every late phase
    assert table["recovery_rate"]["time-projection"] > table["recovery_rate"]["dlqr"]
    import matplotlib.image

    h, w = matplotlib.image.imread(tmp_path / "compare.png").shape[:2]
    assert w > 1.8 * h  # one figure, the two maps side by side
    assert "largest recovered forward impulse" in r.stdout and "time-projection" in r.stdout
    for c in ("time-projection", "dlqr"):
        assert (tmp_path / c / "summary.json").exists()


@pytest.mark.slow
def test_two_processes_under_jax_distributed_match_one(reference, tmp_path):
    """Two processes (one CPU device each) on one global mesh; only process 0 writes."""
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    out = tmp_path / "mp"
    procs = [subprocess.Popen([sys.executable, "-m", "sweeps", "map", *SMALL, "--out", str(out),
                               "--coordinator", f"localhost:{port}", "--num-processes", "2", "--process-id", str(i)],
                              cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    outs = [p.communicate(timeout=400) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    assert "wrote" in outs[0][0] and "wrote" not in outs[1][0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["process_count"] == 2 and summary["device_count"] == 2
    a, b = _results(out), _results(reference)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("argv, expected", [
    # no grid option: the built-in default, one subfolder per run
    (["map"], [("3lp", "3lp", 32 * 41, 512), ("mjx", "mjx", 20, 20)]),
    (["map", "--preset", "gpu"], [("mjx", "mjx", 4096, 4096)]),
    # options override a preset's fields; model-specific ones only in runs of that model
    (["map", "--preset", "default", "--phases", "2", "--noise", "0.5"], [("3lp", "3lp", 2 * 41, 512),
                                                                         ("mjx", "mjx", 10, 20)]),
    # a grid option without --preset: one map into --out with the base defaults
    (["map", "--phases", "4"], [("", "3lp", 4 * 41, 256)]),
    (["compare", "--model", "mjx", "--phases", "2", "--impulses", "0,1"],  # 8 directions by default
     [(c, "mjx", 2 * 8 * 4, 32) for c in ("time-projection", "open-loop", "no-deadzone", "dlqr", "footstep-mpc",
                                          "straight-leg", "straight-leg-no-toe-off", "bent-knee",
                                          "straight-leg-step-adjust")]),
    (["compare", "--model", "mjx", "--controllers", "dlqr"], [("dlqr", "mjx", 2 * 8 * 1 * 2, 32)]),
    (["compare", "--model", "mjx", "--controllers", "dlqr", "--direction", "45", "--chunk", "8", "--repeats", "1"],
     [("dlqr", "mjx", 1 * 2, 8)]),
    (["compare", "--model", "mjx", "--controllers", "dlqr", "--directions", "left,right", "--impulses", "1"],
     [("dlqr", "mjx", 2 * 2 * 1, 32)]),
    (["map", "--model", "mjx", "--directions", "4", "--phases", "2"], [("", "mjx", 4 * 2 * 41, 256)]),
    (["compare", "--model", "mjx", "--controllers", "footstep-mpc", "--axis", "actuator=ideal,sea"],
     [("footstep-mpc", "mjx", 2 * 2 * 8 * 1 * 2, 32)]),
    (["map", "--model", "mjx", "--controller", "open-loop", "--set", "hip_attack=0.5", "--phases", "2"],
     [("", "mjx", 2 * 41, 256)]),
    # scenario axes: batched ones multiply the grid; each terrain is its own run (a scene)
    (["map", "--model", "mjx", "--phases", "2", "--axis", "payload_kg=0,1", "--axis", "slope_deg=-5,0,5"],
     [("", "mjx", 2 * 41 * 6, 256)]),
    (["compare", "--model", "mjx", "--controllers", "time-projection,dlqr", "--phases", "2", "--impulses", "0,1",
      "--axis", "terrain=flat,rough:2", "--delay-ms", "10"],
     [(f"terrain-{t}/{c}", "mjx", 2 * 8 * 4, 32) for t in ("flat", "rough-2") for c in ("time-projection", "dlqr")]),
])
def test_presets_and_overrides(argv, expected, tmp_path):
    from sweeps.cli import build_parser
    from sweeps.plan import plan_runs

    plans = plan_runs(build_parser().parse_args([*argv, "--out", str(tmp_path)]))
    got = [(str(out.relative_to(tmp_path)).replace(".", ""), cfg.model, cfg.n_rollouts, cfg.chunk)
           for out, cfg, _, _ in plans]
    assert got == expected
    if "--noise" in argv:
        assert plans[0][1].noise_std_m == 0.5 and plans[1][1].sensor_noise_scale == 0.5
    if argv == ["map"]:
        assert [p[1].controller for p in plans] == ["time-projection", "time-projection"]
    if "--set" in argv:
        assert plans[0][1].controller == "open-loop" and plans[0][1].overrides() == {"hip_attack": 0.5}
    if "--axis" in argv:
        cfgs = [p[1] for p in plans]
        assert len({c.hash() for c in cfgs}) == len(cfgs)  # scenarios are part of the hash
        if "--delay-ms" in argv:
            assert [c.terrain for c in cfgs] == ["flat", "flat", "rough:2", "rough:2"]
            assert all(dict(c.scenario)["delay_ms"] == (10.0,) for c in cfgs)


def test_an_mjx_run_walks_at_its_controllers_own_step_time_unless_one_is_given(tmp_path, capsys):
    """compare's default list mixes 0.4 s and 0.6 s gaits: each run takes its controller's step time; an
    explicit --step-time is kept, and one a controller does not walk at is one line naming both, exit 2."""
    from mjx_coman import controllers
    from sweeps.cli import build_parser, main
    from sweeps.plan import plan_runs

    plans = plan_runs(build_parser().parse_args(["compare", "--model", "mjx", "--out", str(tmp_path)]))
    for _, cfg, _, _ in plans:
        _, own = controllers.load(cfg.controller)
        assert cfg.step_time_s == pytest.approx(controllers.get(cfg.controller).gait(own).step_time_s)
    assert {cfg.step_time_s for _, cfg, _, _ in plans} == {0.4, 0.6}
    argv = ["map", "--model", "mjx", "--controller", "straight-leg", "--out", str(tmp_path / "m")]
    assert plan_runs(build_parser().parse_args([*argv, "--step-time", "0.4"]))[0][1].step_time_s == 0.4
    with pytest.raises(SystemExit) as e:
        main([*argv, "--step-time", "0.4"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "step_time_s=0.4" in err and "0.6" in err


def test_controllers_command_lists_every_registered_controller(capsys):
    from mjx_coman import controllers
    from sweeps.cli import main

    assert main(["controllers", "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in table["mjx"]] == list(controllers.names())
    assert [r["name"] for r in table["3lp"]] == ["time-projection", "dlqr", "open-loop"]
    tp = next(r for r in table["mjx"] if r["name"] == "time-projection")
    zeta = next(s for s in tp["settings"] if s["name"] == "zeta")
    assert zeta["default"] == 0.1 and zeta["tunable"] and zeta["bounds"] == [0.0, 1.0]
    assert main(["controllers"]) == 0 and "joint-pd" in capsys.readouterr().out


def test_scenario_lines_give_each_scenarios_own_largest_recovered_impulse():
    from sweeps.scenario_args import describe

    row = lambda i, sc, best: {"scenario_index": i, "scenario": sc, "recovery_rate": 0.5, "fell": 1, "nan": 0,  # noqa: E731
                               "per_phase": [{"phase": 0.0, "max_recovered_impulse_ns": best}]}
    text = describe({"per_scenario": [row(0, {"slope_deg": 0.0}, 6.0), row(1, {"slope_deg": 5.0}, None)]})
    lines = text.splitlines()
    assert len(lines) == 2 and "slope_deg=0" in lines[0] and lines[0].endswith("0.00: 6")
    assert "slope_deg=5" in lines[1] and lines[1].endswith("0.00: -")
    assert describe({}) == ""
