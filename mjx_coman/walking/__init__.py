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
)

__all__ = [
    "CartesianTargets",
    "cartesian_targets",
    "command_voltages",
    "crouched_pelvis_height_m",
    "hip_switch_gamma",
    "hip_voltage",
    "joint_targets",
    "knee_compensation",
    "position_voltage",
]
