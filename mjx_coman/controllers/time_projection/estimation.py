"""State estimation of the walking COMAN (seed 000, "State Estimation", eq. 15, 26).

Measurement. The link (post-spring) encoders of both legs and the pelvis IMU
orientation give, by forward kinematics, the vectors from the pelvis point to
both foot points in the heading frame (world z up, x along the pelvis
heading; :func:`mjx_coman.kinematics.feet_in_frame`). The seed "solely
relies on the pelvis IMU" for the orientation and does not build the chain up
from a flat stance foot; neither does this module.

3LP frame. Per horizontal axis (0 sagittal x, 1 lateral y) the state is the
pair ``[s1, s2]``: swing foot minus stance foot and pelvis minus stance foot
(seed 000, Figure 1), positions in m; ``d = +1`` is a left-swing phase (the
right foot stands), ``d = -1`` a right-swing phase. Arrays of relative
positions are (2 axes, 2) = ``[[s1_x, s2_x], [s1_y, s2_y]]``.

Filtering. Positions pass the IIR filter of eq. 26 (``zeta = 0.1`` per 2 ms
tick); velocities are the differences of the filtered positions averaged over
the last 30 ticks (:mod:`jaxlp.filters`). At a phase change the filter
memory is carried into the new stance frame (:func:`estimator_swap`), so the
swap is no jump for the filter.

Error. ``e = M (q - q_bar)`` (eq. 15): per axis ``[e1, e2, e1_dot, e2_dot]``,
the filtered state minus the nominal 3LP gait at the same phase time, the
lateral axis mirrored into the ``d = +1`` frame (as :mod:`jaxlp.simulate`).

All functions are pure and vmappable; nothing is jitted here.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp import filters
from mjx_coman.actuators import JOINT_INDEX
from mjx_coman.kinematics import FOOT_POINT_OFFSET_M, feet_in_frame, quat_to_rot, rot_z
from mjx_coman.sensors import Readings, model_ids
from mjx_coman.controllers.time_projection.open_loop import LEFT_LEG, RIGHT_LEG

LEFT_KNEE = JOINT_INDEX["LKneeSag"]
RIGHT_KNEE = JOINT_INDEX["RKneeSag"]
VELOCITY_WINDOW = 30  # samples of the velocity moving average (seed 000, "State Estimation")


class Estimate(NamedTuple):
    """One tick of the estimator's output.

    Attributes:
        raw_m: (2, 2) measured relative positions ``[[s1_x, s2_x], [s1_y, s2_y]]`` before filtering, m.
        pos_m: (2, 2) IIR-filtered relative positions (eq. 26), m.
        vel_mps: (2, 2) their velocities (difference + moving average), m/s.
        error: (2, 4) error against the nominal gait per axis ``[e1, e2, e1_dot, e2_dot]``
            (eq. 15), lateral axis mirrored into the ``d = +1`` frame.
    """

    raw_m: jax.Array
    pos_m: jax.Array
    vel_mps: jax.Array
    error: jax.Array


def relative_from_feet(left_m: jax.Array, right_m: jax.Array, d) -> jax.Array:
    """3LP relative positions from the pelvis-to-foot vectors of both legs.

    Args:
        left_m, right_m: (3,) pelvis point -> foot point, heading frame, m.
        d: phase sign, +1 left swing (right stance), -1 right swing.

    Returns:
        (2, 2) ``[[s1_x, s2_x], [s1_y, s2_y]]``: ``s1 = swing - stance``,
        ``s2 = pelvis - stance`` (horizontal components), m.
    """
    left_swing = jnp.asarray(d) > 0
    swing = jnp.where(left_swing, left_m, right_m)
    stance = jnp.where(left_swing, right_m, left_m)
    s1 = (swing - stance)[:2]
    s2 = -stance[:2]
    return jnp.stack([s1, s2], axis=-1)


def measure_feet(readings: Readings) -> tuple[jax.Array, jax.Array]:
    """Pelvis-to-foot-point vectors (left, right) in the heading frame from link encoders and the IMU."""
    q = readings.link_angle_rad
    feet = feet_in_frame(readings.imu_quat, q[LEFT_LEG], q[RIGHT_LEG], yaw_free=True)
    return feet.foot_point_m[0], feet.foot_point_m[1]


def measure_relative(readings: Readings, d) -> jax.Array:
    """(2, 2) measured 3LP relative positions of one tick (see :func:`relative_from_feet`)."""
    left, right = measure_feet(readings)
    return relative_from_feet(left, right, d)


def true_feet(data, foot_body_ids: tuple[int, int], pelvis_body_id: int) -> tuple[jax.Array, jax.Array]:
    """Ground truth of :func:`measure_feet` from the simulator (``mjx.Data``).

    The foot point is 3 cm ahead of the ankle centre in the foot body frame
    (the foot body's origin is the ankle centre), the pelvis point the pelvis
    body origin; the vectors are rotated into the heading frame of the true
    pelvis orientation.

    Args:
        data: ``mjx.Data`` after kinematics.
        foot_body_ids: MuJoCo ids of the (left, right) foot bodies.
        pelvis_body_id: id of the pelvis (Waist) body.

    Returns:
        ``(left_m (3,), right_m (3,))``.
    """
    rot = quat_to_rot(jnp.asarray(data.xquat[pelvis_body_id]))
    yaw = jnp.arctan2(rot[1, 0], rot[0, 0])
    to_heading = rot_z(-yaw)
    pelvis = jnp.asarray(data.xpos[pelvis_body_id])
    offset = jnp.asarray(FOOT_POINT_OFFSET_M, pelvis.dtype)
    out = []
    for b in foot_body_ids:
        foot = jnp.asarray(data.xpos[b]) + jnp.asarray(data.xmat[b]).reshape(3, 3) @ offset
        out.append(to_heading @ (foot - pelvis))
    return out[0], out[1]


def true_relative(data, d) -> jax.Array:
    """(2, 2) true 3LP relative positions from the simulator (``mjx.Data``): :func:`measure_relative`'s truth."""
    ids = model_ids()
    return relative_from_feet(*true_feet(data, (ids["l_foot_body"], ids["r_foot_body"]), ids["pelvis_body"]), d)


def estimator_init(window: int = VELOCITY_WINDOW, dtype=jnp.float32) -> filters.FilterState:
    """Empty filter memory for the (2, 2) relative positions and a ``window``-sample velocity average."""
    return filters.filter_init((2, 2), window, dtype)


def nominal_relative(q_nominal: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(2, 2) positions and velocities ``[s1, s2]`` per axis of a 3LP state ``(2, 6)`` ``[s, p, a, sd, pd, ad]``."""
    pos = jnp.stack([q_nominal[:, 0] - q_nominal[:, 2], q_nominal[:, 1] - q_nominal[:, 2]], axis=-1)
    vel = jnp.stack([q_nominal[:, 3] - q_nominal[:, 5], q_nominal[:, 4] - q_nominal[:, 5]], axis=-1)
    return pos, vel


def nominal_error(pos_m, vel_mps, q_nominal, d) -> jax.Array:
    """Error against the nominal gait (seed 000, eq. 15), (2, 4) per axis ``[e1, e2, e1_dot, e2_dot]``.

    Args:
        pos_m, vel_mps: (2, 2) filtered relative positions and velocities.
        q_nominal: (2, 6) nominal 3LP state at this phase time, in the frame of
            the current phase (lateral axis already signed by ``d``).
        d: phase sign; the lateral error is multiplied by ``d`` so that it is
            expressed in the ``d = +1`` frame of the gain tables.
    """
    nom_pos, nom_vel = nominal_relative(q_nominal)
    sign = jnp.stack([jnp.ones_like(jnp.asarray(d, pos_m.dtype)), jnp.asarray(d, pos_m.dtype)])
    return jnp.concatenate([pos_m - nom_pos, vel_mps - nom_vel], axis=-1) * sign[:, None]


def estimator_step(state: filters.FilterState, raw_m, q_nominal, d, zeta, dt_s
                   ) -> tuple[filters.FilterState, Estimate]:
    """One tick: IIR filter (eq. 26), velocities, error (eq. 15).

    Args:
        state: filter memory (:func:`estimator_init`), in the current stance frame.
        raw_m: (2, 2) measured relative positions (:func:`measure_relative`).
        q_nominal: (2, 6) nominal 3LP state of this tick (lateral signed by ``d``).
        d: phase sign.
        zeta: IIR constant per tick.
        dt_s: control tick, s.

    Returns:
        The new filter memory and the :class:`Estimate`.
    """
    state, pos, vel = filters.filter_step(state, raw_m, zeta, dt_s)
    return state, Estimate(raw_m, pos, vel, nominal_error(pos, vel, q_nominal, d))


LANDED_VELOCITY_SWAP = jnp.array([[0.0, 0.0], [0.0, 1.0]])


def estimator_swap(state: filters.FilterState) -> filters.FilterState:
    """Carry the filter memory into the next phase's stance frame.

    Positions transform exactly (``s1' = -s1``, ``s2' = s2 - s1``,
    :data:`jaxlp.filters.SWAP_RELATIVE`). The velocity memory holds the last
    ``window`` differences, taken while the landing foot was still moving in
    the old frame; transforming them like the positions (as
    :func:`jaxlp.filters.filter_swap` does, exact for the 3LP whose swing foot
    lands at rest) would carry that stale swing velocity into the new
    ``s2_dot`` and ``s1_dot``. With both feet on the ground at the phase
    change, the feet are at rest relative to each other and the pelvis moves
    relative to the new stance foot as it did relative to the old one, so the
    memory becomes ``s1_dot' = 0``, ``s2_dot' = s2_dot``.
    """
    return state._replace(
        position=state.position @ filters.SWAP_RELATIVE.T,
        diffs=state.diffs @ LANDED_VELOCITY_SWAP.T,
    )


def knee_deflection_rad(readings: Readings) -> jax.Array:
    """(2,) knee spring deflections ``link - motor`` (left, right), rad (> 0 when a loaded knee yields)."""
    defl = readings.link_angle_rad - readings.motor_angle_rad
    return jnp.stack([defl[LEFT_KNEE], defl[RIGHT_KNEE]])
