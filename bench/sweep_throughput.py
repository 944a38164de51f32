"""Closed-loop environment steps per second of the MJX sweep, against native MuJoCo driven from NumPy.

    python bench/sweep_throughput.py [--batch 1 16 64] [--seconds 0.8] [--native-seconds 2] [--json]

MJX side: the sweep's own rollout (``sweeps.model_mjx``: one pushed walk of
COMAN under the time-projection walking controller of
``mjx_coman.walking``), jitted and vmapped over ``--batch`` rollouts of
``--seconds`` each, as ``coman-sweep map --model mjx`` runs a chunk.
Compilation is timed apart; the best of ``--repeats`` timed calls counts.

Peer baseline: what a researcher writes without this tool, one rollout at a
time: ``mujoco.mj_step`` on the same scene (``mjx_coman.model_path()``, 1 ms
timestep, 2 physics steps per 2 ms control tick) with the same actuator model
in NumPy (eq. 25 position loop on the motor shaft with the same gains and the
20 ms delay line, series springs and motors of eq. 19-20), fed the position
targets the MJX open-loop controller produces for the same walk, plus a
NumPy time-projection footstep feedback each tick: pelvis and swing foot
relative to the stance foot, IIR filter (eq. 26), 30-sample velocity average,
error against the nominal 3LP gait, smooth dead-zone (eq. 27), table-B
footstep adjustment truncated at 0.35 h1, added to the swing hip pitch as an
attack angle. It skips the per-tick inverse kinematics and the sensor model
of the MJX controller, so it does less work per step than the MJX side.

One environment step = one 2 ms control tick of one robot (2 physics steps).
Prints ``{"mjx_steps_per_s": {batch: steps/s}, "native_steps_per_s": ...,
"ratio": best MJX / native, "backend": ..., "device": ...}`` (``--json``).
"""

from __future__ import annotations

import jaxlp  # noqa: F401  (XLA CPU flags before JAX starts)

import argparse
import json
import os
import platform
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from sweeps import model_mjx
from sweeps.grid import SweepConfig
from sweeps.models import RolloutInputs
from sweeps.runner import rollout_keys

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


class NativeCOMAN:
    """COMAN in native MuJoCo with the SEA actuator model and a NumPy time-projection footstep feedback."""

    def __init__(self):
        from mjx_coman import model_path
        from mjx_coman.actuators import MAX_DELAY_TICKS, SEA_MASK, make_actuator_params
        from mjx_coman.env import make_env_params, standing_posture
        from mjx_coman.sensors import model_ids
        from mjx_coman.walking.controller import LEFT_HIP_PITCH, RIGHT_HIP_PITCH, make_controller_params

        self.m = mujoco.MjModel.from_xml_path(str(model_path()))
        self.m.opt.timestep = 0.001
        self.d = mujoco.MjData(self.m)
        a = make_actuator_params(control_period_s=0.002)
        self.a = {k: np.asarray(v, float) for k, v in a.__dict__.items()}
        self.sea = np.asarray(SEA_MASK)
        self.delay = int(a.delay_ticks)
        self.buf_len = MAX_DELAY_TICKS + 1
        ctrl = make_controller_params(make_env_params())
        self.table = np.asarray(ctrl.footstep_table, float)  # (n, 4)
        self.nominal = np.asarray(ctrl.nominal_base, float)  # (n + 1, 2, 6), d = +1
        self.deadzone = np.asarray(ctrl.deadzone, float)
        self.zeta = float(ctrl.zeta)
        self.h1 = float(ctrl.h1_m)
        self.trunc = float(ctrl.truncation_m)
        self.n = int(ctrl.ticks_per_step)
        self.hips = (LEFT_HIP_PITCH, RIGHT_HIP_PITCH)
        ids = model_ids()
        self.pelvis = ids["pelvis_body"]
        self.feet = (mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, "LFoot"),
                     mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, "RFoot"))
        self.q0, self.root = standing_posture()

    def reset(self):
        mujoco.mj_resetData(self.m, self.d)
        self.d.qpos[:7] = self.root
        self.d.qpos[7:] = self.q0
        mujoco.mj_forward(self.m, self.d)
        self.th = np.array(self.q0, float)
        self.dth = np.zeros_like(self.th)
        self.buf = np.tile(self.q0, (self.buf_len, 1))
        self.k = 0
        self.filt = None
        self.hist = []

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

    def _footstep_feedback(self, tick: int, d: float) -> float:
        """Time-projection footstep adjustment from the sagittal error (NumPy, ideal position sensing)."""
        left, right = self.d.xpos[self.feet[0]], self.d.xpos[self.feet[1]]
        stance, swing = (right, left) if d > 0 else (left, right)
        raw = np.array([swing[0] - stance[0], self.d.xpos[self.pelvis][0] - stance[0]])
        if self.filt is None or tick == 0:
            self.filt, self.hist = raw.copy(), []
        self.filt = self.zeta * raw + (1 - self.zeta) * self.filt  # eq. 26
        self.hist = (self.hist + [self.filt.copy()])[-31:]
        vel = (self.hist[-1] - self.hist[0]) / (0.002 * max(1, len(self.hist) - 1))  # 30-sample average
        nom = self.nominal[tick, 0]
        e = np.array([self.filt[0] - (nom[0] - nom[2]), self.filt[1] - (nom[1] - nom[2]),
                      vel[0] - (nom[3] - nom[5]), vel[1] - (nom[4] - nom[5])])
        a = self.deadzone
        e = e - np.arctan(np.pi * e / (2.0 * a)) * 2.0 * a / np.pi  # eq. 27
        return float(np.clip(self.table[min(tick, self.n - 1)] @ e, -self.trunc, self.trunc))

    def step(self, target: np.ndarray) -> None:
        """One 2 ms control tick: feedback, delay line, two physics steps."""
        k = self.k
        phase_tick, step = k % self.n, k // self.n
        d = 1.0 if step % 2 == 0 else -1.0
        target = np.array(target, float)
        if step >= 1:  # walking phases (the first is the start-up phase)
            target[self.hips[0] if d > 0 else self.hips[1]] -= self._footstep_feedback(phase_tick, d) / self.h1
        self.buf[k % self.buf_len] = target
        delayed = self.buf[(k - self.delay) % self.buf_len]
        for _ in range(2):
            self._substep(delayed)
        self.k += 1


def open_loop_targets(seconds: float) -> np.ndarray:
    """The MJX open-loop controller's motor targets of one unpushed walk, (ticks, NU)."""
    from mjx_coman.walking.rollout import WalkSpec, no_push, walk

    env, ctrl = model_mjx.nominal(sweep_config(seconds, 1).compiled_part())
    spec = WalkSpec(controller="open-loop", seconds=seconds, step_time_s=STEP_TIME_S, record_every=1)
    r = jax.jit(lambda k: walk(env, ctrl, no_push(), spec, k))(jax.random.PRNGKey(0))
    return np.asarray(r.trace.target_rad, float)


def native_throughput(seconds: float, repeats: int) -> dict:
    """Env steps/s of the NumPy + native MuJoCo loop, one rollout at a time."""
    targets = open_loop_targets(seconds)
    sim = NativeCOMAN()
    best, fell = float("inf"), False
    for _ in range(repeats):
        sim.reset()
        t0 = time.perf_counter()
        for target in targets:
            sim.step(target)
        best = min(best, time.perf_counter() - t0)
        fell = bool(sim.d.xpos[sim.pelvis][2] < 0.3)
    return dict(ticks=len(targets), seconds=best, env_steps_per_s=len(targets) / best, fell=fell,
                physics_steps_per_s=2 * len(targets) / best)


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
        backend=f"MJX (JAX {jax.__version__}, {jax.default_backend()}); no Warp",
        device=str(jax.devices()[0]) + (f" x{jax.device_count()}" if jax.device_count() > 1 else ""),
        env_step="one 2 ms control tick of one robot (2 physics steps of 1 ms)",
        cpu_count=os.cpu_count(), machine=platform.machine(), mujoco=mujoco.__version__,
        mjx_runs=mjx_runs, native=native,
    )
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for r in mjx_runs:
            print(f"MJX batch {r['batch']:5d}: {r['env_steps_per_s']:12.0f} env steps/s "
                  f"(first call {r['first_call_s']:.1f} s)")
        print(f"native MuJoCo + NumPy: {native['env_steps_per_s']:12.0f} env steps/s; ratio {out['ratio']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
