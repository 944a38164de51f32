"""Closed-loop environment steps per second of the MJX sweep, against native MuJoCo driven from NumPy.

    python bench/sweep_throughput.py [--batch 1 16 64] [--seconds 0.8] [--native-seconds 2] [--json]

MJX side: the sweep's own rollout (``sweeps.models.mjx``: one pushed walk of
COMAN under the registered ``time-projection`` controller of
``mjx_coman.controllers``), jitted and vmapped over ``--batch`` rollouts of
``--seconds`` each, as ``coman-sweep map --model mjx`` runs a chunk.
Compilation is timed apart; the best of ``--repeats`` timed calls counts.

Peer baseline: what a researcher writes without this tool, one rollout at a
time: ``mujoco.mj_step`` on the same scene (``mjx_coman.model_path()``, 1 ms
timestep, 2 physics steps per 2 ms control tick) with the same actuator model
in NumPy (eq. 25 position loop on the motor shaft with the same gains and the
20 ms delay line, series springs and motors of eq. 19-20), the sensors read
from ``MjData`` (backlash, 12-bit encoders, IMU noise, foot forces from
``mj_contactForce``) and the same walking controller: the source of
``mjx_coman.controllers.time_projection.controller.step`` (estimation, eq. 26-27, table B,
adaptive lift, IK, eq. 21 and 24) executed by NumPy through
``bench/numpy_twin.py`` (``pytest -m slow tests/bench`` checks it gives the
JAX controller's targets). That controller costs about 2,600 Python-level NumPy calls a tick
(about 110 of them ``np.stack`` calls, most building 3x3 rotations);
a hand-tuned port (scalar ``math`` for the rotations, say) would be faster,
so the run also times the physics alone (the same walk replaying the recorded
targets through the delay line, SEA model and ``mj_step``): the bound no
NumPy controller can beat, ``native_physics_only_steps_per_s``.

One environment step = one 2 ms control tick of one robot (2 physics steps).
Prints ``{"mjx_steps_per_s": {batch: steps/s}, "native_steps_per_s": ...,
"ratio": best MJX / native, "native_physics_only_steps_per_s": ..., "ratio_to_physics_only": ...,
"backend": ..., "device": ...}`` (``--json``).
"""

from __future__ import annotations

from jaxlp.xla_flags import configure_cpu

configure_cpu()  # the project's XLA CPU flags, before JAX starts (jaxlp.xla_flags)

import argparse  # noqa: E402
import os
import platform
import time

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import numpy_twin  # noqa: E402  (bench/: run as python bench/sweep_throughput.py)
from jaxlp.files import strict_json  # noqa: E402
from sweeps.grid import SweepConfig  # noqa: E402
from sweeps.models import RolloutInputs  # noqa: E402
from sweeps.models import mjx as model_mjx  # noqa: E402
from sweeps.runner import rollout_keys  # noqa: E402

STEP_TIME_S = 0.4


def sweep_config(seconds: float, batch: int, controller: str = "time-projection") -> SweepConfig:
    n_steps = max(1, int(round(seconds / STEP_TIME_S)) - 1)  # the walk adds its start-up phase
    return SweepConfig(model="mjx", controller=controller, phases=(0.5,), impulses_ns=(2.0,), n_steps=n_steps,
                       push_step=min(1, n_steps - 1), chunk=batch)


def mjx_throughput(batch: int, seconds: float, repeats: int) -> dict:
    """Env steps/s of a batch of sweep rollouts (compilation apart)."""
    cfg = sweep_config(seconds, batch).compiled_part()
    model = model_mjx.load()
    idx = np.arange(batch, dtype=np.int32)
    inputs = RolloutInputs(index=jnp.asarray(idx), key=jnp.asarray(rollout_keys(0, idx)),
                           phase=jnp.asarray(np.linspace(0.0, 0.9, batch), jnp.float32),
                           impulse_ns=jnp.asarray(np.linspace(0.0, 4.0, batch), jnp.float32),
                           direction_rad=jnp.zeros(batch, jnp.float32))
    model.prepare(cfg, inputs)
    fn = jax.jit(jax.vmap(lambda i: model.rollout(cfg, i, None)))
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(inputs))
    compile_s = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(inputs))
        best = min(best, time.perf_counter() - t0)
    ticks = model.ticks_per_rollout(cfg)
    return dict(batch=batch, ticks=ticks, seconds=best, first_call_s=compile_s, env_steps_per_s=batch * ticks / best,
                fell=int(np.sum(np.asarray(out.fell))))


class NativeSensors:
    """COMAN's sensors read from ``mujoco.MjData`` with the project's sensor functions run by NumPy."""

    def __init__(self, m, sensor_params: dict, seed: int = 0):
        from mjx_coman import sensors

        self.m, self.p = m, sensor_params
        self.rng = np.random.default_rng(seed)
        self.backlash, self.quantize = numpy_twin.twin(sensors.backlash), numpy_twin.twin(sensors.quantize)
        self.quat_mul, self.quat_to_rpy = numpy_twin.twin(sensors.quat_mul), numpy_twin.twin(sensors.quat_to_rpy)
        self.small_rotation = numpy_twin.twin(sensors._small_rotation_quat)
        self.Readings = sensors.Readings
        feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("RFoot", "LFoot")]
        self.foot_of_body = {b: i for i, b in enumerate(feet)}  # (right, left), as Readings
        self.force = np.zeros(6)

    def reset(self, q):
        self.out = np.array(q, float)

    def read(self, d, motor_angle, motor_vel, pelvis_body):
        p = self.p
        self.out = self.backlash(self.out, d.qpos[7:], p["backlash_rad"])
        link = self.quantize(self.out + p["encoder_offset_rad"], p["encoder_resolution_rad"])
        noise = p["imu_orientation_noise_rad"] * self.rng.standard_normal(3)
        quat = self.quat_mul(d.xquat[pelvis_body], self.small_rotation(noise))
        quat = quat / np.linalg.norm(quat)
        normal = np.zeros(2)
        for i in range(d.ncon):
            c = d.contact[i]
            foot = self.foot_of_body.get(self.m.geom_bodyid[c.geom2], self.foot_of_body.get(self.m.geom_bodyid[c.geom1]))
            if foot is None:
                continue
            mujoco.mj_contactForce(self.m, d, i, self.force)
            normal[foot] += abs(self.force[:3] @ c.frame.reshape(3, 3)[:, 2])  # world z of the contact force
        gyro = d.qvel[3:6] + p["gyro_noise_rad_per_s"] * self.rng.standard_normal(3)
        zeros = np.zeros(6)
        return self.Readings(
            link_angle_rad=link, motor_angle_rad=numpy_twin.as_twin(motor_angle), motor_vel_rad_per_s=motor_vel,
            imu_quat=quat, imu_rpy_rad=self.quat_to_rpy(quat), gyro_rad_per_s=gyro, ft_right=zeros, ft_left=zeros,
            foot_normal_force_n=numpy_twin.as_twin(normal), contact=normal > p["contact_threshold_n"])


class NativeCOMAN:
    """COMAN in native MuJoCo, the SEA actuator model in NumPy, the walking controller run by NumPy.

    The controller is :func:`mjx_coman.controllers.time_projection.controller.step` itself, executed
    by NumPy through :mod:`numpy_twin` (same source, same parameters as the
    sweep's ``mjx`` model); the sensors are read from ``mujoco.MjData`` by the
    project's sensor functions (backlash, 12-bit quantisation, IMU noise, RPY),
    also twinned, and the foot normal forces from ``mujoco.mj_contactForce``.
    F/T wrenches and gyro rates, which the controller does not read, are not
    computed.
    """

    def __init__(self, seconds: float, seed: int = 0):
        from mjx_coman import model_path
        from mjx_coman.actuators import MAX_DELAY_TICKS, SEA_MASK
        from mjx_coman.env import standing_posture
        from mjx_coman.controllers import joystick
        from mjx_coman.controllers.base import Observation
        from mjx_coman.controllers.time_projection import controller
        from mjx_coman.sensors import model_ids

        cfg = sweep_config(seconds, 1).compiled_part()
        env, (_, ctrl) = model_mjx.nominal_env(cfg.sensor_noise_scale), model_mjx.controller(cfg)
        self.Observation, self.joystick = Observation, numpy_twin.to_twin_tree(joystick(cfg.speed_mps))
        self.m = mujoco.MjModel.from_xml_path(str(model_path()))
        self.m.opt.timestep = float(env.model.opt.timestep)
        self.d = mujoco.MjData(self.m)
        self.a = {k: np.asarray(v, float) for k, v in env.actuator.__dict__.items()}
        self.sen = {k: np.asarray(v, float) for k, v in env.sensor.__dict__.items()}
        self.sea = np.asarray(SEA_MASK)
        self.delay = int(env.actuator.delay_ticks)
        self.buf_len = MAX_DELAY_TICKS + 1
        self.n_sub = int(env.n_substeps)
        self.knee_rad = float(ctrl.knee_rad)
        self.cp = numpy_twin.to_twin_tree(ctrl)
        self.ctl_init, self.ctl_step = numpy_twin.twin(controller.init), numpy_twin.twin(controller.step)
        self.sensors = NativeSensors(self.m, self.sen, seed)
        self.pelvis = model_ids()["pelvis_body"]
        self.q0, self.root = standing_posture(self.knee_rad)

    def reset(self):
        mujoco.mj_resetData(self.m, self.d)
        self.d.qpos[:7] = self.root
        self.d.qpos[7:] = self.q0
        mujoco.mj_forward(self.m, self.d)
        self.th = np.array(self.q0, float)
        self.dth = np.zeros_like(self.th)
        self.buf = np.tile(self.q0, (self.buf_len, 1))
        self.k = 0
        self.sensors.reset(self.d.qpos[7:])
        self.cs = self.ctl_init(self.cp)
        self.targets = []

    def _substep(self, target):
        a = self.a
        q, dq = self.d.qpos[7:], self.d.qvel[6:]
        v = np.clip(a["kp_v_per_rad"] * (target - self.th), -a["supply_v"], a["supply_v"])
        k, b = a["spring_stiffness_nm_per_rad"], a["spring_damping_nms_per_rad"]
        tau_spring = k * (self.th - q) + b * (self.dth - dq)
        visc = a["alpha_v_s_per_rad"] / a["beta_v_per_nm"] + a["friction_nms_per_rad"]
        rhs = v / a["beta_v_per_nm"] - k * (self.th - q) + b * dq
        jm, dt = a["rotor_inertia_nms2_per_rad"], self.m.opt.timestep
        dth = (jm * self.dth + dt * rhs) / (jm + dt * (visc + b))
        th = self.th + dt * dth
        tau_rigid = v / a["beta_v_per_nm"] - (a["alpha_v_s_per_rad"] / a["beta_v_per_nm"] + a["friction_nms_per_rad"]) * dq
        self.d.ctrl[:] = np.where(self.sea, tau_spring, tau_rigid)
        self.th, self.dth = np.where(self.sea, th, q), np.where(self.sea, dth, dq)
        mujoco.mj_step(self.m, self.d)

    def actuate(self, target: np.ndarray) -> None:
        """Delay line and the physics steps of one 2 ms tick."""
        self.buf[self.k % self.buf_len] = target
        delayed = self.buf[(self.k - self.delay) % self.buf_len]
        for _ in range(self.n_sub):
            self._substep(delayed)
        self.k += 1

    def step(self) -> np.ndarray:
        """One 2 ms control tick: sensors, the walking controller, delay line, physics; returns the target."""
        readings = self.sensors.read(self.d, self.th, self.dth, self.pelvis)
        obs = self.Observation(readings, self.joystick, self.k * 0.002)
        self.cs, cmd, _ = self.ctl_step(self.cp, self.cs, obs)
        target = np.asarray(cmd.target, float)
        self.actuate(target)
        return target


def native_throughput(seconds: float, repeats: int) -> dict:
    """Env steps/s of the native MuJoCo + NumPy controller loop, one rollout at a time.

    Also times the physics alone: the same walk replaying the recorded targets
    (delay line, SEA model, ``mj_step``), the part no controller can shave off.
    """
    n = int(round(seconds / 0.002))
    sim = NativeCOMAN(seconds)
    best = replay = float("inf")
    for _ in range(repeats):
        sim.reset()
        t0 = time.perf_counter()
        targets = [sim.step() for _ in range(n)]
        best = min(best, time.perf_counter() - t0)
        fell = bool(sim.d.xpos[sim.pelvis][2] < 0.3)
        sim.reset()
        t0 = time.perf_counter()
        for target in targets:
            sim.actuate(target)
        replay = min(replay, time.perf_counter() - t0)
    return dict(ticks=n, seconds=best, env_steps_per_s=n / best, fell=fell,
                physics_steps_per_s=sim.n_sub * n / best, physics_only_env_steps_per_s=n / replay)


def main(argv=None) -> int:
    gpu = jax.default_backend() != "cpu"
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 256, 1024, 4096] if gpu else [1, 16, 64])
    ap.add_argument("--seconds", type=float, default=4.0 if gpu else 0.8, help="walk length of the MJX batches, s")
    ap.add_argument("--native-seconds", type=float, default=2.0, help="walk length of the native loop, s")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if min(args.batch) < 1 or args.seconds <= 0 or args.native_seconds <= 0 or args.repeats < 1:
        ap.error("--batch, --seconds, --native-seconds and --repeats must be positive")
    mjx_runs = [mjx_throughput(b, args.seconds, args.repeats) for b in args.batch]
    native = native_throughput(args.native_seconds, args.repeats)
    best = max(r["env_steps_per_s"] for r in mjx_runs)
    out = dict(
        mjx_steps_per_s={str(r["batch"]): round(r["env_steps_per_s"], 1) for r in mjx_runs},
        native_steps_per_s=round(native["env_steps_per_s"], 1),
        ratio=round(best / native["env_steps_per_s"], 3),
        native_physics_only_steps_per_s=round(native["physics_only_env_steps_per_s"], 1),
        ratio_to_physics_only=round(best / native["physics_only_env_steps_per_s"], 3),
        backend=f"MJX (JAX {jax.__version__}, {jax.default_backend()}); no Warp",
        device=str(jax.devices()[0]) + (f" x{jax.device_count()}" if jax.device_count() > 1 else ""),
        env_step="one 2 ms control tick of one robot (2 physics steps of 1 ms)",
        cpu_count=os.cpu_count(), machine=platform.machine(), mujoco=mujoco.__version__,
        mjx_runs=mjx_runs, native=native,
    )
    if args.json:
        print(strict_json(out, indent=1))
    else:
        for r in mjx_runs:
            print(f"MJX batch {r['batch']:5d}: {r['env_steps_per_s']:12.0f} env steps/s "
                  f"(first call {r['first_call_s']:.1f} s)")
        print(f"native MuJoCo + NumPy: {native['env_steps_per_s']:12.0f} env steps/s; ratio {out['ratio']:.2f}")
        print(f"native physics alone:  {native['physics_only_env_steps_per_s']:12.0f} env steps/s; "
              f"ratio {out['ratio_to_physics_only']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
