"""What the simulator says a walk did: falls, touchdowns, CoM steps, recovery; one definition for every controller.

Nothing here reads a controller's state or estimate. From ``mjx.Data``:

* **Fall**: the pelvis lower than ``fall_height_m`` above the ground under
  it (the floor, or the judge's ``terrain``: :func:`mjx_coman.scenarios.terrain_height_m`),
  tilted more than ``max_tilt_rad`` from gravity's vertical (the world z
  axis, or a scene variant's gravity frame on a slope), or a non-finite state.
* **Contact**: a foot is loaded when its true normal force (MJX's solved
  contact forces, :func:`mjx_coman.sensors.foot_wrenches`) exceeds
  ``contact_n``. A **touchdown** is a foot becoming loaded after at least
  ``min_air_s`` unloaded; each is logged with its time, the whole-body CoM
  (``subtree_com`` of the world body), the landing foot point and the pelvis.
* **Step velocity**: the CoM displacement from one touchdown to the next
  over their time apart, in the heading frame of the pelvis at the first,
  its lateral component mirrored for a right-foot landing (a symmetric
  periodic gait then has one step velocity, not two alternating ones).
* **Cycle**: the limit cycle the walk ends in: the mean step velocity of
  its last ``cycle_steps`` steps. An unpushed walk of a controller with
  one stable gait ends in that gait's limit cycle, and so does a pushed walk
  that recovered; sweeps report how far the pushed walks' cycles lie from the
  unpushed ones' (``cycle_velocity_mps``).
* **Recovered after k steps** (``steps_to_recover = k``): counting the
  touchdowns after the push ends (the first is 1), k is the first from which
  every step velocity to the end of the walk lies within ``recover_tol_mps``
  (Euclidean) of the cycle, at least ``confirm_steps`` steps in a row (so a
  walk still drifting when it ends is not called recovered). It is ``0`` for
  an unpushed walk that did not fall, and ``-1`` for a walk that fell, never
  settled or ended too soon to tell. Pushes during a controller's start-up
  transient count the transient too: push after it has settled.
* **Mean speed**: the forward CoM velocity (heading frame) from the middle
  touchdown to the last (at least two steps apart; 0 otherwise).

All functions are pure and vmappable.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman.kinematics import FOOT_POINT_OFFSET_M, quat_to_rot
from mjx_coman.scenarios.terrain import parse_terrain, terrain_height_m
from mjx_coman.sensors import foot_wrenches, gravity_frame_quat, model_ids

LEFT, RIGHT = 0, 1


class Judge(NamedTuple):
    """Thresholds of the verdict (static; plain values).

    Attributes:
        fall_height_m: a pelvis lower than this above the floor is a fall, m.
        max_tilt_rad: a pelvis tilted further from upright is a fall, rad.
        contact_n: normal force above which a foot is loaded, N (COMAN weighs about 310 N).
        min_air_s: unloaded time before a loading counts as a touchdown, s.
        recover_tol_mps: largest step-velocity difference from the cycle that counts as recovered, m/s.
        cycle_steps: last steps of the walk averaged into its cycle.
        confirm_steps: steps in a row within the tolerance needed to call a walk recovered (the cycle's included).
        terrain: the ground the height is measured from (``flat``, ``rough:CM[:SEED]``, ``stairs:CM``:
            :func:`judge_on` sets the scene's).
    """

    fall_height_m: float = 0.3
    max_tilt_rad: float = 0.8
    contact_n: float = 30.0
    min_air_s: float = 0.1
    recover_tol_mps: float = 0.05
    cycle_steps: int = 2
    confirm_steps: int = 4
    terrain: str = "flat"

    def validate(self) -> "Judge":
        for name in ("fall_height_m", "max_tilt_rad", "contact_n", "min_air_s", "recover_tol_mps"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} must be a finite positive number")
        for name in ("cycle_steps", "confirm_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValueError(f"{name}={v!r} must be a positive whole number")
        if parse_terrain(self.terrain).text != self.terrain:
            raise ValueError(f"terrain={self.terrain!r} must be written {parse_terrain(self.terrain).text!r}")
        return self

    def max_touchdowns(self, seconds: float) -> int:
        """A bound on the touchdowns of a walk (each foot needs ``min_air_s`` between two)."""
        return 2 * int(math.ceil(seconds / self.min_air_s)) + 2


class Touchdowns(NamedTuple):
    """The touchdown log (leading axis: ``max_touchdowns``; rows past ``count`` are NaN, foot -1).

    Attributes:
        count: touchdowns logged (int32).
        time_s: when, s.
        foot: which foot landed (:data:`LEFT` or :data:`RIGHT`).
        com_m: (n, 3) whole-body CoM, world frame.
        foot_m: (n, 3) the landing foot point (ankle axis, 3 cm ahead of the ankle centre), world.
        other_foot_m: (n, 3) the other foot point, world.
        pelvis_m: (n, 3) pelvis (Waist origin), world.
        yaw_rad: (n,) pelvis heading.
    """

    count: jax.Array
    time_s: jax.Array
    foot: jax.Array
    com_m: jax.Array
    foot_m: jax.Array
    other_foot_m: jax.Array
    pelvis_m: jax.Array
    yaw_rad: jax.Array


class JudgeState(NamedTuple):
    """Per-walk memory: how long each foot (left, right) has been unloaded, and the log."""

    air_s: jax.Array
    log: Touchdowns


class Verdict(NamedTuple):
    """The walk's outcome besides the fall (see the module docstring).

    Attributes:
        steps_to_recover: int32 (0 unpushed, -1 fell or not recovered).
        mean_speed_mps: forward CoM speed over the last half of the touchdowns.
        step_velocity_mps: (n, 2) step velocities (row k: touchdown k-1 to k; NaN where none).
        cycle_velocity_mps: (2,) the cycle the walk ends in (NaN with fewer than ``cycle_steps`` steps).
    """

    steps_to_recover: jax.Array
    mean_speed_mps: jax.Array
    step_velocity_mps: jax.Array
    cycle_velocity_mps: jax.Array


@functools.lru_cache(maxsize=1)
def judge_on(terrain, judge: Judge | None = None) -> Judge:
    """The fall judge on a terrain (its text, or anything with a ``terrain`` field such as a
    :class:`~mjx_coman.scenarios.Scenario`), with ``judge``'s thresholds (default :class:`Judge`)."""
    terrain = getattr(terrain, "terrain", terrain)
    return (judge or Judge())._replace(terrain=parse_terrain(terrain).text)


def foot_body_ids() -> tuple[int, int]:
    """MuJoCo ids of the (left, right) foot bodies (their origin is the ankle centre)."""
    ids = model_ids()
    return ids["l_foot_body"], ids["r_foot_body"]


def foot_points_world(data) -> jax.Array:
    """(2, 3) world positions of the (left, right) foot points."""
    xpos, xmat = jnp.asarray(data.xpos), jnp.asarray(data.xmat)
    offset = jnp.asarray(FOOT_POINT_OFFSET_M, xpos.dtype)
    return jnp.stack([xpos[b] + xmat[b].reshape(3, 3) @ offset for b in foot_body_ids()])


def pelvis_m(data) -> jax.Array:
    """(3,) pelvis (Waist origin) position, world."""
    return data.xpos[model_ids()["pelvis_body"]]


def com_m(data) -> jax.Array:
    """(3,) whole-body centre of mass, world."""
    return data.subtree_com[0]


def pelvis_yaw_rad(data) -> jax.Array:
    rot = quat_to_rot(data.xquat[model_ids()["pelvis_body"]])
    return jnp.arctan2(rot[1, 0], rot[0, 0])


def tilt_rad(data) -> jax.Array:
    """Angle between the pelvis z axis and the vertical (against gravity: a scene variant's gravity frame z)."""
    rot = quat_to_rot(data.xquat[model_ids()["pelvis_body"]])
    g = gravity_frame_quat(data)
    cos = rot[2, 2] if g is None else jnp.dot(rot[:, 2], quat_to_rot(g)[:, 2])
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))


def pelvis_height_m(data, judge: Judge) -> jax.Array:
    """Pelvis height above the ground under it (the judge's terrain), m."""
    p = pelvis_m(data)
    return p[2] - terrain_height_m(judge.terrain, p[0], p[1])


def fallen(data, judge: Judge) -> jax.Array:
    """The pelvis is too low or too tilted (non-finite states are the rollout's to catch)."""
    return (pelvis_height_m(data, judge) < judge.fall_height_m) | (tilt_rad(data) > judge.max_tilt_rad)


def foot_loads_n(data) -> jax.Array:
    """(2,) true normal forces on the (left, right) feet, N."""
    _, _, normal = foot_wrenches(data)  # (right, left)
    return jnp.stack([normal[1], normal[0]])


def support_point(data) -> jax.Array:
    """(3,) the feet points weighted by their true normal loads (the stance foot in single support), world."""
    w = jnp.maximum(foot_loads_n(data), 0.0)
    feet = foot_points_world(data)
    return (w[:, None] * feet).sum(0) / jnp.maximum(w.sum(), 1e-6)


def init(judge: Judge, seconds: float, dtype) -> JudgeState:
    """Both feet down, nothing logged."""
    n = judge.max_touchdowns(seconds)
    nan = lambda *shape: jnp.full(shape, jnp.nan, dtype)  # noqa: E731
    log = Touchdowns(count=jnp.zeros((), jnp.int32), time_s=nan(n), foot=jnp.full(n, -1, jnp.int32),
                     com_m=nan(n, 3), foot_m=nan(n, 3), other_foot_m=nan(n, 3), pelvis_m=nan(n, 3), yaw_rad=nan(n))
    return JudgeState(air_s=jnp.zeros(2, dtype), log=log)


def update(state: JudgeState, data, time_s, dt_s, judge: Judge) -> JudgeState:
    """Log the touchdowns of this tick (``data`` after the tick, ``time_s`` its end)."""
    loaded = foot_loads_n(data) > judge.contact_n
    landed = loaded & (state.air_s >= judge.min_air_s)
    feet = foot_points_world(data)
    log = state.log
    n = log.time_s.shape[0]
    for foot in (LEFT, RIGHT):
        i = jnp.minimum(log.count, n - 1)
        put = lambda arr, v: jnp.where(landed[foot], arr.at[i].set(v), arr)  # noqa: E731
        log = Touchdowns(
            count=log.count + landed[foot].astype(jnp.int32), time_s=put(log.time_s, time_s),
            foot=put(log.foot, foot), com_m=put(log.com_m, com_m(data)), foot_m=put(log.foot_m, feet[foot]),
            other_foot_m=put(log.other_foot_m, feet[1 - foot]), pelvis_m=put(log.pelvis_m, pelvis_m(data)),
            yaw_rad=put(log.yaw_rad, pelvis_yaw_rad(data)),
        )
    air = jnp.where(loaded, 0.0, state.air_s + dt_s)
    return JudgeState(air_s=air.astype(state.air_s.dtype), log=log)


def step_velocities(log: Touchdowns) -> jax.Array:
    """(n, 2) mirrored heading-frame step velocities (row k: touchdown k-1 to k; NaN where none)."""
    dpos = log.com_m[1:, :2] - log.com_m[:-1, :2]
    dt = log.time_s[1:] - log.time_s[:-1]
    c, s = jnp.cos(log.yaw_rad[:-1]), jnp.sin(log.yaw_rad[:-1])
    fwd = (c * dpos[:, 0] + s * dpos[:, 1]) / dt
    lat = (-s * dpos[:, 0] + c * dpos[:, 1]) / dt * jnp.where(log.foot[1:] == RIGHT, -1.0, 1.0)
    k = jnp.arange(1, log.time_s.shape[0])
    v = jnp.where((k < log.count)[:, None], jnp.stack([fwd, lat], axis=1), jnp.nan)
    return jnp.concatenate([jnp.full((1, 2), jnp.nan, v.dtype), v])


def verdict(log: Touchdowns, push_end_s, pushed, fell, judge: Judge) -> Verdict:
    """Steps to recover, mean speed, step velocities and the final cycle (see the module docstring)."""
    n = log.time_s.shape[0]
    k = jnp.arange(n)
    v = step_velocities(log)
    valid = (k >= 1) & (k < log.count)
    cyc_rows = valid & (k >= log.count - judge.cycle_steps)
    n_cyc = jnp.sum(cyc_rows)
    cycle = jnp.sum(jnp.where(cyc_rows[:, None], v, 0.0), axis=0) / jnp.maximum(n_cyc, 1)
    cycle = jnp.where(n_cyc == judge.cycle_steps, cycle, jnp.nan)

    after = (k < log.count) & (log.time_s > push_end_s)
    k1 = jnp.min(jnp.where(after, k, n))  # the first touchdown after the push ends
    dist = jnp.linalg.norm(jnp.nan_to_num(v - cycle, nan=jnp.inf), axis=1)
    ok = jnp.where(valid, dist <= judge.recover_tol_mps, True)
    settled = jnp.flip(jnp.cumprod(jnp.flip(ok))).astype(bool)  # every step from k to the end is within
    enough = (log.count - k) >= judge.confirm_steps
    first = jnp.min(jnp.where(settled & enough & (k >= jnp.maximum(k1, 1)) & valid, k, n))
    recovered = (first < n) & ~fell
    s2r = jnp.where(pushed, jnp.where(recovered, first - k1 + 1, -1), jnp.where(fell, -1, 0)).astype(jnp.int32)

    c = log.count
    i0, i1 = c // 2, jnp.maximum(c - 1, 0)
    heading = jnp.stack([jnp.cos(log.yaw_rad[i0]), jnp.sin(log.yaw_rad[i0])])
    span = log.time_s[i1] - log.time_s[i0]
    speed = jnp.dot(log.com_m[i1, :2] - log.com_m[i0, :2], heading) / jnp.where(span > 0, span, 1.0)
    speed = jnp.where(i1 - i0 >= 2, speed, 0.0)
    return Verdict(steps_to_recover=s2r, mean_speed_mps=jnp.nan_to_num(speed), step_velocity_mps=v,
                   cycle_velocity_mps=cycle)
