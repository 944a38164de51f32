"""The environment of each controller's plant: seed 000's position loops for walking, seed 001's torque loops."""

from __future__ import annotations

import math

from mjx_coman import env as env_mod
from mjx_coman.actuators import JOINT_INDEX, default_kp_v_per_rad, make_actuator_params

WALKING_ANKLE_ROLL_KP_V_PER_RAD = 100.0


def walking_env_params(ankle_roll_kp_v_per_rad: float = WALKING_ANKLE_ROLL_KP_V_PER_RAD,
                       **actuator_kwargs) -> env_mod.EnvParams:
    """Environment parameters for walking: the seed's gains except a stiffer ankle roll loop.

    The seed sets the ankle roll gain "to a small value" (10 V/rad, eq. 25) so
    the foot settles on the floor. On the simulated robot that ankle (22 N m/rad
    through the motor) leaves the single-support body free to topple sideways
    over its soft ankle roll, and every in-place walk tried with it fell
    sideways within 2.5 s; 100 V/rad (and 500) walked. Other gains follow
    :func:`mjx_coman.actuators.default_kp_v_per_rad`.

    Args:
        ankle_roll_kp_v_per_rad: ankle roll position gain, V/rad (> 0).
        **actuator_kwargs: passed to :func:`mjx_coman.actuators.make_actuator_params`
            (``kp_v_per_rad`` there overrides the gains, ankle roll included).

    Raises:
        ValueError: a non-positive gain (and what ``make_actuator_params`` rejects).
    """
    if not (math.isfinite(ankle_roll_kp_v_per_rad) and ankle_roll_kp_v_per_rad > 0):
        raise ValueError(f"ankle_roll_kp_v_per_rad={ankle_roll_kp_v_per_rad!r} must be finite and positive")
    if "kp_v_per_rad" not in actuator_kwargs:
        kp = default_kp_v_per_rad()
        for side in "RL":
            kp[JOINT_INDEX[side + "AnkLat"]] = ankle_roll_kp_v_per_rad
        actuator_kwargs["kp_v_per_rad"] = kp
    return env_mod.make_env_params(actuator=make_actuator_params(**actuator_kwargs))


SEA_TORQUE_DELAY_S = 0.010  # motor-board link delay under the series-elastic torque loop (seed 001: 10 ms)


def plant_env_params(plant: str = "position", **actuator_kwargs) -> env_mod.EnvParams:
    """Environment parameters for a controller's plant (``Gait.plant``).

    * ``"position"``: :func:`walking_env_params` (seed 000's position loops, 20 ms delay);
    * ``"torque-ideal"``: torques reach the links at once and exactly, within the
      motor's limits (seed 001's simulation); no transport delay;
    * ``"torque-sea"``: the series-elastic torque loop at 10 Hz, critically damped,
      behind a 10 ms transport delay.

    Args:
        **actuator_kwargs: override :func:`mjx_coman.actuators.make_actuator_params` values.

    Raises:
        ValueError: an unknown plant (naming the known ones) and bad actuator values.
    """
    from mjx_coman.controllers.base import PLANTS

    if plant not in PLANTS:
        raise ValueError(f"plant={plant!r} is not one of {', '.join(PLANTS)}")
    if plant == "position":
        return walking_env_params(**actuator_kwargs)
    defaults = dict(torque_loop="ideal", delay_s=0.0) if plant == "torque-ideal" else dict(
        torque_loop="sea", delay_s=SEA_TORQUE_DELAY_S)
    return env_mod.make_env_params(actuator=make_actuator_params(**{**defaults, **actuator_kwargs}))
