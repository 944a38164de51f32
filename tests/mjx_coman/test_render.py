"""mjx_coman.render: poses from MuJoCo C's kinematics, frames drawn without OpenGL, GIF written atomically."""

import mujoco
import numpy as np
import pytest

from mjx_coman import load_model, render
from mjx_coman.env import standing_posture


@pytest.fixture(scope="module")
def model():
    return load_model()


@pytest.fixture(scope="module")
def standing(model):
    q, root = standing_posture()
    return np.concatenate([root, q])


def _walked(standing, n=6, dx=0.05):
    """``n`` poses of the standing robot translated forward by ``dx`` each, 40 ms apart."""
    qpos = np.tile(standing, (n, 1))
    qpos[:, 0] += dx * np.arange(n)
    return 0.04 * np.arange(n), qpos


def test_frame_clock_picks_the_nearest_later_records():
    t = np.arange(0.0, 1.0 + 1e-9, 0.02)  # records every 20 ms
    idx = render.frame_indices(t, 25.0)
    assert np.allclose(np.diff(t[idx]), 0.04) and t[idx][0] == 0.0 and len(idx) == 26
    with pytest.raises(ValueError, match="fps"):
        render.frame_indices(t, 0.0)


def test_geom_poses_are_mujocos_forward_kinematics(model, standing):
    t, qpos = _walked(standing, n=3)
    xpos, xmat, push_at = render.geom_poses(model, qpos)
    data = mujoco.MjData(model)
    data.qpos[:] = qpos[2]
    mujoco.mj_forward(model, data)
    assert np.allclose(xpos[2], data.geom_xpos) and np.allclose(xmat[2].reshape(-1, 9), data.geom_xmat)
    torso = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, render.PUSH_BODY)
    assert np.allclose(push_at[2], data.xipos[torso])
    assert np.allclose(xpos[2, 1:] - xpos[0, 1:], [0.1, 0.0, 0.0])  # the robot (not the floor, geom 0) moved
    with pytest.raises(ValueError, match=r"\(T, "):
        render.geom_poses(model, qpos[:, :-1])


def test_hull_of_a_square_with_inner_points():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.2, 0.7]], float)
    hull = render._hull(pts)
    assert len(hull) == 4 and {tuple(p) for p in hull} == {(0, 0), (1, 0), (1, 1), (0, 1)}


def _red(frame):
    f = frame.astype(int)
    return int(np.sum((f[..., 0] > 200) & (f[..., 1] < 60) & (f[..., 2] < 60)))


def test_matplotlib_frames_show_the_robot_and_the_push_only_while_it_acts(model, standing):
    t, qpos = _walked(standing)
    push = render.PushDrawing(start_s=0.06, duration_s=0.04, force_n=(40.0, 0.0, 0.0))  # acts at t = 0.08 only
    frames, name = render.render_frames(model, t, qpos, push, "test", fps=25.0, size_px=(480, 270),
                                        backend="matplotlib")
    assert name == "matplotlib" and len(frames) == len(t)
    assert all(f.shape == (270, 480, 3) and f.dtype == np.uint8 for f in frames)
    reds = [_red(f) for f in frames]
    assert reds[2] > 100 and reds[0] == reds[1] == reds[3] == 0, reds
    dark = [int(np.sum(f.max(-1) < 200)) for f in frames]  # the robot's geoms are drawn in every frame
    assert min(dark) > 2000


def test_gif_has_every_frame_and_no_temporary_file(model, standing, tmp_path):
    from PIL import Image

    t, qpos = _walked(standing, n=4)
    info = render.write_video(tmp_path / "walk.gif", model, t, qpos, fps=25.0, backend="matplotlib")
    with Image.open(tmp_path / "walk.gif") as im:
        assert im.n_frames == info["frames"] == 4
    assert [p.name for p in tmp_path.iterdir()] == ["walk.gif"]


def test_bad_paths_are_refused_naming_them(monkeypatch):
    with pytest.raises(ValueError, match="walk.avi"):
        render.check_path("walk.avi")
    monkeypatch.setattr(render.shutil, "which", lambda name: None)
    with pytest.raises(ValueError, match="ffmpeg"):
        render.check_path("walk.mp4")
    with pytest.raises(ValueError, match="backend"):
        render.backend_name("vulkan")
