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

Torque commands (seeds 001 and 004 are torque-controlled) are realised in one
of two ways, chosen per rollout by ``ActuatorParams.torque_loop`` (an array,
so one batch can hold both):

* ideal (:data:`TORQUE_IDEAL`): the link receives the desired torque,
  clipped to what the motor can give at the joint's speed (eq. 20 at the
  supply voltage, :func:`torque_limits_nm`: +-33 N m at stall), as seed 001's
  simulation assumes ("torque tracking is ideal");
* series-elastic (:data:`TORQUE_SEA`): a torque loop on the motor board
  drives the spring torque to the desired one through the voltage-limited
  motor (:func:`torque_loop_voltage_v`), with a closed-loop bandwidth and
  damping ratio as parameters; rigid joints get the eq. 20 feed-forward voltage.
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
DELAY_S = 0.02  # the position plant's transport delay (make_actuator_params' default)
SUPPLY_V = 15.0  # the motor drivers' supply, the voltage saturation of the seed (make_actuator_params' default)
MODE_POSITION, MODE_VOLTAGE, MODE_TORQUE = 0, 1, 2  # what a command's target is: motor angles, volts, link torques
MODES = {"position": MODE_POSITION, "voltage": MODE_VOLTAGE, "torque": MODE_TORQUE}
TORQUE_IDEAL, TORQUE_SEA = 0, 1
TORQUE_LOOPS = {"ideal": TORQUE_IDEAL, "sea": TORQUE_SEA}


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
        torque_loop: how a torque command is realised, :data:`TORQUE_IDEAL` or :data:`TORQUE_SEA` (int32 scalar).
        torque_bandwidth_hz: natural frequency of the series-elastic torque loop, Hz.
        torque_damping_ratio: its damping ratio.
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
    torque_loop: jax.Array
    torque_bandwidth_hz: jax.Array
    torque_damping_ratio: jax.Array


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
    supply_v=SUPPLY_V,
    spring_stiffness_nm_per_rad=390.0,
    spring_damping_nms_per_rad=0.5,
    kp_v_per_rad=None,
    delay_s=DELAY_S,
    control_period_s=0.002,
    torque_loop="ideal",
    torque_bandwidth_hz=10.0,
    torque_damping_ratio=1.0,
) -> ActuatorParams:
    """Build validated actuator parameters (scalars broadcast to every joint).

    Args:
        delay_s: transport delay, rounded to whole control periods.
        control_period_s: control period used to convert ``delay_s`` to ticks.
        torque_loop: ``"ideal"`` or ``"sea"`` (how torque commands are realised).
        others: see :class:`ActuatorParams`.

    Raises:
        ValueError: naming the bad value (non-positive alpha, beta, inertia,
            supply, period, torque bandwidth or damping ratio; negative
            stiffness, damping, friction, gains or delay; a delay longer than
            ``MAX_DELAY_TICKS`` ticks; an unknown torque loop).
    """
    if torque_loop not in TORQUE_LOOPS:
        raise ValueError(f"torque_loop={torque_loop!r} is not one of {', '.join(TORQUE_LOOPS)}")
    kp = default_kp_v_per_rad() if kp_v_per_rad is None else kp_v_per_rad
    for name, v in [("alpha_v_s_per_rad", alpha_v_s_per_rad), ("beta_v_per_nm", beta_v_per_nm),
                    ("rotor_inertia_nms2_per_rad", rotor_inertia_nms2_per_rad), ("supply_v", supply_v),
                    ("coulomb_eps_rad_per_s", coulomb_eps_rad_per_s), ("control_period_s", control_period_s),
                    ("torque_bandwidth_hz", torque_bandwidth_hz), ("torque_damping_ratio", torque_damping_ratio)]:
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
        torque_loop=jnp.asarray(TORQUE_LOOPS[torque_loop], jnp.int32),
        torque_bandwidth_hz=jnp.asarray(torque_bandwidth_hz, float),
        torque_damping_ratio=jnp.asarray(torque_damping_ratio, float),
    )


class ActuatorState(NamedTuple):
    """Motor shaft states and the command delay line.

    Attributes:
        motor_angle_rad: motor shaft angles (link side of the gearbox), (NU,).
            At rigid joints it equals the link angle.
        motor_vel_rad_per_s: shaft velocities, (NU,).
        buffer: ring buffer of command targets, (MAX_DELAY_TICKS + 1, NU).
        tick: control ticks since reset (int32).
        mode_buffer: the command mode of each buffered target (``MODE_*``), (MAX_DELAY_TICKS + 1,) int32.
    """

    motor_angle_rad: jax.Array
    motor_vel_rad_per_s: jax.Array
    buffer: jax.Array
    tick: jax.Array
    mode_buffer: jax.Array


def init_actuator_state(q_rad: jax.Array, dq_rad_per_s: jax.Array, initial_command: jax.Array) -> ActuatorState:
    """Motors at the link angles, the delay line filled with the position command ``initial_command``.

    Until a controller's first command has come through the delay, the motor
    boards hold that position, whatever mode the controller commands in.
    """
    buf = jnp.broadcast_to(initial_command, (MAX_DELAY_TICKS + 1, NU)).astype(q_rad.dtype)
    modes = jnp.full((MAX_DELAY_TICKS + 1,), MODE_POSITION, jnp.int32)
    return ActuatorState(q_rad, dq_rad_per_s, buf, jnp.asarray(0, jnp.int32), modes)


def delay_command(params: ActuatorParams, state: ActuatorState, command: jax.Array,
                  mode=MODE_POSITION) -> tuple[ActuatorState, jax.Array, jax.Array]:
    """Push this tick's command (and its mode) into the ring buffer; return the ones ``delay_ticks`` old.

    The delay is a traced integer index into a static buffer, so rollouts
    with different delays vmap together. ``delay_ticks = 0`` passes the
    command through.

    Returns:
        ``(state, target, mode)``.
    """
    n = state.buffer.shape[0]
    slot = state.tick % n
    buf = state.buffer.at[slot].set(command)
    modes = state.mode_buffer.at[slot].set(jnp.asarray(mode, jnp.int32))
    old = (state.tick - params.delay_ticks) % n
    return state._replace(buffer=buf, mode_buffer=modes, tick=state.tick + 1), buf[old], modes[old]


def motor_voltage_v(params: ActuatorParams, target: jax.Array, motor_angle_rad: jax.Array,
                    voltage_mode: jax.Array) -> jax.Array:
    """Saturated motor voltage: eq. 25 position loop, or raw volts if ``voltage_mode``.

    ``v = clip(k_p (theta_des - theta_m), -supply, supply)`` (seed eq. 25).
    """
    v = jnp.where(voltage_mode, target, params.kp_v_per_rad * (target - motor_angle_rad))
    return jnp.clip(v, -params.supply_v, params.supply_v)


def torque_limits_nm(params: ActuatorParams, dq_rad_per_s: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Link torques the motor can give at joint speed ``dq`` (eq. 20 at +-supply, steady shaft).

    ``tau = (+-V - (alpha + beta A_c) q_dot) / beta``: +-33 N m at stall with the
    seed's 15 V and beta = 0.45 V/(N m), shrinking linearly with speed (Coulomb term ignored).
    Braking (torque against the motion) is capped at the stall torque ``V / beta`` as well: the
    back-EMF would allow more, the motor driver's current limit does not (and a torque limit that grew
    with speed would let a numerical blow-up feed itself).
    """
    p = params
    stall = p.supply_v / p.beta_v_per_nm
    emf = (p.alpha_v_s_per_rad / p.beta_v_per_nm + p.friction_nms_per_rad) * dq_rad_per_s
    return jnp.maximum(-stall - emf, -stall), jnp.minimum(stall - emf, stall)


def ideal_torque_nm(params: ActuatorParams, tau_des_nm: jax.Array, dq_rad_per_s: jax.Array) -> jax.Array:
    """The ideal torque loop: the desired link torque within :func:`torque_limits_nm`."""
    lo, hi = torque_limits_nm(params, dq_rad_per_s)
    return jnp.clip(tau_des_nm, lo, hi)


def torque_loop_voltage_v(params: ActuatorParams, state: "ActuatorState", tau_des_nm: jax.Array,
                          q_rad: jax.Array, dq_rad_per_s: jax.Array) -> jax.Array:
    """Motor voltage of the series-elastic torque loop (saturated at the supply).

    With the eq. 20 feed-forward ``v = (alpha + beta A_c) theta_dot + beta u`` the
    motor obeys ``J_m theta_ddot = u - tau_s``; the loop sets
    ``u = tau_d + K (tau_d - tau_s) - D (theta_dot - q_dot)`` so that, for a still
    link, the deflection ``delta = theta - q`` obeys
    ``J_m delta_ddot + (D + (1 + K) b) delta_dot + (1 + K) k delta = (1 + K) tau_d``:
    the spring torque follows ``tau_d`` as a second-order system of natural
    frequency ``w = 2 pi bandwidth`` and damping ratio ``zeta`` with
    ``1 + K = J_m w^2 / k`` and ``D = 2 zeta w J_m - (1 + K) b``.
    Rigid joints: ``v = beta tau_d + (alpha + beta A_c) q_dot``, exact up to saturation.
    """
    p = params
    th, dth = state.motor_angle_rad, state.motor_vel_rad_per_s
    k, b, jm = p.spring_stiffness_nm_per_rad, p.spring_damping_nms_per_rad, p.rotor_inertia_nms2_per_rad
    w = 2.0 * jnp.pi * p.torque_bandwidth_hz
    gain = jm * w**2 / jnp.maximum(k, 1e-9) - 1.0
    damp = 2.0 * p.torque_damping_ratio * w * jm - (1.0 + gain) * b
    tau_s = k * (th - q_rad) + b * (dth - dq_rad_per_s)
    u = tau_des_nm + gain * (tau_des_nm - tau_s) - damp * (dth - dq_rad_per_s)
    emf = p.alpha_v_s_per_rad + p.beta_v_per_nm * p.friction_nms_per_rad
    v = jnp.where(jnp.asarray(SEA_MASK), emf * dth + p.beta_v_per_nm * u, emf * dq_rad_per_s + p.beta_v_per_nm * tau_des_nm)
    return jnp.clip(v, -p.supply_v, p.supply_v)


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
