"""A walk as an animation (GIF, or MP4 where ffmpeg is present), on any machine.

The poses are the simulated ``qpos`` a rollout recorded; MuJoCo C places
every geom for each (``mj_kinematics``). Two back ends draw them:

* ``mujoco``: MuJoCo's offscreen renderer, when an OpenGL back end is
  configured (``MUJOCO_GL=egl`` or ``osmesa``), with a camera that follows
  the pelvis;
* ``matplotlib``: an orthographic side view (x-z) and front view (y-z) of
  the visual geoms (capsules as thick segments, boxes and meshes as the
  outline of their bounding box), far geoms first, so it runs on a headless
  CPU machine.

A push is drawn as a red arrow on the upper torso, proportional to its force,
while it acts.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import NamedTuple, Sequence

import mujoco
import numpy as np

SUFFIXES = (".gif", ".mp4")
PUSH_BODY = "DWYTorso"
ARROW_M_PER_N = 0.004  # a 40 N push is drawn 0.16 m long
VISUAL_GROUP = 1  # the model's visual geoms (the foot contact spheres are group 3)
SIDE_RGB = {"L": (0.25, 0.45, 0.8), "R": (0.85, 0.55, 0.2), "": (0.55, 0.55, 0.6)}  # left, right, trunk
GL_BACKENDS = ("egl", "osmesa", "glfw")


class PushDrawing(NamedTuple):
    """The push to draw: world force (N), from ``start_s`` for ``duration_s``."""

    start_s: float
    duration_s: float
    force_n: tuple[float, float, float]


def check_path(path: str | os.PathLike) -> Path:
    """The output path, if its suffix is one this machine can write.

    Raises:
        ValueError: a suffix other than ``.gif``/``.mp4``, or ``.mp4`` without ffmpeg on the PATH.
    """
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise ValueError(f"--video must end in {' or '.join(SUFFIXES)}, got {str(path)!r}")
    if p.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
        raise ValueError(f"--video {str(path)!r}: .mp4 needs ffmpeg on the PATH, which this machine lacks; use .gif")
    return p


def frame_indices(time_s: np.ndarray, fps: float) -> np.ndarray:
    """Indices of the records nearest to a clock of ``fps`` frames per second over ``time_s``."""
    t = np.asarray(time_s, float)
    if fps <= 0 or not np.isfinite(fps):
        raise ValueError(f"fps must be positive, got {fps}")
    clock = np.arange(t[0], t[-1] + 1e-9, 1.0 / fps)
    return np.unique(np.clip(np.searchsorted(t, clock), 0, len(t) - 1))


def geom_poses(model: mujoco.MjModel, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(geom_xpos [T, G, 3], geom_xmat [T, G, 3, 3], push point [T, 3])`` of each ``qpos`` by MuJoCo C's
    forward kinematics; the push point is the CoM of :data:`PUSH_BODY`, where the rollout applies the push."""
    qpos = np.asarray(qpos, float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise ValueError(f"qpos must have shape (T, {model.nq}), got {qpos.shape}")
    data = mujoco.MjData(model)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PUSH_BODY)
    xpos = np.empty((len(qpos), model.ngeom, 3))
    xmat = np.empty((len(qpos), model.ngeom, 3, 3))
    push_at = np.empty((len(qpos), 3))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)  # xipos: body CoMs
        xpos[i] = data.geom_xpos
        xmat[i] = data.geom_xmat.reshape(-1, 3, 3)
        push_at[i] = data.xipos[body]
    return xpos, xmat, push_at


def push_force_at(push: PushDrawing | None, t: float) -> np.ndarray:
    """The push force acting at time ``t`` (zero outside the push)."""
    if push is None or not push.start_s <= t < push.start_s + push.duration_s:
        return np.zeros(3)
    return np.asarray(push.force_n, float)


def _cross(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _hull(pts: np.ndarray) -> np.ndarray:
    """Convex hull of 2-D points, counterclockwise (Andrew's monotone chain)."""
    pts = np.unique(pts.round(9), axis=0)
    if len(pts) < 3:
        return pts

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and _cross(out[-1] - out[-2], p - out[-2]) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]

    return np.array(half(pts) + half(pts[::-1]))


def _box_corners(model: mujoco.MjModel, g: int, pos: np.ndarray, mat: np.ndarray) -> np.ndarray:
    """World corners of geom ``g``'s bounding box (its half sizes for a box, the mesh's AABB otherwise)."""
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
        centre, half = np.zeros(3), model.geom_size[g]
    else:
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return pos + (centre + signs * half) @ mat.T


def _side(model: mujoco.MjModel, g: int) -> str:
    """``L``, ``R`` or ``""`` from the name of geom ``g``'s body (``LThighUpLeg``, ``RElb``, ``Waist``)."""
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g]) or ""
    return name[0] if len(name) > 1 and name[0] in "LR" and name[1].isupper() else ""


class _Matplotlib:
    """Side (x-z) and front (y-z) orthographic views drawn with matplotlib's Agg canvas."""

    VIEWS = ((0, 1, "side (x-z)"), (1, 0, "front (y-z)"))  # (horizontal axis, depth axis: drawn far first)
    HALF_WIDTH_M = 0.45

    def __init__(self, model: mujoco.MjModel, size_px: tuple[int, int]):
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.figure import Figure
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        self.model = model
        self.geoms = [g for g in range(model.ngeom) if model.geom_group[g] == VISUAL_GROUP]
        self.rgb = {g: SIDE_RGB[_side(model, g)] for g in self.geoms}
        w, h = size_px
        self.fig = Figure(figsize=(w / 100, h / 100), dpi=100)
        self.canvas = FigureCanvasAgg(self.fig)
        self.axes = self.fig.subplots(1, 2)
        self.fig.subplots_adjust(left=0.03, right=0.99, bottom=0.04, top=0.88, wspace=0.08)

    def frame(self, xpos, xmat, push_at, force, centre, title) -> np.ndarray:
        from matplotlib.patches import FancyArrow, Polygon

        m = self.model
        for ax, (hor, depth, label) in zip(self.axes, self.VIEWS):
            ax.clear()
            lo, hi = centre[hor] - self.HALF_WIDTH_M, centre[hor] + self.HALF_WIDTH_M
            ax.set_xlim(lo, hi)
            ax.set_ylim(-0.05, 1.0)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(label, fontsize=8)
            ax.axhspan(-0.05, 0.0, color="0.85", zorder=0)
            ax.axhline(0.0, color="0.4", lw=0.8, zorder=0)
            pts_per_m = ax.get_window_extent().width * 72 / self.fig.dpi / (hi - lo)
            for g in sorted(self.geoms, key=lambda g: -xpos[g, depth] if depth == 1 else xpos[g, depth]):
                rgba = self.rgb[g]
                if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
                    r, half = m.geom_size[g, :2]
                    ends = xpos[g] + np.outer((-half, half), xmat[g][:, 2])
                    ax.plot(ends[:, hor], ends[:, 2], color=rgba, lw=2 * r * pts_per_m, solid_capstyle="round")
                else:
                    corners = _box_corners(m, g, xpos[g], xmat[g])[:, (hor, 2)]
                    ax.add_patch(Polygon(_hull(corners), closed=True, fc=rgba, ec="0.2", lw=0.5))
            d = force[(hor, 2),] * ARROW_M_PER_N
            if np.hypot(*d) > 1e-3:  # the push's component in this view's plane
                ax.add_patch(FancyArrow(push_at[hor] - d[0], push_at[2] - d[1], d[0], d[1], width=0.012,
                                        length_includes_head=True, color="red", zorder=5))
        self.fig.suptitle(title, fontsize=9)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


class _MujocoGL:
    """MuJoCo's offscreen renderer with a tracking camera; the push as an arrow geom in the scene."""

    def __init__(self, model: mujoco.MjModel, size_px: tuple[int, int]):
        w, h = size_px
        self.renderer = mujoco.Renderer(model, height=h, width=w)
        self.model, self.data = model, mujoco.MjData(model)
        self.cam = mujoco.MjvCamera()
        self.cam.distance, self.cam.azimuth, self.cam.elevation = 1.8, 120.0, -15.0

    def set_qpos(self, q):
        self.data.qpos[:] = q
        mujoco.mj_forward(self.model, self.data)

    def frame(self, push_at, force, centre) -> np.ndarray:
        self.cam.lookat[:] = (centre[0], centre[1], 0.4)
        self.renderer.update_scene(self.data, self.cam)
        if np.any(force):
            scn = self.renderer.scene
            if scn.ngeom < scn.maxgeom:
                tip = np.asarray(push_at, float)
                tail = tip - np.asarray(force, float) * ARROW_M_PER_N
                g = scn.geoms[scn.ngeom]
                mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.zeros(9),
                                    np.array([1, 0, 0, 1], np.float32))
                mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_ARROW, 0.01, tail, tip)
                scn.ngeom += 1
        return self.renderer.render().copy()


def backend_name(requested: str = "auto") -> str:
    """``mujoco`` where an OpenGL back end is configured (``MUJOCO_GL``) and ``auto`` asked, else
    ``matplotlib``."""
    if requested not in ("auto", "mujoco", "matplotlib"):
        raise ValueError(f"backend must be auto, mujoco or matplotlib, got {requested!r}")
    if requested == "auto":
        return "mujoco" if os.environ.get("MUJOCO_GL", "").lower() in GL_BACKENDS else "matplotlib"
    return requested


def render_frames(model: mujoco.MjModel, time_s: np.ndarray, qpos: np.ndarray, push: PushDrawing | None = None,
                  title: str = "", fps: float = 25.0, size_px: tuple[int, int] = (640, 360),
                  backend: str = "auto") -> tuple[list[np.ndarray], str]:
    """RGB frames (uint8 ``[H, W, 3]``) of the recorded walk at ``fps``, and the back end that drew them
    (``auto`` falls back to matplotlib when MuJoCo's renderer cannot start)."""
    time_s, qpos = np.asarray(time_s, float), np.asarray(qpos, float)
    if len(time_s) != len(qpos) or len(time_s) == 0:
        raise ValueError(f"time_s and qpos must have the same nonzero length, got {len(time_s)} and {len(qpos)}")
    idx = frame_indices(time_s, fps)
    xpos, xmat, push_at = geom_poses(model, qpos[idx])
    name = backend_name(backend)
    drawer = None
    if name == "mujoco":
        try:
            drawer = _MujocoGL(model, size_px)
        except Exception:  # no usable OpenGL context: draw with matplotlib
            if backend == "mujoco":
                raise
            name = "matplotlib"
    if drawer is None:
        drawer = _Matplotlib(model, size_px)
    frames = []
    for k, i in enumerate(idx):
        force = push_force_at(push, time_s[i])
        centre = qpos[i, :3]
        if name == "mujoco":
            drawer.set_qpos(qpos[i])
            frames.append(drawer.frame(push_at[k], force, centre))
        else:
            label = f"{title}  t = {time_s[i]:.2f} s" + (f"  push {np.linalg.norm(force):.0f} N" if np.any(force) else "")
            frames.append(drawer.frame(xpos[k], xmat[k], push_at[k], force, centre, label.strip()))
    return frames, name


def write_frames(path: str | os.PathLike, frames: Sequence[np.ndarray], fps: float) -> Path:
    """Write the frames as a looping GIF (Pillow) or an H.264 MP4 (ffmpeg), atomically."""
    path = check_path(path)
    tmp = path.with_name(f".{path.name}.tmp{path.suffix}")
    if path.suffix.lower() == ".gif":
        from PIL import Image

        imgs = [Image.fromarray(f) for f in frames]
        imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=int(round(1000 / fps)), loop=0)
    else:
        h, w = frames[0].shape[:2]
        cmd = ["ffmpeg", "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}",
               "-r", f"{fps:g}", "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", str(tmp)]
        subprocess.run(cmd, input=b"".join(np.ascontiguousarray(f).tobytes() for f in frames), check=True)
    os.replace(tmp, path)
    return path


def write_video(path, model, time_s, qpos, push: PushDrawing | None = None, title: str = "", fps: float = 25.0,
                backend: str = "auto") -> dict:
    """Render and write a walk; returns ``{path, frames, fps, backend}``."""
    frames, name = render_frames(model, time_s, qpos, push, title, fps, backend=backend)
    out = write_frames(path, frames, fps)
    return dict(path=str(out), frames=len(frames), fps=fps, backend=name)
