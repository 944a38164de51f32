"""The scenario of a rollout: payload, slope, terrain, sensor noise and delay, applied to ``EnvParams``.

Seed 001 (Faraji et al., experiments and Fig. 5) judges its controller
blind to: +1 kg on the torso with the CoM 1 cm back, slopes, +-5 cm rough
ground, 3 deg IMU orientation noise with 1 deg joint-encoder noise, and a
10 ms controller-to-robot delay; seed 004 walks 19.7 cm stairs on Atlas.
Every controller meets the same scenarios, so they are parameters of the
rollout (:class:`Scenario`), never controller code.

* **Payload** (``payload_kg`` at ``payload_com_m`` from the CoM of
  ``payload_body``, in the body frame): a point mass added to that body,
  its mass, CoM and inertia combined by the parallel-axis theorem
  (:func:`add_point_mass`); then ``mj_setConst`` on the ``MjModel``
  recomputes what MuJoCo precomputes from them and MJX reads
  (``body_subtreemass``, ``body_invweight0``, ``dof_invweight0``: the
  contact softness), so MJX sees what MuJoCo C sees.
* **Slope** (``slope_deg``, + up the walking direction +x): gravity is
  rotated, ``g = |g| (-sin s, 0, -cos s)``, which is exact for a flat rigid
  floor (the physics of rotating the whole world, floor included) and
  batches (``model.opt.gravity``); the robot starts standing on the floor,
  perpendicular to it. The scene's gravity frame body is set to the
  gravity-aligned frame, so the IMU reads orientation relative to gravity
  (:func:`mjx_coman.sensors.pelvis_quat_gravity`) and the fall judge
  measures tilt from gravity's vertical; heights stay above the floor
  (perpendicular to the slope) and velocities along it.
* **Terrain** (``flat``, ``rough:CM[:SEED]``, ``stairs:CM``): a static scene
  variant (:mod:`mjx_coman.scenarios.terrain`), a new model and a new
  compilation; the fall judge then measures the pelvis height above the
  local terrain (:func:`mjx_coman.ground_truth.judge_on`).
* **Sensor noise**: ``imu_noise_deg`` (std of the IMU orientation error per
  axis) and ``joint_noise_deg`` (white noise on the link encoders; the
  motor encoders, precise optical ones, stay exact); ``None`` keeps the base
  parameters' levels.
* **Delay** (``delay_ms``): an extra controller-to-robot transport delay on
  top of the plant's own, ``delay_ticks += round(delay_ms / control period)``.
* **Actuator** (``actuator``: ``ideal`` or ``sea``): how a torque plant
  realises torque commands (``ActuatorParams.torque_loop``): the desired
  torque at the link, or the series-elastic loop with its bandwidth and lag.

Payload, slope, noise, delay and actuator are arrays of the ``EnvParams``: one
compiled walk covers several (:func:`batched_env_params`, with the
``in_axes`` of :func:`scenario_batch_axes`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_coman.actuators import DELAY_S, MAX_DELAY_TICKS, TORQUE_LOOPS
from mjx_coman.env import EnvParams, batch_axes
from mjx_coman.scenarios.terrain import parse_terrain, scene_model

MAX_PAYLOAD_KG = 30.0
MAX_PAYLOAD_OFFSET_M = 0.5
MAX_SLOPE_DEG = 30.0
MAX_NOISE_DEG = 30.0
PAYLOAD_FIELDS = ("body_mass", "body_ipos", "body_iquat", "body_inertia", "body_subtreemass", "body_invweight0",
                  "dof_invweight0")
BATCH_MODEL_FIELDS = PAYLOAD_FIELDS + ("body_quat",)  # and opt.gravity (see scenario_batch_axes)
NAMES = ("payload_kg", "payload_body", "payload_com_m", "slope_deg", "terrain", "imu_noise_deg", "joint_noise_deg",
         "delay_ms")


@functools.lru_cache(maxsize=1)
def body_names() -> tuple[str, ...]:
    """Body names of the robot (the packaged model; index = body id)."""
    from mjx_coman import load_model

    m = load_model()
    return tuple(m.body(i).name for i in range(m.nbody))


def _number(name: str, v, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name}={v!r} must be a number")
    v = float(v)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{name}={v!r} must lie in [{lo:g}, {hi:g}]")
    return v


@dataclasses.dataclass(frozen=True)
class Scenario:
    """What a rollout's robot and world are (plain values, hashable; see the module docstring).

    Attributes:
        payload_kg: mass added to ``payload_body``, kg (seed 001: 1).
        payload_body: the body that carries it (default the torso, ``DWYTorso``).
        payload_com_m: (3,) the payload's CoM from the body's CoM, in the body frame, m (seed 001: 1 cm
            back, ``(-0.01, 0, 0)``).
        slope_deg: floor slope, + up the walking direction (+x), deg.
        terrain: ``flat``, ``rough:CM[:SEED]`` or ``stairs:CM`` (static: a scene variant).
        imu_noise_deg: std of the IMU orientation noise, deg (``None``: the base parameters').
        joint_noise_deg: std of the link encoder noise, deg (``None``: the base parameters').
        delay_ms: extra controller-to-robot delay, ms (rounded to control ticks).
        actuator: how torque commands are realised, ``"ideal"`` or ``"sea"`` (:data:`mjx_coman.actuators.TORQUE_LOOPS`;
            ``None``: the base parameters'); position and voltage commands do not use it.
    """

    payload_kg: float = 0.0
    payload_body: str = "DWYTorso"
    payload_com_m: tuple = (0.0, 0.0, 0.0)
    slope_deg: float = 0.0
    terrain: str = "flat"
    imu_noise_deg: float | None = None
    joint_noise_deg: float | None = None
    delay_ms: float = 0.0
    actuator: str | None = None

    def validate(self) -> "Scenario":
        """This scenario with its values checked and made canonical (floats, the terrain's text).

        Raises:
            ValueError: naming the bad value.
        """
        kg = _number("payload_kg", self.payload_kg, 0.0, MAX_PAYLOAD_KG)
        if self.payload_body not in body_names()[1:]:
            raise ValueError(f"payload_body={self.payload_body!r} is not a body of the robot; "
                             f"bodies: {', '.join(body_names()[1:])}")
        com = tuple(np.ravel(np.asarray(self.payload_com_m, dtype=object)))
        if len(com) != 3:
            raise ValueError(f"payload_com_m={self.payload_com_m!r} must be 3 numbers (x, y, z in the body frame, m)")
        com = tuple(_number("payload_com_m", c, -MAX_PAYLOAD_OFFSET_M, MAX_PAYLOAD_OFFSET_M) for c in com)
        if self.actuator is not None and self.actuator not in TORQUE_LOOPS:
            raise ValueError(f"actuator={self.actuator!r} must be one of {', '.join(TORQUE_LOOPS)}")
        noise = {}
        for name in ("imu_noise_deg", "joint_noise_deg"):
            v = getattr(self, name)
            noise[name] = None if v is None else _number(name, v, 0.0, MAX_NOISE_DEG)
        return Scenario(payload_kg=kg, payload_body=self.payload_body, payload_com_m=com,
                        slope_deg=_number("slope_deg", self.slope_deg, -MAX_SLOPE_DEG, MAX_SLOPE_DEG),
                        terrain=parse_terrain(self.terrain).text, delay_ms=_number("delay_ms", self.delay_ms, 0.0, 1e3),
                        actuator=self.actuator, **noise)

    def to_dict(self) -> dict:
        """JSON values of every field."""
        d = dataclasses.asdict(self)
        d["payload_com_m"] = list(self.payload_com_m)
        return d


def extra_delay_ticks(delay_ms: float, control_period_s: float) -> int:
    """``round(delay_ms / control period)``: the extra delay in control ticks."""
    return int(round(float(delay_ms) * 1e-3 / float(control_period_s)))


def check_delay(delay_ms: float, base_ticks: int, control_period_s: float) -> int:
    """The total delay in ticks, ``base_ticks`` plus the extra.

    Raises:
        ValueError: naming ``delay_ms`` when the total exceeds ``MAX_DELAY_TICKS``.
    """
    total = int(base_ticks) + extra_delay_ticks(delay_ms, control_period_s)
    if total > MAX_DELAY_TICKS:
        room = (MAX_DELAY_TICKS - int(base_ticks)) * float(control_period_s) * 1e3
        raise ValueError(f"delay_ms={delay_ms:g} brings the transport delay to {total} control ticks, more than "
                         f"MAX_DELAY_TICKS={MAX_DELAY_TICKS} (at most {room:g} ms on top of the plant's own)")
    return total


def nominal_delay_ticks(control_period_s: float) -> int:
    """The position plant's own transport delay in ticks (:data:`mjx_coman.actuators.DELAY_S`; nothing built)."""
    return int(round(DELAY_S / float(control_period_s)))


def add_point_mass(mass_kg: float, ipos_m, iquat, inertia, payload_kg: float, offset_m):
    """A body's inertial properties with a point mass added at ``ipos + offset`` (body frame).

    Parallel-axis theorem: ``I = R diag(I_0) R^T + m0 (|a|^2 E - a a^T) + m (|b|^2 E - b b^T)`` about the
    combined CoM ``c = (m0 ipos + m p) / (m0 + m)``, ``a = ipos - c``, ``b = p - c``; its principal
    moments and axes give MuJoCo's ``body_inertia`` and ``body_iquat``.

    Returns:
        ``(mass, ipos (3,), iquat (4,), inertia (3,))`` as NumPy.
    """
    ipos, off = np.asarray(ipos_m, float), np.asarray(offset_m, float)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(iquat, float))
    rot = rot.reshape(3, 3)
    i_body = rot @ np.diag(np.asarray(inertia, float)) @ rot.T
    p = ipos + off
    total = mass_kg + payload_kg
    com = (mass_kg * ipos + payload_kg * p) / total

    def steiner(m, r):
        return m * (r @ r * np.eye(3) - np.outer(r, r))

    i_new = i_body + steiner(mass_kg, ipos - com) + steiner(payload_kg, p - com)
    w, v = np.linalg.eigh(0.5 * (i_new + i_new.T))
    if np.linalg.det(v) < 0:
        v[:, 0] = -v[:, 0]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, v.ravel())
    return total, com, quat, w


def apply_payload(m: mujoco.MjModel, body: str, payload_kg: float, offset_m) -> mujoco.MjModel:
    """``m`` (modified in place and returned) carrying the payload, with ``mj_setConst`` recomputed."""
    if payload_kg == 0:
        return m
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
    if b < 1:
        raise ValueError(f"payload_body={body!r} is not a body of the model")
    mass, ipos, iquat, inertia = add_point_mass(m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b],
                                                payload_kg, offset_m)
    m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b] = mass, ipos, iquat, inertia
    mujoco.mj_setConst(m, mujoco.MjData(m))
    return m


def slope_gravity(slope_deg: float, g_mps2: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """``(gravity (3,), gravity frame quaternion (4,))`` of a floor sloping ``slope_deg`` up along +x.

    The gravity-aligned frame is the world (floor) frame turned about y by the slope: its z axis,
    ``(sin s, 0, cos s)``, points against gravity.
    """
    s = math.radians(slope_deg)
    return (g_mps2 * np.array([-math.sin(s), 0.0, -math.cos(s)]),
            np.array([math.cos(s / 2), 0.0, math.sin(s / 2), 0.0]))


def needs_scene(scenarios: Sequence[Scenario]) -> bool:
    """Whether the scenarios need a scene variant (a terrain, or a slope and so the gravity frame)."""
    return any(s.terrain != "flat" or s.slope_deg != 0 for s in scenarios)


def _scene_models(base: EnvParams, scenarios: Sequence[Scenario], scene: bool) -> list[mujoco.MjModel]:
    """One ``MjModel`` per scenario carrying its payload and gravity (the scene variant, or the packaged one)."""
    from mjx_coman import load_model

    out = []
    for s in scenarios:
        m = scene_model(s.terrain) if scene else load_model()
        m.opt.timestep = float(base.model.opt.timestep)
        if scene:
            from mjx_coman.sensors import model_ids

            g, q = slope_gravity(s.slope_deg, float(np.linalg.norm(m.opt.gravity)))
            m.opt.gravity[:] = g
            m.body_quat[model_ids()["n_robot_bodies"]] = q
        out.append(apply_payload(m, s.payload_body, s.payload_kg, s.payload_com_m))
    return out


def batched_env_params(base: EnvParams, scenarios: Sequence[Scenario],
                       scene: bool = False) -> tuple[EnvParams, EnvParams]:
    """``(params, in_axes)``: ``base`` under each scenario, stacked on a leading axis, for ``jax.vmap``.

    The scenarios must share their terrain (a static scene). With no terrain, no slope and ``scene`` false
    the model is ``base.model`` with the payload fields replaced; otherwise the scene variant's (``scene``:
    always, so that flat and sloped batches are one program) (with ``base``'s
    timestep: other changes of ``base.model`` are not carried over). Actuator and sensor leaves are all
    stacked; the model's :data:`BATCH_MODEL_FIELDS` and ``opt.gravity`` are.

    Raises:
        ValueError: an empty list, a bad scenario value, different terrains, a total delay beyond
            ``MAX_DELAY_TICKS``.
    """
    if not scenarios:
        raise ValueError("scenarios is empty")
    scenarios = [s.validate() for s in scenarios]
    terrains = sorted({s.terrain for s in scenarios})
    if len(terrains) > 1:
        raise ValueError(f"terrain differs within one batch ({', '.join(terrains)}): each terrain is its own "
                         "scene and compilation")
    period = float(base.control_period_s)
    base_ticks = int(np.asarray(base.actuator.delay_ticks))
    ticks = [check_delay(s.delay_ms, base_ticks, period) for s in scenarios]
    n = len(scenarios)
    scene = scene or needs_scene(scenarios)
    models = _scene_models(base, scenarios, scene)
    model = mjx.put_model(models[0]) if scene else base.model
    fields = {f: jnp.asarray(np.stack([getattr(m, f) for m in models]), getattr(model, f).dtype)
              for f in BATCH_MODEL_FIELDS}
    gravity = jnp.asarray(np.stack([m.opt.gravity for m in models]), model.opt.gravity.dtype)
    model = model.replace(opt=model.opt.replace(gravity=gravity), **fields)

    def stack(tree):
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(jnp.asarray(x), (n,) + jnp.shape(x)), tree)

    act = stack(base.actuator)
    loop = [act.torque_loop[i] if s.actuator is None else TORQUE_LOOPS[s.actuator] for i, s in enumerate(scenarios)]
    act = dataclasses.replace(act, delay_ticks=jnp.asarray(ticks, act.delay_ticks.dtype),
                              torque_loop=jnp.asarray(loop, act.torque_loop.dtype))
    sen = stack(base.sensor)
    for name, field in (("imu_noise_deg", "imu_orientation_noise_rad"), ("joint_noise_deg", "joint_noise_rad")):
        old = getattr(sen, field)
        vals = [math.radians(getattr(s, name)) if getattr(s, name) is not None else None for s in scenarios]
        new = jnp.asarray([old[i] if v is None else v for i, v in enumerate(vals)], old.dtype)
        sen = dataclasses.replace(sen, **{field: new})
    engine = base.engine.for_model(models[0]) if scene else base.engine
    params = dataclasses.replace(base, model=model, actuator=act, sensor=sen, engine=engine)
    return params, scenario_batch_axes(params)


def scenario_batch_axes(params: EnvParams) -> EnvParams:
    """``in_axes`` of :func:`batched_env_params`: ``batch_axes`` with the scenario's model fields and ``opt.gravity``."""
    axes = batch_axes(params, model_fields=BATCH_MODEL_FIELDS)
    opt = jax.tree_util.tree_map(lambda _: None, params.model.opt).replace(gravity=0)
    return dataclasses.replace(axes, model=axes.model.replace(opt=opt))


def select(params: EnvParams, axes: EnvParams, i) -> EnvParams:
    """Row ``i`` (an int or a traced index) of batched parameters."""
    return jax.tree_util.tree_map(lambda a, x: x if a is None else x[i], axes, params, is_leaf=lambda a: a is None)


def scenario_env_params(base: EnvParams, scenario: Scenario) -> EnvParams:
    """``base`` under one scenario (see :func:`batched_env_params`; the same values, unbatched)."""
    params, axes = batched_env_params(base, [scenario])
    return select(params, axes, 0)

