"""Terrain scene variants: rough ground (a height field) and stairs (boxes), with their height function.

A terrain is a string (plain and hashable: a static scene choice, each a
new ``MjModel`` and a new compilation):

* ``flat``: the packaged floor plane at ``z = 0``.
* ``rough:CM`` or ``rough:CM:SEED``: a height field of heights within
  +-CM cm (seed 001, experiments: +-5 cm). Heights are drawn uniformly in
  [-CM, CM] cm on a coarse grid of :data:`ROUGH_CELL_M` (two foot lengths,
  so a sole rests on a nearly plane patch: the steepest grade is
  ``2 CM / ROUGH_CELL_M``), interpolated bilinearly onto the height field's
  :data:`HFIELD_RES_M` grid, and faded to flat near the start: within
  ``|x| <= 0.3 m, |y| <= 0.25 m`` the ground is flat at ``z = 0`` (the
  robot starts there, standing), reaching full roughness 0.3 m further out
  (a raised-cosine ramp). The integer seed (default 0) drives NumPy's
  ``default_rng``. The field spans ``x`` in [-2, 6] m, ``y`` in [-2, 2] m;
  the floor plane lies below it and takes no contacts.
* ``stairs:CM``: :data:`STAIR_STEPS` steps of riser CM cm going up in
  +x, the first riser :data:`STAIR_START_X_M` ahead of the pelvis (0.2 m
  ahead of the standing toes), treads :data:`STAIR_TREAD_M` deep (a 0.2 m
  sole and room to place it; seed 004 walks 19.7 cm stairs on Atlas, whose
  legs are about twice COMAN's), then a 2 m landing; 2 m wide. Each step is
  a box, on the floor plane, which keeps its contacts.
* ``stairs:-CM``: the same staircase going down in +x: the robot starts on a
  platform (a box, top at ``z = 0``, from ``x = -2``) whose edge is the
  first drop, each tread CM cm lower, the last drop onto the floor plane,
  lowered to ``-STAIR_STEPS * CM`` cm.

The foot spheres collide with the terrain through explicit ``<pair>``
elements, as with the floor: MJX implements ``hfield``-``sphere`` (up to 4
contacts per pair) and ``sphere``-``box`` (1 per pair), see
``mujoco.mjx._src.collision_driver._COLLISION_FUNC``.
:func:`terrain_height_m` gives the ground height under a point, for the
fall judge (:mod:`mjx_coman.ground_truth`).
"""

from __future__ import annotations

import copy
import functools
import math
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_coman import mjcf

ROUGH_CELL_M = 0.4
HFIELD_RES_M = 0.025
ROUGH_X_M = (-2.0, 6.0)
ROUGH_Y_M = (-2.0, 2.0)
FLAT_START_HALF_M = (0.3, 0.25)  # |x|, |y| of the flat start patch
FLAT_RAMP_M = 0.3
HFIELD_BASE_M = 0.05
MAX_ROUGH_CM = 10.0

STAIR_START_X_M = 0.3
STAIR_TREAD_M = 0.3
STAIR_STEPS = 6
STAIR_LANDING_M = 2.0
STAIR_HALF_WIDTH_M = 1.0
MAX_STAIR_CM = 20.0


class Terrain(NamedTuple):
    """A parsed terrain: ``kind`` (``flat``, ``rough``, ``stairs``), ``height_m`` (amplitude or riser), ``seed``."""

    kind: str
    height_m: float = 0.0
    seed: int = 0

    @property
    def text(self) -> str:
        """The canonical string (``rough:2``, ``rough:2:7``, ``stairs:5``, ``flat``)."""
        if self.kind == "flat":
            return "flat"
        cm = f"{self.height_m * 100:g}"
        return f"{self.kind}:{cm}" + (f":{self.seed}" if self.kind == "rough" and self.seed else "")


def parse_terrain(text: str) -> Terrain:
    """``flat``, ``rough:CM[:SEED]`` or ``stairs:CM`` (``CM < 0``: down).

    Raises:
        ValueError: naming the bad value (unknown kind, a height outside (0, 10] cm for rough or
            [-20, 0) or (0, 20] cm for stairs, a seed that is not a whole number in [0, 2**32)).
    """
    t = str(text).strip()
    parts = t.split(":")
    kind = parts[0]
    if kind == "flat" and len(parts) == 1:
        return Terrain("flat")
    if kind not in ("rough", "stairs") or len(parts) < 2 or len(parts) > (3 if kind == "rough" else 2):
        raise ValueError(f"terrain {t!r} must be flat, rough:CM, rough:CM:SEED or stairs:CM")
    try:
        cm = float(parts[1])
    except ValueError:
        raise ValueError(f"terrain {t!r}: the height {parts[1]!r} is not a number of cm") from None
    top = MAX_ROUGH_CM if kind == "rough" else MAX_STAIR_CM
    if kind == "stairs" and math.isfinite(cm) and cm != 0 and abs(cm) <= top:
        pass
    elif kind == "stairs":
        raise ValueError(f"terrain {t!r}: the riser must lie in [-{top:g}, 0) or (0, {top:g}] cm, got {parts[1]}")
    elif not (math.isfinite(cm) and 0 < cm <= top):
        raise ValueError(f"terrain {t!r}: the height must lie in (0, {top:g}] cm, got {parts[1]}")
    seed = 0
    if len(parts) == 3:
        try:
            seed = int(parts[2])
        except ValueError:
            raise ValueError(f"terrain {t!r}: the seed {parts[2]!r} is not a whole number") from None
        if not 0 <= seed < 2**32:
            raise ValueError(f"terrain {t!r}: the seed must lie in [0, 2**32), got {seed}")
    return Terrain(kind, cm / 100.0, seed)


def _axis(lo: float, hi: float, step: float) -> np.ndarray:
    return np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)


@functools.lru_cache(maxsize=8)
def _rough_grid(height_m: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, ys = _axis(*ROUGH_X_M, HFIELD_RES_M), _axis(*ROUGH_Y_M, HFIELD_RES_M)
    cx, cy = _axis(*ROUGH_X_M, ROUGH_CELL_M), _axis(*ROUGH_Y_M, ROUGH_CELL_M)
    coarse = np.random.default_rng(seed).uniform(-1.0, 1.0, (cy.size, cx.size)) * height_m
    along_x = np.stack([np.interp(xs, cx, row) for row in coarse])  # (ny_coarse, nx)
    field = np.stack([np.interp(ys, cy, col) for col in along_x.T], axis=1)  # (ny, nx): bilinear
    dx = np.maximum(np.abs(xs)[None, :] - FLAT_START_HALF_M[0], 0.0)
    dy = np.maximum(np.abs(ys)[:, None] - FLAT_START_HALF_M[1], 0.0)
    ramp = np.minimum(np.hypot(dx, dy) / FLAT_RAMP_M, 1.0)
    field = field * (0.5 - 0.5 * np.cos(np.pi * ramp))
    for a in (xs, ys, field):
        a.setflags(write=False)
    return xs, ys, field


def rough_heights_m(terrain: Terrain) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(xs (nx,), ys (ny,), heights (ny, nx))`` of a rough terrain's height field, m (read-only)."""
    if terrain.kind != "rough":
        raise ValueError(f"terrain {terrain.text!r} is not rough")
    return _rough_grid(float(terrain.height_m), int(terrain.seed))


def stair_floor_m(terrain: Terrain) -> float:
    """Height of the floor plane under a staircase: 0 going up, the bottom of the last drop going down."""
    return min(0.0, STAIR_STEPS * terrain.height_m)


def stair_boxes(terrain: Terrain) -> list[tuple[float, float, float]]:
    """``(x_start, x_end, top)`` of each box standing on the floor plane, m: the steps going up; going down the
    start platform (from ``x = -2``) and the treads above the floor."""
    h, t, x0 = terrain.height_m, STAIR_TREAD_M, STAIR_START_X_M
    if h < 0:
        return [(-2.0, x0, 0.0)] + [(x0 + (k - 1) * t, x0 + k * t, k * h) for k in range(1, STAIR_STEPS)]
    out = []
    for k in range(STAIR_STEPS):
        end = x0 + (k + 1) * t if k < STAIR_STEPS - 1 else x0 + k * t + STAIR_LANDING_M
        out.append((x0 + k * t, end, (k + 1) * h))
    return out


def stair_edges(terrain: Terrain) -> tuple[tuple[float, float], ...]:
    """``(x, rise)`` of each stair edge, in +x: the height change there, m (> 0 up, < 0 down)."""
    return tuple((STAIR_START_X_M + k * STAIR_TREAD_M, terrain.height_m) for k in range(STAIR_STEPS))


def scene_parts(terrain: Terrain) -> dict:
    """Keyword arguments of :func:`mjx_coman.mjcf.scene_xml` for a terrain."""
    f = mjcf._fmt
    if terrain.kind == "flat":
        return {}
    if terrain.kind == "stairs":
        geoms, names = [], []
        floor = stair_floor_m(terrain)
        for k, (a, b, top) in enumerate(stair_boxes(terrain)):
            names.append(f"stair_{k}")
            half = (top - floor) / 2
            geoms.append(f'<geom name="stair_{k}" type="box" size="{f((b - a) / 2)} {f(STAIR_HALF_WIDTH_M)} {f(half)}" '
                         f'pos="{f((a + b) / 2)} 0 {f(floor + half)}" contype="0" conaffinity="0" '
                         f'rgba="0.7 0.7 0.65 1"/>')
        return dict(terrain_geoms=tuple(geoms), contact_geoms=tuple(names), floor_z_m=floor)
    xs, ys, _ = rough_heights_m(terrain)
    h = terrain.height_m
    rx, ry = (xs[-1] - xs[0]) / 2, (ys[-1] - ys[0]) / 2
    asset = (f'<hfield name="rough" nrow="{ys.size}" ncol="{xs.size}" '
             f'size="{f(rx)} {f(ry)} {f(2 * h)} {f(HFIELD_BASE_M)}"/>')
    geom = (f'<geom name="rough" type="hfield" hfield="rough" pos="{f((xs[0] + xs[-1]) / 2)} '
            f'{f((ys[0] + ys[-1]) / 2)} {f(-h)}" contype="0" conaffinity="0" rgba="0.6 0.65 0.55 1"/>')
    return dict(assets=(asset,), terrain_geoms=(geom,), contact_geoms=("rough",), floor_contacts=False,
                floor_z_m=-h - HFIELD_BASE_M - 0.01)


def variant_xml(terrain: str = "flat") -> str:
    """The scene MJCF of a variant: the gravity frame body, and the terrain (see the module docstring)."""
    t = parse_terrain(terrain)
    include = str(Path(mjcf.ASSETS_DIR) / "coman.xml")
    return mjcf.scene_xml(include, gravity_frame=True, **scene_parts(t))


@functools.lru_cache(maxsize=8)
def _compiled(terrain: str) -> mujoco.MjModel:
    t = parse_terrain(terrain)
    m = mujoco.MjModel.from_xml_string(variant_xml(t.text))
    if t.kind == "rough":
        # MuJoCo's height field: z = geom z + hfield_data * size[2], row r at y_r, column c at x_c.
        _, _, field = rough_heights_m(t)
        m.hfield_data[:] = ((field + t.height_m) / (2 * t.height_m)).ravel()
    return m


def scene_model(terrain: str = "flat") -> mujoco.MjModel:
    """A fresh ``MjModel`` of the scene variant (the robot, a gravity frame body and the terrain)."""
    return copy.copy(_compiled(parse_terrain(terrain).text))


def terrain_height_m(terrain: str, x, y):
    """Ground height under the points ``(x, y)``, m (jnp; ``0.0`` for ``flat``).

    Stairs: the top of the step box under the point, else the floor. Rough: bilinear interpolation of the height field's
    samples (MuJoCo triangulates each cell; the two differ by well under a millimetre on these fields).
    """
    t = parse_terrain(terrain)
    if t.kind == "flat":
        return 0.0
    x, y = jnp.asarray(x), jnp.asarray(y)
    if t.kind == "stairs":
        z = jnp.full_like(x, stair_floor_m(t))
        for a, b, top in stair_boxes(t):
            z = jnp.where((x >= a) & (x < b) & (jnp.abs(y) <= STAIR_HALF_WIDTH_M), top, z)
        return z
    xs, ys, field = rough_heights_m(t)
    fx = jnp.clip((x - xs[0]) / HFIELD_RES_M, 0.0, xs.size - 1.000001)
    fy = jnp.clip((y - ys[0]) / HFIELD_RES_M, 0.0, ys.size - 1.000001)
    i, j = jnp.floor(fx).astype(jnp.int32), jnp.floor(fy).astype(jnp.int32)
    u, v = fx - i, fy - j
    g = jnp.asarray(field, x.dtype)
    return ((1 - u) * (1 - v) * g[j, i] + u * (1 - v) * g[j, i + 1] + (1 - u) * v * g[j + 1, i]
            + u * v * g[j + 1, i + 1])
