"""The former peer of ``bench/sweep_throughput.py``: COMAN in MuJoCo C with the walking controller's own source
executed by NumPy (:mod:`numpy_twin`), one rollout at a time.

About 2,600 Python-level NumPy calls a tick (about 110 of them ``np.stack`` calls, most building 3x3 rotations):
what a line-by-line NumPy port of the controller costs, not what a user of MuJoCo C with a compiled controller
pays (the peer of the bench now). ``pytest -m slow tests/bench`` checks the twin gives the JAX controller's targets.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

import numpy_twin  # bench/: run as python bench/sweep_throughput.py


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


class TwinCOMAN:
    """COMAN in native MuJoCo, the SEA actuator model in NumPy, the walking controller run by NumPy.

    The controller is :func:`mjx_coman.controllers.time_projection.controller.step` itself, executed
    by NumPy through :mod:`numpy_twin` (same source, same parameters as the
    sweep's ``mjx`` model); the sensors are read from ``mujoco.MjData`` by the
    project's sensor functions (backlash, 12-bit quantisation, IMU noise, RPY),
    also twinned, and the foot normal forces from ``mujoco.mj_contactForce``.
    F/T wrenches and gyro rates, which the controller does not read, are not
    computed.
    """

    def __init__(self, seed: int = 0):
        from mjx_coman import model_path
        from mjx_coman.actuators import MAX_DELAY_TICKS, SEA_MASK
        from mjx_coman.env import standing_posture
        from mjx_coman.controllers import joystick
        from mjx_coman.controllers.base import Observation
        from mjx_coman.controllers.time_projection import controller
        from mjx_coman.sensors import model_ids

        from mjx_coman.controllers import load
        from mjx_coman.rollout import plant_env_params

        ctrl = load("time-projection")[1]
        env = plant_env_params("position")
        self.Observation, self.joystick = Observation, numpy_twin.to_twin_tree(joystick(0.0))
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


def twin_throughput(seconds: float, repeats: int) -> dict:
    """Env steps/s of the native MuJoCo + NumPy-twin controller loop, one rollout at a time (and of the same walk
    replaying its recorded targets through the NumPy delay line, SEA model and ``mj_step``)."""
    n = int(round(seconds / 0.002))
    sim = TwinCOMAN()
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
