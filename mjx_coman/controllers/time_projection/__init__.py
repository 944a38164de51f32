"""Position-controlled 3LP walking on the simulated COMAN (seed 000, "COMAN Implementation")."""

from mjx_coman.walking.open_loop import (
    CartesianTargets,
    cartesian_targets,
    command_voltages,
    crouched_pelvis_height_m,
    hip_switch_gamma,
    hip_voltage,
    joint_targets,
    knee_compensation,
    position_voltage,
    targets_from_state,
)
from mjx_coman.walking.controller import (
    CONTROLLERS,
    ControllerParams,
    ControllerState,
    make_controller_params,
)
from mjx_coman.walking.rollout import (
    WalkPush,
    WalkResult,
    WalkSpec,
    WalkTrace,
    batched_walk,
    jit_walk,
    make_push,
    no_push,
    walk,
    walking_env_params,
)

__all__ = [
    "CONTROLLERS",
    "CartesianTargets",
    "ControllerParams",
    "ControllerState",
    "WalkPush",
    "WalkResult",
    "WalkSpec",
    "WalkTrace",
    "batched_walk",
    "cartesian_targets",
    "command_voltages",
    "crouched_pelvis_height_m",
    "hip_switch_gamma",
    "hip_voltage",
    "jit_walk",
    "joint_targets",
    "knee_compensation",
    "make_controller_params",
    "make_push",
    "no_push",
    "position_voltage",
    "targets_from_state",
    "walk",
    "walking_env_params",
]
