"""Task-based whole-body QP (seeds 001 eq. 2 and 004 eq. 5-8): task accelerations to joint torques.

Each control tick, one QP on qpax turns soft task accelerations into joint-space accelerations, contact
forces and torques under the floating-base dynamics, stance contacts, friction pyramids and torque
limits. A controller builds a :class:`Plant` (plain arrays, e.g. ``plant_from(mjx_coman.dynamics.terms(m, d))``),
a list of :class:`Task` s from the builders of :mod:`mjx_coman.wbc.tasks` (or its own), and calls

    sol = wbc.solve(plant, tasks, contact_mask, tau_min_nm, tau_max_nm)   # sol.qdd, .forces, .tau, .info

Modules: :mod:`~mjx_coman.wbc.plant` (inputs), :mod:`~mjx_coman.wbc.tasks` (soft rows, PD laws),
:mod:`~mjx_coman.wbc.contacts` (stance and friction rows), :mod:`~mjx_coman.wbc.limits` (joint-acceleration
bounds from the joint limits), :mod:`~mjx_coman.wbc.qp` (assembly, export to a
reference solver), :mod:`~mjx_coman.wbc.solver` (qpax, diagnostics, fallback, derivatives, float32 or
float64: see there), :mod:`~mjx_coman.wbc.batching` (on CPU a loop over the batch: jaxlib 0.10.2's batched
LAPACK kernels deadlock), :mod:`~mjx_coman.wbc.reference` (plants from MuJoCo's C functions for tests).
"""

from mjx_coman.wbc.limits import joint_acc_bounds, joint_range_rad
from mjx_coman.wbc.plant import Plant, check_plant, plant_from
from mjx_coman.wbc.qp import QP, build_qp, export_qp, problem_size
from mjx_coman.wbc.solver import (
    WbcInfo,
    WbcSolution,
    fallback_torque,
    kkt_residual,
    qpax_solve,
    solution,
    solve,
    solve_qp,
)
from mjx_coman.wbc.tasks import (
    Task,
    com_task,
    foot_task,
    force_distribution_task,
    force_regularization,
    frame_velocity,
    joint_acc_task,
    joint_pd,
    momentum_rate_task,
    motion_task,
    null_space_task,
    orientation_error,
    orientation_pd,
    pelvis_orientation_task,
    position_pd,
    posture_task,
    qdd_regularization,
    torso_orientation_task,
)

__all__ = [
    "joint_acc_bounds", "joint_range_rad", "Plant", "check_plant", "plant_from", "QP", "build_qp", "export_qp",
    "problem_size", "WbcInfo",
    "WbcSolution", "fallback_torque", "kkt_residual", "qpax_solve", "solution", "solve", "solve_qp", "Task",
    "com_task", "foot_task",
    "force_distribution_task", "force_regularization", "frame_velocity", "joint_acc_task", "joint_pd",
    "momentum_rate_task", "motion_task", "null_space_task", "orientation_error", "orientation_pd",
    "pelvis_orientation_task", "position_pd", "posture_task", "qdd_regularization", "torso_orientation_task",
]
