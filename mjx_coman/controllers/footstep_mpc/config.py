"""Settings and the config pytree of ``footstep-mpc``: planner weights, task gains and weights (tunable);
step timing, plant, solver and body (static)."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp

from mjx_coman.controllers.base import PLANTS, Setting
from mjx_coman.controllers.torque import stance_references

MPC_SOLVERS = ("closed-form", "qpax")
MAX_FORWARD_MPS = 0.4  # seed 001, Fig. 3: -0.2 .. 0.4 m/s
MAX_LATERAL_MPS = 0.1
MAX_TURN_RAD_PER_S = 0.6

TUNABLE = ("mpc_com_midpoint_weight", "mpc_com_step_weight", "mpc_footstep_weight", "mpc_footstep_step_weight",
           "half_width_m", "clearance_m", "com_height_kp_per_s2", "com_height_kd_per_s", "com_weight",
           "base_kp_per_s2", "base_kd_per_s", "base_weight", "swing_kp_per_s2", "swing_kd_per_s", "swing_weight",
           "posture_kp_per_s2", "posture_kd_per_s", "posture_weight", "qdd_weight", "force_weight_per_n2",
           "imu_filter_s", "shift_m", "touchdown_depth_m", "joystick_ramp_s",
           "encoder_filter_s")

SETTINGS = (
    Setting("step_time_s", 0.4, "duration of one single-support step, s (the seed does not state it; "
            "seed 000's T on COMAN)"),
    Setting("start_s", 0.6, "double support at the start, shifting the CoM toward the first stance foot, s"),
    Setting("double_support_s", 0.0, "the previous stance foot stays in contact this long into each step (the "
            "load moves over in the QP), then lifts; its swing takes the rest of the step, s"),
    Setting("knee_rad", 0.4, "knee flexion of the crouched stance the walk starts from"),
    Setting("plant", "torque-ideal", "torque-ideal or torque-sea: how the torques reach the joints"),
    Setting("fixed_upper_body", True, "waist and arms held by a joint PD outside the QP (seed 001)"),
    Setting("friction_coeff", 0.7, "design friction coefficient of the pyramids and the planner's bound"),
    Setting("startup_s", 0.05, "torques ramp in linearly over this time from the reset, s"),
    Setting("contact_slack_weight", 0.0, "0: hard stance rows (seed 001), an infeasible tick ends the walk as a "
            "failed solve; w > 0: the stance rows relaxed at a cost w |e|^2, per (m/s^2)^2 (mjx_coman.wbc.qp)"),
    Setting("qp_max_iter", 20, "interior-point iterations of each whole-body QP solve (static; qpax runs them all)"),
    Setting("qp_retry_iter", 0, "0: off; n: where the solve fails, the same QP stopped after n iterations "
            "(mjx_coman.wbc.solve_qp's retry: float32 breaks down late on some QPs), static"),
    Setting("n_steps", 5, "footsteps the MPC plans ahead (seed 001: N = 5)"),
    Setting("mpc_solver", "closed-form", "closed-form (equality-only, one linear solve) or qpax (with the "
            "friction bound |mu z0| on the CoM-to-foot distance)"),
    Setting("shift_m", 0.055, "CoM shift toward the first stance foot during the start, m", True, (0.0, 0.1)),
    Setting("mpc_com_midpoint_weight", 0.6, "Q_q of seed 001 eq. 16: step-average CoM on the midpoint path, 1/m^2",
            True, (0.0, None)),
    Setting("mpc_com_step_weight", 10.0, "Q_dq: CoM advance per step, 1/m^2", True, (0.0, None)),
    Setting("mpc_footstep_weight", 1.0, "Q_p: footsteps on the reference plan, 1/m^2", True, (0.0, None)),
    Setting("mpc_footstep_step_weight", 10.0, "Q_dp: footstep increments as the reference's, 1/m^2", True,
            (0.0, None)),
    Setting("half_width_m", 0.08, "d of seed 001 eq. 14-15: half the lateral distance of the feet, m", True,
            (0.05, 0.15)),
    Setting("clearance_m", 0.04, "swing-foot apex above the ground (eq. 8, normalized), m", True, (0.0, 0.15)),
    Setting("touchdown_depth_m", 0.005, "the swing foot's path ends this far below the ground: it lands before the "
            "fixed-time switch instead of hanging above the ground when the QP starts to load it, m", True,
            (0.0, 0.03)),
    Setting("com_height_kp_per_s2", 75.0, "CoM height PD stiffness, 1/s^2", True, (0.0, None)),
    Setting("com_height_kd_per_s", 17.32, "CoM height PD damping, 1/s", True, (0.0, None)),
    Setting("com_weight", 100.0, "CoM task weight (larger than the base's: seed 001, sec. II)", True, (0.0, None)),
    Setting("base_kp_per_s2", 100.0, "pelvis orientation stiffness, 1/s^2", True, (0.0, None)),
    Setting("base_kd_per_s", 20.0, "pelvis orientation damping, 1/s", True, (0.0, None)),
    Setting("base_weight", 1.5, "pelvis orientation weight", True, (0.0, None)),
    Setting("swing_kp_per_s2", 400.0, "swing-foot pose stiffness, 1/s^2", True, (0.0, None)),
    Setting("swing_kd_per_s", 40.0, "swing-foot pose damping, 1/s", True, (0.0, None)),
    Setting("swing_weight", 13.0, "swing-foot task weight", True, (0.0, None)),
    Setting("posture_kp_per_s2", 100.0, "joint posture stiffness (and the fixed upper body's PD), 1/s^2", True,
            (0.0, None)),
    Setting("posture_kd_per_s", 20.0, "joint posture damping, 1/s", True, (0.0, None)),
    Setting("posture_weight", 0.01, "joint posture weight (the legs' null space)", True, (0.0, None)),
    Setting("qdd_weight", 1e-4, "regularization of the accelerations", True, (0.0, None)),
    Setting("force_weight_per_n2", 1e-6, "regularization and distribution of the contact forces, 1/N^2", True,
            (0.0, None)),
    Setting("imu_filter_s", 0.05, "time constant of the IMU's complementary filter, s (0: raw IMU)", True,
            (0.0, None)),
    Setting("joystick_ramp_s", 3.0, "the joystick's velocities ramp in linearly over this time, s (seed 001, "
            "Fig. 4: about 3 s)", True, (0.0, 30.0)),
    Setting("encoder_filter_s", 0.0, "time constant of the link encoders' complementary filter with the motor "
            "rates, s (0: the encoders as read, as seed 001)", True, (0.0, None)),
)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[*TUNABLE, "posture_rad", "com_ref_m", "sole_anchor_m"],
    meta_fields=["step_time_s", "double_support_s", "start_s", "knee_rad", "plant", "fixed_upper_body",
                 "friction_coeff", "startup_s", "contact_slack_weight", "qp_max_iter", "qp_retry_iter", "n_steps",
                 "mpc_solver",
                 "dt_s"],
)
@dataclasses.dataclass(frozen=True)
class Config:
    """Tunables (array leaves, named as the settings), the stance's references, and static choices."""

    mpc_com_midpoint_weight: jax.Array
    mpc_com_step_weight: jax.Array
    mpc_footstep_weight: jax.Array
    mpc_footstep_step_weight: jax.Array
    half_width_m: jax.Array
    clearance_m: jax.Array
    com_height_kp_per_s2: jax.Array
    com_height_kd_per_s: jax.Array
    com_weight: jax.Array
    base_kp_per_s2: jax.Array
    base_kd_per_s: jax.Array
    base_weight: jax.Array
    swing_kp_per_s2: jax.Array
    swing_kd_per_s: jax.Array
    swing_weight: jax.Array
    posture_kp_per_s2: jax.Array
    posture_kd_per_s: jax.Array
    posture_weight: jax.Array
    qdd_weight: jax.Array
    force_weight_per_n2: jax.Array
    imu_filter_s: jax.Array
    shift_m: jax.Array
    touchdown_depth_m: jax.Array
    joystick_ramp_s: jax.Array
    encoder_filter_s: jax.Array
    posture_rad: jax.Array  # (23,) the crouched stance
    com_ref_m: jax.Array  # (3,) its CoM over the mid-ankles; z is the LIPM height z0 (soles at z = 0)
    sole_anchor_m: jax.Array  # (2, 3) right and left sole sites at the reset
    step_time_s: float
    double_support_s: float
    start_s: float
    knee_rad: float
    plant: str
    fixed_upper_body: bool
    friction_coeff: float
    startup_s: float
    contact_slack_weight: float
    qp_max_iter: int
    qp_retry_iter: int
    n_steps: int
    mpc_solver: str
    dt_s: float = 0.002

    def replace(self, **kw) -> "Config":
        return dataclasses.replace(self, **kw)


def number_in(name, v, lo, hi, lo_open=False) -> float:
    """``v`` as a float, or a ``ValueError`` naming ``name`` if it is not a finite number in ``[lo, hi]``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{name}={v!r} must be a finite number")
    if v < lo or v > hi or (lo_open and v == lo):
        raise ValueError(f"{name}={v!r} must lie in {'(' if lo_open else '['}{lo:g}, {hi:g}]")
    return float(v)


def _whole(name, v, lo, hi) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise ValueError(f"{name}={v!r} must be a whole number in [{lo}, {hi}]")
    return v


def make_config(step_time_s: float = 0.4, double_support_s: float = 0.0, start_s: float = 0.6, knee_rad: float = 0.4,
                plant: str = "torque-ideal", fixed_upper_body: bool = True, friction_coeff: float = 0.7,
                startup_s: float = 0.05, contact_slack_weight: float = 0.0,
                qp_max_iter: int = 20, qp_retry_iter: int = 0, n_steps: int = 5, mpc_solver: str = "closed-form", **tunables) -> Config:
    """A validated config (host).

    Raises:
        ValueError: an unknown plant, solver or setting, or a value out of its range (naming it).
    """
    unknown = [k for k in tunables if k not in TUNABLE]
    if unknown:
        raise ValueError(f"unknown setting {unknown[0]!r} of footstep-mpc")
    if plant not in PLANTS or plant == "position":
        raise ValueError(f"plant={plant!r} must be torque-ideal or torque-sea")
    if mpc_solver not in MPC_SOLVERS:
        raise ValueError(f"mpc_solver={mpc_solver!r} must be one of {', '.join(MPC_SOLVERS)}")
    if not isinstance(fixed_upper_body, bool):
        raise ValueError(f"fixed_upper_body={fixed_upper_body!r} must be true or false")
    n_steps = _whole("n_steps", n_steps, 1, 20)
    qp_max_iter = _whole("qp_max_iter", qp_max_iter, 1, 200)
    qp_retry_iter = _whole("qp_retry_iter", qp_retry_iter, 0, qp_max_iter - 1)
    step_time_s = number_in("step_time_s", step_time_s, 0.2, 1.0)
    dt = 0.002
    if abs(round(step_time_s / dt) * dt - step_time_s) > 1e-9:
        raise ValueError(f"step_time_s={step_time_s!r} must be a whole number of {dt:g} s control ticks")
    double_support_s = number_in("double_support_s", double_support_s, 0.0, step_time_s / 2)
    start_s = number_in("start_s", start_s, 0.0, 5.0)
    knee_rad = number_in("knee_rad", knee_rad, 0.1, 1.2)
    friction_coeff = number_in("friction_coeff", friction_coeff, 0.0, 2.0, lo_open=True)
    startup_s = number_in("startup_s", startup_s, 0.0, 1.0)
    contact_slack_weight = number_in("contact_slack_weight", contact_slack_weight, 0.0, 1e8)
    values = {s.name: s.default for s in SETTINGS if s.tunable} | tunables
    bounds = {s.name: s.bounds for s in SETTINGS if s.tunable}
    for name, v in values.items():
        if isinstance(v, jax.core.Tracer):
            continue
        lo, hi = bounds[name]
        if not math.isfinite(float(v)) or float(v) < lo or (hi is not None and float(v) > hi):
            raise ValueError(f"{name}={v!r} must be finite and lie in [{lo:g}, {'inf' if hi is None else f'{hi:g}'}]")
    f = jnp.result_type(float)
    q, com, soles = stance_references(knee_rad)
    return Config(**{k: jnp.asarray(v, f) for k, v in values.items()}, posture_rad=jnp.asarray(q, f),
                  com_ref_m=jnp.asarray(com, f), sole_anchor_m=jnp.asarray(soles, f), step_time_s=step_time_s,
                  double_support_s=double_support_s, start_s=start_s, knee_rad=knee_rad, plant=plant,
                  fixed_upper_body=fixed_upper_body, friction_coeff=friction_coeff, startup_s=startup_s,
                  contact_slack_weight=contact_slack_weight, qp_max_iter=qp_max_iter, qp_retry_iter=qp_retry_iter,
                  n_steps=n_steps,
                  mpc_solver=mpc_solver)
