"""Example family: stands still by joint-space PD on the motor encoders (the README's ten-line controller).

The motor targets are the crouched posture plus ``gain`` times the motors'
error from it, less ``damping_s`` times the motor velocity; the motor boards
close their position loop on them (eq. 25), so the stiffness is ``(1 + gain)``
times the board's and ``damping_s`` adds damping. It plans no step.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp

from mjx_coman.controllers.base import Controller, Gait, Setting, standing_telemetry
from mjx_coman.env import MODE_POSITION, Command, standing_posture


@functools.partial(jax.tree_util.register_dataclass, data_fields=["posture_rad", "gain", "damping_s"],
                   meta_fields=["knee_rad"])
@dataclasses.dataclass(frozen=True)
class Config:
    posture_rad: jax.Array  # (23,) the crouched posture held
    gain: jax.Array  # extra position feedback on top of the motor loop
    damping_s: jax.Array  # motor-velocity feedback, s
    knee_rad: float

    def replace(self, **kw) -> "Config":
        return dataclasses.replace(self, **kw)


def make_config(knee_rad: float = 0.4, gain: float = 0.5, damping_s: float = 0.01) -> Config:
    for name, v, hi in (("knee_rad", knee_rad, 1.5), ("gain", gain, 2.0), ("damping_s", damping_s, 0.1)):
        if not 0.0 <= float(v) <= hi:
            raise ValueError(f"{name}={v!r} must lie in [0, {hi:g}]")
    f = jnp.result_type(float)
    return Config(jnp.asarray(standing_posture(float(knee_rad))[0], f), jnp.asarray(gain, f),
                  jnp.asarray(damping_s, f), float(knee_rad))


def step(config: Config, state, obs):
    r = obs.readings
    target = config.posture_rad + config.gain * (config.posture_rad - r.motor_angle_rad) \
        - config.damping_s * r.motor_vel_rad_per_s
    dtype = r.motor_angle_rad.dtype
    return state, Command(target.astype(dtype), jnp.zeros(3, dtype), jnp.asarray(MODE_POSITION, jnp.int32)), standing_telemetry(dtype)


CONTROLLER = Controller(
    name="joint-pd", make_config=make_config, init=lambda config, env_params, key: (), step=step,
    gait=lambda c: Gait(knee_rad=c.knee_rad, control_period_s=0.002, first_step_s=0.0, step_time_s=0.4,
                        max_forward_mps=0.0),
    settings=(Setting("knee_rad", 0.4, "knee flexion of the crouched posture held"),
              Setting("gain", 0.5, "extra position feedback on top of the motor loop", True, (0.0, 2.0)),
              Setting("damping_s", 0.01, "motor-velocity feedback, s", True, (0.0, 0.1))),
    description="example: stands still by joint-space PD on the motor encoders",
)
