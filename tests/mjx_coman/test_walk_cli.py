"""``python -m mjx_coman.walk``: one-line errors with exit status 2, and one real short walk.

The bad-argument tests call ``main`` in-process and check that nothing is
built before the arguments are; the real walk is a subprocess.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mjx_coman import walk as cli


SECONDS = "4"  # keep equal to tests/mjx_coman/test_notebook_03.py (one shared compilation)


def _run(*args, timeout=600, env=None):
    return subprocess.run([sys.executable, "-m", "mjx_coman.walk", *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


@pytest.fixture
def no_build(monkeypatch):
    """Fail loudly if a bad argument got as far as building the environment or walking."""
    import mjx_coman.env
    import mjx_coman.rollout

    def boom(*a, **k):
        raise AssertionError("built the environment before validating the arguments")

    monkeypatch.setattr(mjx_coman.env, "make_env_params", boom)
    monkeypatch.setattr(mjx_coman.rollout, "jit_walk", boom)


@pytest.mark.parametrize(
    "args,word",
    [
        (["--seconds", "-1"], "--seconds"),
        (["--seconds", "0"], "--seconds"),
        (["--seconds", "nan"], "--seconds"),
        (["--speed", "0.5"], "--speed"),
        (["--speed", "fast"], "--speed"),
        (["--speed", "0.1", "--controller", "joint-pd"], "--speed"),
        (["--controller", "mpc"], "mpc"),
        (["--controller", "nope"], "time-projection"),  # the known names are listed
        (["--set", "zeta"], "KEY=VALUE"),
        (["--set", "bogus=1"], "bogus"),
        (["--set", "hip_attack=2"], "hip_attack"),
        (["--set", "window=1.5"], "window"),
        (["--controller", "joint-pd", "--set", "zeta=0.2"], "zeta"),
        (["--controller", "straight-leg", "--set", "terrain=hills"], "hills"),
        (["--controller", "straight-leg", "--set", "toe_off=maybe"], "toe_off"),
        (["--controller", "straight-leg", "--terrain", "stairs:50"], "stairs:50"),
        (["--controller", "straight-leg", "--terrain", "stairs:0"], "stairs:0"),
        (["--controller", "straight-leg", "--set", "stairs_swing_s=0.401"], "stairs_swing_s"),
        (["--controller", "straight-leg", "--set", "joint_limit_horizon_s=0"], "joint_limit_horizon_s"),
        (["--controller", "straight-leg", "--set", "stair_max_step_m=1"], "stair_max_step_m"),
        (["--push-phase", "1.0"], "--push-phase"),
        (["--push-phase", "-0.1"], "--push-phase"),
        (["--push-ns", "-3"], "--push-ns"),
        (["--push-dir", "up"], "up"),
        (["--push-dir", "nan"], "--push-dir"),
        (["--turn-rate", "0.3"], "--turn-rate"),  # time-projection does not steer
        (["--turn-rate", "inf"], "--turn-rate"),
        (["--controller", "footstep-mpc", "--turn-rate", "0.7"], "--turn-rate"),  # beyond its 0.6 rad/s
        (["--controller", "footstep-mpc", "--speed", "0.5"], "--speed"),  # beyond seed 001's 0.4 m/s
        (["--push-duration", "0"], "--push-duration"),
        (["--push-step", "-1"], "--push-step"),
        (["--push-ns", "4", "--push-step", "30", "--seconds", "2"], "--push-step"),
        (["--payload-kg", "-1"], "--payload-kg"),
        (["--payload-body", "Tail"], "--payload-body"),
        (["--payload-com-m", "0.1,0"], "--payload-com-m"),
        (["--payload-com-m", "a,b,c"], "--payload-com-m"),
        (["--slope-deg", "45"], "--slope-deg"),
        (["--slope-deg", "nan"], "--slope-deg"),
        (["--terrain", "bumpy"], "bumpy"),
        (["--terrain", "rough:50"], "rough:50"),
        (["--terrain", "stairs:5:1"], "stairs:5:1"),
        (["--imu-noise-deg", "-1"], "--imu-noise-deg"),
        (["--joint-noise-deg", "inf"], "--joint-noise-deg"),
        (["--delay-ms", "500"], "--delay-ms"),
        (["--seed", "-2"], "--seed"),
        (["--seed", str(2**64)], "--seed"),
        (["--plot", "out.txt"], "--plot"),
        (["--plot", "/no/such/dir/out.png"], "--plot"),
        (["--plot", "/proc/out.png"], "/proc/out.png"),  # mode bits let root write there: tried, not read
        (["--video", "walk.avi"], "walk.avi"),
        (["--video", "/no/such/dir/walk.gif"], "--video"),
        (["--bogus"], "--bogus"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(args, word, capsys, no_build):
    with pytest.raises(SystemExit) as exc:
        sys.exit(cli.main(args))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and word in err


def test_bad_argument_in_a_subprocess_is_one_line_and_fast():
    out = _run("--push-phase", "1.5", timeout=120)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and "--push-phase" in out.stderr


def test_unknown_controller_in_a_subprocess_lists_the_known_names():
    out = _run("--controller", "nope", timeout=120)
    assert out.returncode == 2 and out.stdout == "" and out.stderr.count("\n") == 1
    assert all(n in out.stderr for n in ("time-projection", "open-loop", "dlqr", "joint-pd"))


def test_push_force_is_the_impulse_over_the_duration():
    assert cli.push_force_n(4.0, 0.1, "forward") == pytest.approx((40.0, 0.0, 0.0))
    assert cli.push_force_n(2.0, 0.2, "right") == pytest.approx((0.0, -10.0, 0.0))
    assert cli.push_force_n(2.0, 0.2, "backward") == pytest.approx((-10.0, 0.0, 0.0))


def test_push_direction_in_degrees_matches_the_names():
    for name, deg in (("forward", "0"), ("left", "90"), ("backward", "180"), ("right", "-90")):
        assert cli.push_force_n(3.0, 0.3, deg) == pytest.approx(cli.push_force_n(3.0, 0.3, name), abs=1e-12)
    fx, fy, _ = cli.push_force_n(3.0, 0.3, "45")
    assert fx == pytest.approx(10.0 / 2**0.5) and fy == pytest.approx(10.0 / 2**0.5)


@pytest.fixture(scope="module")
def short_walk(tmp_path_factory):
    png = tmp_path_factory.mktemp("walk") / "walk.png"
    gif = png.with_suffix(".gif")
    # JAX's persistent compilation cache, shared with the notebook 03 test (the same compiled walk)
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(tmp_path_factory.getbasetemp() / "jax_compile_cache"))
    out = _run("--speed", "0.0", "--seconds", SECONDS, "--controller", "closed-loop", "--set", "hip_attack=0.7",
               "--push-ns", "3", "--push-step", "1", "--push-phase", "0.35", "--push-dir", "backward",
               "--plot", str(png), "--video", str(gif), "--json", env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout), png


def test_short_walk_reports_ground_truth_and_stays_up(short_walk):
    report, png = short_walk
    for key in ("controller", "settings", "fell", "mean_speed_mps", "touchdowns", "steps_to_recover",
                "max_abs_footstep_adjustment_m", "nan", "solve_failed", "push", "heading_change_rad"):
        assert key in report
    assert report["controller"] == "time-projection" and report["settings"] == {"hip_attack": 0.7}
    assert report["fell"] is False and report["nan"] is False and report["solve_failed"] is False
    assert report["touchdowns"] >= 8  # 4 s: the start-up phase, then a touchdown every 0.4 s
    assert abs(report["mean_speed_mps"]) < 0.15  # in place
    assert abs(report["heading_change_rad"]) < 0.2 and report["turn_rate_rad_per_s"] == 0.0  # no steering
    assert report["push"]["start_s"] == pytest.approx((1 + 1 + 0.35) * 0.4)
    s2r = report["steps_to_recover"]
    assert s2r is None or 1 <= s2r <= report["touchdowns"]  # ground truth: touchdowns after the push ends
    assert report["max_abs_footstep_adjustment_m"] > 0.0
    assert png.stat().st_size > 10_000


def test_video_shows_the_robot_every_frame_and_the_push_while_it_acts(short_walk):
    """Drawn without OpenGL (matplotlib): the red push arrow in the frames inside the push only."""
    import numpy as np
    from PIL import Image, ImageSequence

    report, png = short_walk
    video = report["video"]
    assert video["backend"] == "matplotlib" and video["fps"] == 25.0
    with Image.open(video["path"]) as im:
        frames = [np.asarray(f.convert("RGB")).astype(int) for f in ImageSequence.Iterator(im)]
    assert len(frames) == video["frames"] and abs(len(frames) - 25 * float(SECONDS)) <= 2
    red = np.array([np.sum((f[..., 0] > 200) & (f[..., 1] < 60) & (f[..., 2] < 60)) for f in frames])
    t = np.arange(len(frames)) / 25.0
    start, dur = report["push"]["start_s"], report["push"]["duration_s"]
    inside = (t >= start + 0.02) & (t < start + dur - 0.02)  # a record's time is within 20 ms of the frame's
    outside = (t < start - 0.02) | (t >= start + dur + 0.02)
    assert inside.sum() >= 1 and np.all(red[inside] > 50) and np.all(red[outside] == 0), red
    robot = np.array([np.sum((f[..., 2] > 150) & (f[..., 0] < 100)) for f in frames])  # the blue left leg
    assert np.all(robot > 200)

