"""COMAN's voltage-driven motors, series springs, position loops and delay, in JAX.

Every joint has a DC motor behind a harmonic drive. Seed 000 (section
"Low-Level Challenges", eq. 19-20) relates voltage, shaft speed and output
torque by

    v = alpha theta_dot + beta (J_m theta_ddot + tau_out + A_c |theta_dot|)   (eq. 20)

with alpha ~ 5.42 V s/rad, beta ~ 0.45 V/(N m), J_m ~ 0.23 N m s^2/rad and
A_c ~ 1.66 N m s/rad. The friction term is taken with the sign of the motion,
``A_c |theta_dot| sign(theta_dot) = A_c theta_dot``, so that it always resists
motion; with a 15 V supply the no-load speed is then
``15 / (alpha + beta A_c) = 2.43 rad/s``, the seed's "theoretic velocity bound".
An optional Coulomb term ``coulomb_nm * tanh(theta_dot / eps)`` (smooth, so
that gradients exist) can be added; it is zero by default.

Joints with a series elastic actuator (``mjcf.SEA_JOINTS``: hip, knee and
ankle pitch) carry a spring between motor shaft and link; the link receives
``tau = k (theta_m - q) + b (theta_m_dot - q_dot)`` and the motor is a state of
its own, integrated here. All other joints are rigidly coupled: their motor
inertia ``J_m`` is the joint armature in the MJCF and the motor torque
``v / beta - (alpha / beta + A_c) q_dot`` goes straight to the joint (eq. 20
solved for ``tau_out + J_m q_ddot``), which is exact for a rigid coupling and
avoids a very stiff spring on light links.

Position control runs on the motor shaft (eq. 25): ``v = k_p (theta_des -
theta_m)``, gains 10 V/rad (ankle roll), 100 V/rad (hip pitch), 500 V/rad
otherwise. Commands reach the motor boards after a transport delay, an
integer number of control ticks read from a ring buffer (vmappable).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_coman.mjcf import ROTOR_INERTIA_NMS2_PER_RAD, SEA_JOINTS

# Hinge joints in qpos order (actuator i drives qpos[7 + i], qvel[6 + i]).
JOINT_NAMES = (
    "RHipSag", "RHipLat", "RHipYaw", "RKneeSag", "RAnkLat", "RAnkSag",
    "LHipSag", "LHipLat", "LHipYaw", "LKneeSag", "LAnkLat", "LAnkSag",
    "WaistLat", "WaistSag", "WaistYaw",
    "RShSag", "RShLat", "RShYaw", "RElbj",
    "LShSag", "LShLat", "LShYaw", "LElbj",
)
NU = len(JOINT_NAMES)
JOINT_INDEX = {n: i for i, n in enumerate(JOINT_NAMES)}
SEA_MASK = np.array([n in SEA_JOINTS for n in JOINT_NAMES])  # static structure
MAX_DELAY_TICKS = 32  # static ring-buffer length is MAX_DELAY_TICKS + 1


def default_kp_v_per_rad() -> np.ndarray:
    """Seed gains (eq. 25): 10 V/rad ankle roll, 100 V/rad hip pitch, 500 V/rad others."""
    kp = np.full(NU, 500.0)
    for n in JOINT_NAMES:
        if n.endswith("AnkLat"):
            kp[JOINT_INDEX[n]] = 10.0
        elif n.endswith("HipSag"):
            kp[JOINT_INDEX[n]] = 100.0
    return kp


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ActuatorParams:
    """Motor, spring, position-loop and delay constants (arrays; vmappable).

    Attributes:
        alpha_v_s_per_rad: back-EMF plus viscous coefficient alpha (eq. 20), (NU,).
        beta_v_per_nm: voltage per output torque beta (eq. 20), (NU,).
        rotor_inertia_nms2_per_rad: reflected rotor inertia J_m of SEA motors, (NU,).
            (Rigid joints take J_m from the MJCF armature.)
        friction_nms_per_rad: A_c of eq. 20, applied as ``A_c theta_dot``, (NU,).
        coulomb_nm: optional smooth Coulomb friction amplitude, (NU,).
        coulomb_eps_rad_per_s: velocity scale of the tanh smoothing.
        supply_v: voltage saturation (15 V in the seed).
        spring_stiffness_nm_per_rad: series spring stiffness, (NU,), used at SEA joints.
        spring_damping_nms_per_rad: series spring damping, (NU,).
        kp_v_per_rad: motor-shaft position gains k_d of eq. 25, (NU,).
        delay_ticks: transport delay in control ticks (int32 scalar, <= MAX_DELAY_TICKS).
    """

    alpha_v_s_per_rad: jax.Array
    beta_v_per_nm: jax.Array
    rotor_inertia_nms2_per_rad: jax.Array
    friction_nms_per_rad: jax.Array
    coulomb_nm: jax.Array
    coulomb_eps_rad_per_s: jax.Array
    supply_v: jax.Array
    spring_stiffness_nm_per_rad: jax.Array
    spring_damping_nms_per_rad: jax.Array
    kp_v_per_rad: jax.Array
    delay_ticks: jax.Array


def _check(name: str, value, *, positive: bool) -> None:
    arr = np.asarray(value, dtype=float)
    bad = ~np.isfinite(arr) | ((arr <= 0) if positive else (arr < 0))
    if np.any(bad):
        kind = "positive" if positive else "non-negative"
        raise ValueError(f"{name} must be finite and {kind}, got {arr.tolist()}")


def _per_joint(value) -> jax.Array:
    arr = np.broadcast_to(np.asarray(value, dtype=float), (NU,))
    return jnp.asarray(arr, dtype=float)


def make_actuator_params(
    *,
    alpha_v_s_per_rad=5.42,
    beta_v_per_nm=0.45,
    rotor_inertia_nms2_per_rad=ROTOR_INERTIA_NMS2_PER_RAD,
    friction_nms_per_rad=1.66,
    coulomb_nm=0.0,
    coulomb_eps_rad_per_s=0.05,
    supply_v=15.0,
    spring_stiffness_nm_per_rad=390.0,
    spring_damping_nms_per_rad=0.5,
    kp_v_per_rad=None,
    delay_s=0.02,
    control_period_s=0.002,
) -> ActuatorParams:
    """Build validated actuator parameters (scalars broadcast to every joint).

    Args:
        delay_s: transport delay, rounded to whole control periods.
        control_period_s: control period used to convert ``delay_s`` to ticks.
        others: see :class:`ActuatorParams`.

    Raises:
        ValueError: naming the bad value (non-positive alpha, beta, inertia,
            supply or period; negative stiffness, damping, friction, gains or
            delay; a delay longer than ``MAX_DELAY_TICKS`` ticks).
    """
    kp = default_kp_v_per_rad() if kp_v_per_rad is None else kp_v_per_rad
    for name, v in [("alpha_v_s_per_rad", alpha_v_s_per_rad), ("beta_v_per_nm", beta_v_per_nm),
                    ("rotor_inertia_nms2_per_rad", rotor_inertia_nms2_per_rad), ("supply_v", supply_v),
                    ("coulomb_eps_rad_per_s", coulomb_eps_rad_per_s), ("control_period_s", control_period_s)]:
        _check(name, v, positive=True)
    for name, v in [("friction_nms_per_rad", friction_nms_per_rad), ("coulomb_nm", coulomb_nm),
                    ("spring_stiffness_nm_per_rad", spring_stiffness_nm_per_rad),
                    ("spring_damping_nms_per_rad", spring_damping_nms_per_rad), ("kp_v_per_rad", kp),
                    ("delay_s", delay_s)]:
        _check(name, v, positive=False)
    ticks = int(round(float(delay_s) / float(control_period_s)))
    if ticks > MAX_DELAY_TICKS:
        raise ValueError(
            f"delay_s={delay_s} is {ticks} control ticks, more than MAX_DELAY_TICKS={MAX_DELAY_TICKS}"
        )
    return ActuatorParams(
        alpha_v_s_per_rad=_per_joint(alpha_v_s_per_rad),
        beta_v_per_nm=_per_joint(beta_v_per_nm),
        rotor_inertia_nms2_per_rad=_per_joint(rotor_inertia_nms2_per_rad),
        friction_nms_per_rad=_per_joint(friction_nms_per_rad),
        coulomb_nm=_per_joint(coulomb_nm),
        coulomb_eps_rad_per_s=jnp.asarray(coulomb_eps_rad_per_s, float),
        supply_v=jnp.asarray(supply_v, float),
        spring_stiffness_nm_per_rad=_per_joint(spring_stiffness_nm_per_rad),
        spring_damping_nms_per_rad=_per_joint(spring_damping_nms_per_rad),
        kp_v_per_rad=_per_joint(kp),
        delay_ticks=jnp.asarray(ticks, jnp.int32),
    )


class ActuatorState(NamedTuple):
    """Motor shaft states and the command delay line.

    Attributes:
        motor_angle_rad: motor shaft angles (link side of the gearbox), (NU,).
            At rigid joints it equals the link angle.
        motor_vel_rad_per_s: shaft velocities, (NU,).
        buffer: ring buffer of commands, (MAX_DELAY_TICKS + 1, NU).
        tick: control ticks since reset (int32).
    """

    motor_angle_rad: jax.Array
    motor_vel_rad_per_s: jax.Array
    buffer: jax.Array
    tick: jax.Array


def init_actuator_state(q_rad: jax.Array, dq_rad_per_s: jax.Array, initial_command: jax.Array) -> ActuatorState:
    """Motors at the link angles, the delay line filled with ``initial_command``."""
    buf = jnp.broadcast_to(initial_command, (MAX_DELAY_TICKS + 1, NU)).astype(q_rad.dtype)
    return ActuatorState(q_rad, dq_rad_per_s, buf, jnp.asarray(0, jnp.int32))


def delay_command(params: ActuatorParams, state: ActuatorState, command: jax.Array) -> tuple[ActuatorState, jax.Array]:
    """Push this tick's command into the ring buffer; return the one ``delay_ticks`` old.

    The delay is a traced integer index into a static buffer, so rollouts
    with different delays vmap together. ``delay_ticks = 0`` passes the
    command through.
    """
    n = state.buffer.shape[0]
    buf = state.buffer.at[state.tick % n].set(command)
    delayed = buf[(state.tick - params.delay_ticks) % n]
    return state._replace(buffer=buf, tick=state.tick + 1), delayed


def motor_voltage_v(params: ActuatorParams, target: jax.Array, motor_angle_rad: jax.Array,
                    voltage_mode: jax.Array) -> jax.Array:
    """Saturated motor voltage: eq. 25 position loop, or raw volts if ``voltage_mode``.

    ``v = clip(k_p (theta_des - theta_m), -supply, supply)`` (seed eq. 25).
    """
    v = jnp.where(voltage_mode, target, params.kp_v_per_rad * (target - motor_angle_rad))
    return jnp.clip(v, -params.supply_v, params.supply_v)


def _friction_nm(params: ActuatorParams, vel: jax.Array) -> jax.Array:
    return params.friction_nms_per_rad * vel + params.coulomb_nm * jnp.tanh(vel / params.coulomb_eps_rad_per_s)


def actuator_substep(
    params: ActuatorParams,
    state: ActuatorState,
    voltage_v: jax.Array,
    q_rad: jax.Array,
    dq_rad_per_s: jax.Array,
    dt_s: float | jax.Array,
) -> tuple[ActuatorState, jax.Array]:
    """Advance the motors by one physics step; return the link torques.

    SEA joints (seed eq. 20 with ``tau_out`` the spring torque):
    ``J_m theta_ddot = v / beta - (alpha / beta) theta_dot - A_c theta_dot - tau_s``,
    ``tau_s = k (theta - q) + b (theta_dot - q_dot)``; integrated by
    semi-implicit Euler, with the velocity-proportional terms implicit (stable
    for any step). The link receives ``tau_s`` computed from the state at the
    start of the step.

    Rigid joints: the link receives ``v / beta - (alpha / beta + A_c) q_dot``
    (the rotor inertia is in the MJCF armature) and the motor state copies the link.

    Args:
        voltage_v: saturated voltages (NU,), from :func:`motor_voltage_v`.
        q_rad, dq_rad_per_s: link angles and velocities (NU,).
        dt_s: physics step.

    Returns:
        the new state and the link torques (NU,) for MuJoCo's ``ctrl``.
    """
    p = params
    th, dth = state.motor_angle_rad, state.motor_vel_rad_per_s
    k, b = p.spring_stiffness_nm_per_rad, p.spring_damping_nms_per_rad
    tau_spring = k * (th - q_rad) + b * (dth - dq_rad_per_s)
    visc = p.alpha_v_s_per_rad / p.beta_v_per_nm + p.friction_nms_per_rad
    coulomb = p.coulomb_nm * jnp.tanh(dth / p.coulomb_eps_rad_per_s)
    # Implicit in the viscous terms (motor damping and spring damping).
    rhs = voltage_v / p.beta_v_per_nm - coulomb - k * (th - q_rad) + b * dq_rad_per_s
    jm = p.rotor_inertia_nms2_per_rad
    dth_new = (jm * dth + dt_s * rhs) / (jm + dt_s * (visc + b))
    th_new = th + dt_s * dth_new
    tau_rigid = voltage_v / p.beta_v_per_nm - (p.alpha_v_s_per_rad / p.beta_v_per_nm) * dq_rad_per_s - _friction_nm(
        p, dq_rad_per_s
    )
    sea = jnp.asarray(SEA_MASK)
    tau = jnp.where(sea, tau_spring, tau_rigid)
    new = state._replace(
        motor_angle_rad=jnp.where(sea, th_new, q_rad),
        motor_vel_rad_per_s=jnp.where(sea, dth_new, dq_rad_per_s),
    )
    return new, tau


def static_spring_deflection_rad(params: ActuatorParams, link_torque_nm: jax.Array) -> jax.Array:
    """Spring deflection ``theta_m - q = tau / k`` at SEA joints for a static torque (0 elsewhere)."""
    return jnp.where(jnp.asarray(SEA_MASK), link_torque_nm / params.spring_stiffness_nm_per_rad, 0.0)


def series_stiffness_nm_per_rad(params: ActuatorParams) -> jax.Array:
    """Static joint stiffness seen from the link: spring and position loop in series.

    The position loop makes the motor shaft a spring of ``k_p / beta``
    (eq. 25 into eq. 20 at rest; 500 / 0.45 ~ 1100 N m/rad), in series with
    the physical spring ``k``: ``1 / (1 / k + beta / k_p)``. Rigid joints: ``k_p / beta``.
    """
    k_pos = params.kp_v_per_rad / params.beta_v_per_nm
    k = params.spring_stiffness_nm_per_rad
    return jnp.where(jnp.asarray(SEA_MASK), k * k_pos / (k + k_pos), k_pos)
