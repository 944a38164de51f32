"""Settings and the config pytree of ``wbc-stand``: task gains and weights (tunable), plant and body (static)."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp

from mjx_coman.controllers.base import PLANTS, Setting
from mjx_coman.controllers.torque import stance_references
from mjx_coman.env import MID_FOOT_AHEAD_M

TUNABLE = ("imu_filter_s", "com_ahead_m", "com_kp_per_s2", "com_kd_per_s", "com_weight", "base_kp_per_s2", "base_kd_per_s", "base_weight",
           "posture_kp_per_s2", "posture_kd_per_s", "posture_weight", "qdd_weight", "force_weight_per_n2")

SETTINGS = (
    Setting("knee_rad", 0.4, "knee flexion of the crouched stance held"),
    Setting("plant", "torque-ideal", "torque-ideal or torque-sea: how the torques reach the joints"),
    Setting("fixed_upper_body", False, "waist and arms held by a joint PD outside the QP (seed 001)"),
    Setting("friction_coeff", 0.7, "design friction coefficient of the pyramids (the model's is 1)"),
    Setting("startup_s", 0.05, "torques ramp in linearly over this time from the reset (no contact force yet), s"),
    Setting("com_ahead_m", MID_FOOT_AHEAD_M, "CoM held this far ahead of the ankles, m (the sole centre: 0.03)",
            True, (-0.07, 0.13)),
    Setting("com_kp_per_s2", 30.0, "CoM task stiffness, 1/s^2", True, (0.0, None)),
    Setting("com_kd_per_s", 11.0, "CoM task damping, 1/s", True, (0.0, None)),
    Setting("com_weight", 10.0, "CoM task weight", True, (0.0, None)),
    Setting("base_kp_per_s2", 100.0, "pelvis and torso orientation stiffness, 1/s^2", True, (0.0, None)),
    Setting("base_kd_per_s", 20.0, "pelvis and torso orientation damping, 1/s", True, (0.0, None)),
    Setting("base_weight", 1.0, "pelvis and torso orientation weight", True, (0.0, None)),
    Setting("posture_kp_per_s2", 100.0, "joint posture stiffness, 1/s^2", True, (0.0, None)),
    Setting("posture_kd_per_s", 20.0, "joint posture damping, 1/s", True, (0.0, None)),
    Setting("posture_weight", 0.1, "joint posture weight", True, (0.0, None)),
    Setting("qdd_weight", 1e-3, "regularization of the accelerations", True, (0.0, None)),
    Setting("force_weight_per_n2", 1e-5, "regularization and distribution of the contact forces, 1/N^2", True,
            (0.0, None)),
    Setting("imu_filter_s", 0.05, "time constant of the complementary filter that corrects the gyro-propagated "
            "orientation toward the IMU's, s (0: the raw IMU)", True, (0.0, None)),
)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[*TUNABLE, "posture_rad", "com_ref_m", "sole_anchor_m"],
    meta_fields=["knee_rad", "plant", "fixed_upper_body", "friction_coeff", "startup_s", "dt_s"],
)
@dataclasses.dataclass(frozen=True)
class Config:
    """Tunables (array leaves, named as the settings), the references, and static choices."""

    imu_filter_s: jax.Array
    com_ahead_m: jax.Array
    com_kp_per_s2: jax.Array
    com_kd_per_s: jax.Array
    com_weight: jax.Array
    base_kp_per_s2: jax.Array
    base_kd_per_s: jax.Array
    base_weight: jax.Array
    posture_kp_per_s2: jax.Array
    posture_kd_per_s: jax.Array
    posture_weight: jax.Array
    qdd_weight: jax.Array
    force_weight_per_n2: jax.Array
    posture_rad: jax.Array  # (23,) the crouched stance
    com_ref_m: jax.Array  # (3,) the stance's CoM over the mid-ankles (x: + com_ahead_m), at its height
    sole_anchor_m: jax.Array  # (2, 3) right and left sole sites at the reset
    knee_rad: float
    plant: str
    fixed_upper_body: bool
    friction_coeff: float
    startup_s: float
    dt_s: float = 0.002

    def replace(self, **kw) -> "Config":
        return dataclasses.replace(self, **kw)


def make_config(knee_rad: float = 0.4, plant: str = "torque-ideal", fixed_upper_body: bool = False,
                friction_coeff: float = 0.7, startup_s: float = 0.05, **tunables) -> Config:
    """A validated config (host).

    Raises:
        ValueError: an unknown plant or setting, a knee outside [0.1, 1.2] rad, a friction
            coefficient outside (0, 2], a start-up outside [0, 1] s, a negative or non-finite gain or weight.
    """
    unknown = [k for k in tunables if k not in TUNABLE]
    if unknown:
        raise ValueError(f"unknown setting {unknown[0]!r} of wbc-stand")
    if plant not in PLANTS or plant == "position":
        raise ValueError(f"plant={plant!r} must be torque-ideal or torque-sea")
    if not (isinstance(knee_rad, (int, float)) and 0.1 <= knee_rad <= 1.2):
        raise ValueError(f"knee_rad={knee_rad!r} must lie in [0.1, 1.2]")
    if not (isinstance(friction_coeff, (int, float)) and 0.0 < friction_coeff <= 2.0):
        raise ValueError(f"friction_coeff={friction_coeff!r} must lie in (0, 2]")
    if isinstance(startup_s, bool) or not (isinstance(startup_s, (int, float)) and 0.0 <= startup_s <= 1.0):
        raise ValueError(f"startup_s={startup_s!r} must lie in [0, 1] s")
    if not isinstance(fixed_upper_body, bool):
        raise ValueError(f"fixed_upper_body={fixed_upper_body!r} must be true or false")
    values = {s.name: s.default for s in SETTINGS if s.tunable} | tunables
    for name, v in values.items():
        if isinstance(v, jax.core.Tracer):
            continue
        if name == "com_ahead_m":
            if not (math.isfinite(float(v)) and -0.07 <= float(v) <= 0.13):
                raise ValueError(f"com_ahead_m={v!r} must lie in the sole, [-0.07, 0.13] m")
        elif not (math.isfinite(float(v)) and float(v) >= 0.0):
            raise ValueError(f"{name}={v!r} must be finite and non-negative")
    f = jnp.result_type(float)
    q, com, soles = stance_references(float(knee_rad))
    return Config(**{k: jnp.asarray(v, f) for k, v in values.items()}, posture_rad=jnp.asarray(q, f),
                  com_ref_m=jnp.asarray(com, f), sole_anchor_m=jnp.asarray(soles, f), knee_rad=float(knee_rad),
                  plant=plant, fixed_upper_body=fixed_upper_body, friction_coeff=float(friction_coeff),
                  startup_s=float(startup_s))
