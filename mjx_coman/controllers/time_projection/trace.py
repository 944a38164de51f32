"""What to record of a time-projection walk: a save function of the rollout state (``SaveAt(trace)``).

:func:`trace` reads the controller's telemetry (error, phase sign,
adjustment), the sensors, and, beside the measured relative positions, their
ground truth from the simulator, so that a test or a plot can hold the
estimate against the truth (:func:`mjx_coman.rollout.walk`,
``save=SaveAt(trace, every)``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_coman.controllers.time_projection import estimation as est
from mjx_coman.sensors import model_ids


class Trace(NamedTuple):
    """Signals of one record.

    Attributes:
        error: (4,) filtered sagittal error ``[e1, e2, e1_dot, e2_dot]`` (eq. 15), before the dead-zone.
        adjustment_m: footstep adjustment applied.
        d: phase sign.
        measured_rel_m: (2, 2) relative positions from encoders + IMU (unfiltered).
        true_rel_m: (2, 2) the same from the simulator's true poses.
        knee_deflection_rad: (2,) knee spring deflection link - motor (left, right), from the encoders.
        foot_force_n: (2,) foot normal forces (left, right), N.
        pelvis_rpy_rad: (3,) IMU roll, pitch, yaw of the pelvis, rad.
        target_rad: (23,) motor position targets sent at the recorded tick (before the delay).
        link_angle_rad: (23,) link encoder readings, rad.
        pelvis_m: (3,) pelvis position, world.
    """

    error: jax.Array
    adjustment_m: jax.Array
    d: jax.Array
    measured_rel_m: jax.Array
    true_rel_m: jax.Array
    knee_deflection_rad: jax.Array
    foot_force_n: jax.Array
    pelvis_rpy_rad: jax.Array
    target_rad: jax.Array
    link_angle_rad: jax.Array
    pelvis_m: jax.Array


def trace(state) -> Trace:
    """The :class:`Trace` of a :class:`mjx_coman.rollout.RolloutState` of a time-projection walk."""
    e, x = state.env, state.telemetry.extra
    ids = model_ids()
    force = e.readings.foot_normal_force_n
    return Trace(
        error=x.error[0], adjustment_m=x.adjustment_m, d=x.d,
        measured_rel_m=est.measure_relative(e.readings, x.d), true_rel_m=est.true_relative(e.data, x.d),
        knee_deflection_rad=est.knee_deflection_rad(e.readings), foot_force_n=jnp.stack([force[1], force[0]]),
        pelvis_rpy_rad=e.readings.imu_rpy_rad, target_rad=state.command.target,
        link_angle_rad=e.readings.link_angle_rad, pelvis_m=e.data.xpos[ids["pelvis_body"]],
    )
