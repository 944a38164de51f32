"""The COMAN environment: pure ``reset`` and ``step`` functions over pytrees.

One control tick (2 ms by default) pushes the command through the transport
delay, then runs ``n_substeps`` physics steps; in each, the motor boards
turn the command into motor voltages (a position loop on the motor shaft,
seed eq. 25; raw volts; or a torque loop), the motors and springs are
integrated (:mod:`mjx_coman.actuators`) and MJX advances the rigid bodies
with the link torques as ``ctrl``. A torque command under the ideal torque
loop skips the motors: the link gets the desired torque within the motor's
limits. The sensors are read at the end of the tick.

Nothing here is jitted or vmapped: do that at the outer boundary, e.g.
``jax.jit(jax.vmap(step, in_axes=(batch_axes(params), 0, 0)))``.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_coman import load_model
from mjx_coman.engines import MJX, Engine, make_engine
from mjx_coman.actuators import (
    MODE_POSITION,
    MODE_TORQUE,
    MODE_VOLTAGE,
    MODES,
    NU,
    JOINT_INDEX,
    TORQUE_SEA,
    ActuatorParams,
    ActuatorState,
    actuator_substep,
    delay_command,
    ideal_torque_nm,
    init_actuator_state,
    make_actuator_params,
    motor_voltage_v,
    static_spring_deflection_rad,
    torque_loop_voltage_v,
)
from mjx_coman.sensors import Readings, SensorParams, SensorState, init_sensor_state, make_sensor_params, model_ids, read_sensors

STANDING_KNEE_RAD = 0.4
MID_FOOT_AHEAD_M = 0.03  # sole centre ahead of the ankle axis: (0.13 - 0.07) / 2


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["model", "actuator", "sensor"],
    meta_fields=["n_substeps", "engine"],
)
@dataclasses.dataclass(frozen=True)
class EnvParams:
    """Everything a rollout depends on.

    Attributes:
        model: the ``mjx.Model`` (fields such as ``body_mass`` can be replaced per rollout).
        actuator: motor, spring, position-loop and delay constants.
        sensor: sensor constants.
        n_substeps: physics steps per control tick (static).
        engine: what steps the physics (static; :mod:`mjx_coman.engines`, :func:`use_engine`).
    """

    model: mjx.Model
    actuator: ActuatorParams
    sensor: SensorParams
    n_substeps: int
    engine: Engine = MJX

    @property
    def timestep_s(self) -> jax.Array:
        return self.model.opt.timestep

    @property
    def control_period_s(self) -> jax.Array:
        return self.model.opt.timestep * self.n_substeps


class Command(NamedTuple):
    """One control tick's command.

    Attributes:
        target: (NU,) desired motor angles (rad), voltages (V) or link torques (N m), by ``mode``.
        torso_force_n: external force on the upper torso (world frame), (3,).
        mode: int32 scalar, ``MODE_POSITION``, ``MODE_VOLTAGE`` or ``MODE_TORQUE``
            (how a torque is realised is the plant's choice: ``ActuatorParams.torque_loop``).

    ``target`` and ``mode`` go through the transport delay together
    (``ActuatorParams.delay_ticks``); ``torso_force_n`` acts at once.
    """

    target: jax.Array
    torso_force_n: jax.Array
    mode: jax.Array


class EnvState(NamedTuple):
    """The full simulation state (a pytree).

    Attributes:
        data: ``mjx.Data`` (rigid bodies, contacts).
        actuator: motor states and the command delay line.
        sensor: sensor hysteresis state.
        readings: the last sensor readings.
        key: PRNG key for the sensor noise.
        time_s: simulated time.
    """

    data: mjx.Data
    actuator: ActuatorState
    sensor: SensorState
    readings: Readings
    key: jax.Array
    time_s: jax.Array


def make_command(target, torso_force_n=None, mode: str = "position") -> Command:
    """A :class:`Command` with the force defaulting to zero.

    Raises:
        ValueError: an unknown ``mode`` (``position``, ``voltage`` or ``torque``).
    """
    if mode not in MODES:
        raise ValueError(f"mode={mode!r} is not one of {', '.join(MODES)}")
    target = jnp.asarray(target, float)
    dtype = target.dtype
    force = jnp.zeros(3, dtype) if torso_force_n is None else jnp.asarray(torso_force_n, dtype)
    return Command(target, force, jnp.asarray(MODES[mode], jnp.int32))


def make_env_params(
    *,
    timestep_s: float = 0.001,
    control_period_s: float = 0.002,
    actuator: ActuatorParams | None = None,
    sensor: SensorParams | None = None,
    mj_model: mujoco.MjModel | None = None,
) -> EnvParams:
    """Build validated environment parameters.

    Raises:
        ValueError: a non-positive ``timestep_s`` or ``control_period_s``, or a
            control period that is not a whole number of timesteps.
    """
    for name, v in (("timestep_s", timestep_s), ("control_period_s", control_period_s)):
        if not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name} must be finite and positive, got {v}")
    n = int(round(control_period_s / timestep_s))
    if n < 1 or abs(n * timestep_s - control_period_s) > 1e-9:
        raise ValueError(
            f"control_period_s={control_period_s} must be a whole multiple of timestep_s={timestep_s}"
        )
    m = mj_model if mj_model is not None else load_model()
    m.opt.timestep = timestep_s
    return EnvParams(
        model=mjx.put_model(m),
        actuator=actuator if actuator is not None else make_actuator_params(control_period_s=control_period_s),
        sensor=sensor if sensor is not None else make_sensor_params(),
        n_substeps=n,
    )


def batch_axes(params: EnvParams, model_fields: tuple[str, ...] = ()) -> EnvParams:
    """``in_axes`` for ``jax.vmap`` over params whose actuator and sensor leaves are batched.

    Args:
        params: the (batched) parameters.
        model_fields: ``mjx.Model`` fields that are batched too (e.g. ``("body_mass",)``).
    """
    model_axes = jax.tree_util.tree_map(lambda _: None, params.model)
    if model_fields:
        model_axes = model_axes.replace(**{f: 0 for f in model_fields})
    zeros = functools.partial(jax.tree_util.tree_map, lambda _: 0)
    return EnvParams(model=model_axes, actuator=zeros(params.actuator), sensor=zeros(params.sensor),
                     n_substeps=params.n_substeps, engine=params.engine)


def use_engine(params: EnvParams, engine: str = "mjx", *, mj_model: mujoco.MjModel | None = None,
               n_threads: int | None = None) -> EnvParams:
    """``params`` on the physics engine ``engine`` (:mod:`mjx_coman.engines`: ``mjx`` or ``native``).

    Args:
        mj_model: the compiled model ``params.model`` was made from (default: the packaged robot at the
            params' timestep); a scene variant's params need their own.
        n_threads: the native engine's threads (default: every core).

    Raises:
        ValueError: an unknown engine, bad ``n_threads``, or ``mj_model`` not the model of ``params``
            (other sizes or timestep).
    """
    if mj_model is None:
        mj_model = load_model()
        mj_model.opt.timestep = float(np.asarray(params.model.opt.timestep))
    bad = [f"{k} {getattr(mj_model, k)} != {getattr(params.model, k)}" for k in ("nq", "nv", "nbody", "ngeom", "nsite")
           if getattr(mj_model, k) != getattr(params.model, k)]
    step = float(np.asarray(params.model.opt.timestep))
    if abs(mj_model.opt.timestep - step) > 1e-12:
        bad.append(f"timestep {mj_model.opt.timestep} != {step}")
    if bad:
        raise ValueError(f"mj_model is not the model of these params ({'; '.join(bad)}): pass the scene's MjModel")
    return dataclasses.replace(params, engine=make_engine(engine, mj_model, n_threads))


def solver_iterations(params: EnvParams, iterations: int = 1) -> EnvParams:
    """``params`` with MJX's constraint solver capped at ``iterations`` Newton iterations (static).

    Reverse mode: MJX runs its solver in a ``lax.while_loop`` (``mujoco/mjx/_src/solver.py``), which
    ``jax.grad`` cannot differentiate, except at ``opt.iterations == 1``, where it takes one warm-started
    Newton step with no loop; the line search is a scan, which reverse mode differentiates.
    ``bench/reverse_mode.py`` measures what one iteration costs against the model's 4 on the same walks.

    Raises:
        ValueError: ``iterations`` not a whole number >= 1.
    """
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise ValueError(f"iterations={iterations!r} must be a whole number >= 1")
    model = params.model
    return dataclasses.replace(params, model=model.replace(opt=model.opt.replace(iterations=iterations)))


@functools.lru_cache(maxsize=8)
def standing_posture(knee_rad: float = STANDING_KNEE_RAD) -> tuple[np.ndarray, np.ndarray]:
    """A crouched standing posture: knees bent, feet flat, CoM over the mid-feet.

    Hip pitch is solved (bisection) so that the whole-body CoM lies above the
    sole centres; ankle pitch keeps the feet flat (``ankle = -(hip + knee)``);
    the elbows are bent 0.3 rad to stay off their limit. The free base is set
    so that the soles touch ``z = 0``.

    Returns:
        ``(q_rad (NU,), root_qpos (7,))``.
    """
    m = load_model()
    d = mujoco.MjData(m)
    sole = model_ids()["r_sole_site"]

    def pose(hip):
        q = np.zeros(NU)
        for s in "RL":
            q[JOINT_INDEX[s + "HipSag"]] = hip
            q[JOINT_INDEX[s + "KneeSag"]] = knee_rad
            q[JOINT_INDEX[s + "AnkSag"]] = -(hip + knee_rad)
            q[JOINT_INDEX[s + "Elbj"]] = -0.3
        d.qpos[:] = m.qpos0
        d.qpos[7:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com_x = d.subtree_com[1, 0]
        return q, com_x - (d.site_xpos[sole, 0] + MID_FOOT_AHEAD_M)

    lo, hi = -1.0, 0.5
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if pose(mid)[1] > 0:  # CoM ahead of the feet: lean the thigh back less
            hi = mid
        else:
            lo = mid
    q, _ = pose(0.5 * (lo + hi))
    root = np.array(m.qpos0[:7])
    root[2] = -d.site_xpos[sole, 2]
    return q, root


def reset(key: jax.Array, params: EnvParams, knee_rad: float = STANDING_KNEE_RAD) -> EnvState:
    """Standing crouched on flat feet, at rest, motors at the link angles.

    The robot is placed with its soles on the floor; contact forces appear
    from the first :func:`step` on (the reset readings have zero F/T and no
    contact flags).

    Args:
        key: PRNG key for the sensor noise stream.
        params: environment parameters.
        knee_rad: knee flexion of the posture (static).
    """
    q0, root = standing_posture(float(knee_rad))
    dtype = params.model.opt.timestep.dtype  # float32, or float64 under jax_enable_x64
    q0 = jnp.asarray(q0, dtype)
    data = mjx.make_data(params.model)
    data = data.replace(qpos=jnp.concatenate([jnp.asarray(root, dtype), q0]))
    # Kinematics only (cheap to compile): the first step runs the full forward
    # dynamics, so the reset readings show no contact force yet.
    data = mjx.kinematics(params.model, data)
    act = init_actuator_state(q0, jnp.zeros(NU), q0)
    sens = init_sensor_state(q0)
    key, sub = jax.random.split(key)
    sens, readings = read_sensors(params.sensor, sens, sub, data, act.motor_angle_rad, act.motor_vel_rad_per_s)
    return EnvState(data, act, sens, readings, key, jnp.asarray(0.0, dtype))


def torso_wrench(data: mjx.Data, force_n: jax.Array) -> jax.Array:
    """``xfrc_applied`` for a force at the upper-torso site (moment about the torso CoM added)."""
    ids = model_ids()
    b = ids["torso_body"]
    arm = data.site_xpos[ids["torso_site"]] - data.xipos[b]
    wrench = jnp.concatenate([force_n, jnp.cross(arm, force_n)])
    return jnp.zeros_like(data.xfrc_applied).at[b].set(wrench)


def step(params: EnvParams, state: EnvState, command: Command) -> EnvState:
    """Advance one control tick (``params.n_substeps`` physics steps).

    Args:
        params: environment parameters.
        state: current state.
        command: motor-angle, voltage or torque targets and the torso force.

    Returns:
        the next state, with fresh sensor readings.
    """
    p = params.actuator
    act, target, mode = delay_command(p, state.actuator, command.target, command.mode)
    dt = params.model.opt.timestep
    torque = mode == MODE_TORQUE
    ideal = torque & (p.torque_loop != TORQUE_SEA)

    def substep(carry, _):
        data, act = carry
        q, dq = data.qpos[7:], data.qvel[6:]
        v = jnp.where(torque, torque_loop_voltage_v(p, act, target, q, dq),
                      motor_voltage_v(p, target, act.motor_angle_rad, mode == MODE_VOLTAGE))
        motor, tau = actuator_substep(p, act, v, q, dq, dt)
        # Ideal torque loop: the link gets the torque; the motors sit where that torque puts them.
        tau_ideal = ideal_torque_nm(p, target, dq)
        held = act._replace(motor_angle_rad=q + static_spring_deflection_rad(p, tau_ideal), motor_vel_rad_per_s=dq)
        act = jax.tree_util.tree_map(lambda a, b: jnp.where(ideal, a, b), held, motor)
        tau = jnp.where(ideal, tau_ideal, tau)
        data = data.replace(ctrl=tau, xfrc_applied=torso_wrench(data, command.torso_force_n))
        return (params.engine.step(params.model, data), act), None

    (data, act), _ = jax.lax.scan(substep, (state.data, act), None, length=params.n_substeps)
    key, sub = jax.random.split(state.key)
    sens, readings = read_sensors(params.sensor, state.sensor, sub, data, act.motor_angle_rad, act.motor_vel_rad_per_s)
    return EnvState(data, act, sens, readings, key, state.time_s + dt * params.n_substeps)


def rollout(params: EnvParams, state: EnvState, commands: Command) -> tuple[EnvState, EnvState]:
    """Run a sequence of commands (leading axis = ticks) with ``lax.scan``.

    Returns:
        the final state and the stacked per-tick states (all of ``EnvState``;
        select what you need outside, or write a scan with a smaller output).
    """

    def body(s, c):
        s = step(params, s, c)
        return s, s

    return jax.lax.scan(body, state, commands)


def pelvis_position_m(state: EnvState) -> jax.Array:
    """Pelvis (Waist origin) position in the world, (3,)."""
    return state.data.qpos[:3]
