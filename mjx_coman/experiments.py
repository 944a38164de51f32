"""Longer checks of the simulated COMAN against seed 000, with their numbers.

``python -m mjx_coman.experiments {stand,ankle,knee} [--json]``

* ``stand``: crouched standing (knees 0.4 rad) under position control; pelvis
  drift and the spring deflections that make the actual posture differ from
  the commanded "ghost" one (seed, "The Ghost Robot", Figure 5).
* ``ankle``: a slow horizontal pull on the upper torso ramping to 7 N (seed,
  "Effective Ankle Stiffness", Figure 20); pelvis displacement and effective
  stiffness per ankle, against the spring (390 N m/rad) in series with the
  position loop (k_p / beta = 500 / 0.45 ~ 1100 N m/rad).
* ``knee``: a 1 rad knee step on the robot floating without gravity; the motor
  saturates at 15 V near ``15 / (alpha + beta A_c) = 2.43`` rad/s (seed,
  "Actuator Limitations").

Each function jits one scan over the ticks and returns plain floats and
(decimated) time series as NumPy arrays.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.cliutil import Parser, interrupted, refuse
from jaxlp.files import strict_json
from mjx_coman.actuators import JOINT_INDEX, NU, make_actuator_params, series_stiffness_nm_per_rad
from mjx_coman.env import EnvParams, EnvState, make_command, make_env_params, reset, standing_posture, step
from mjx_coman.sensors import model_ids


def _record(s: EnvState) -> dict:
    d = s.data
    return dict(
        time_s=s.time_s,
        pelvis_m=d.qpos[:3],
        root_quat=d.qpos[3:7],
        q_rad=d.qpos[7:],
        motor_rad=s.actuator.motor_angle_rad,
        motor_vel=s.actuator.motor_vel_rad_per_s,
        link_vel=d.qvel[6:],
        ft_r=s.readings.ft_right,
        ft_l=s.readings.ft_left,
        normal_n=s.readings.foot_normal_force_n,
    )


CHUNK_TICKS = 250  # one compiled scan length serves every experiment

_reset = jax.jit(reset, static_argnames=("knee_rad",))


@jax.jit
def _run_chunk(params: EnvParams, state: EnvState, targets: jax.Array, forces: jax.Array) -> tuple[EnvState, dict]:
    def body(s, tf):
        s = step(params, s, make_command(tf[0], tf[1]))
        return s, _record(s)

    return jax.lax.scan(body, state, (targets, forces))


def run(params: EnvParams, state: EnvState, targets, forces) -> tuple[EnvState, dict]:
    """Step through per-tick targets (T, NU) and torso forces (T, 3); record every tick.

    Runs fixed-length jitted chunks of ``CHUNK_TICKS`` (one compilation for
    any duration); the last chunk is padded with its last command, so the
    returned state is that after the padded ticks while the records are trimmed to T.
    """
    targets = np.asarray(targets, np.float32)
    forces = np.asarray(forces, np.float32)
    n = targets.shape[0]
    pad = (-n) % CHUNK_TICKS
    targets = np.concatenate([targets, np.repeat(targets[-1:], pad, 0)])
    forces = np.concatenate([forces, np.repeat(forces[-1:], pad, 0)])
    recs = []
    for c in range(0, n + pad, CHUNK_TICKS):
        state, rec = _run_chunk(params, state, jnp.asarray(targets[c:c + CHUNK_TICKS]),
                                jnp.asarray(forces[c:c + CHUNK_TICKS]))
        recs.append(jax.tree_util.tree_map(np.asarray, rec))
    rec = {k: np.concatenate([r[k] for r in recs])[:n] for k in recs[0]}
    return state, rec


def stand(duration_s: float = 10.0, params: EnvParams | None = None, seed: int = 0) -> dict:
    """Hold the crouched posture for ``duration_s`` under eq. 25 position control.

    Returns:
        pelvis drift (horizontal, m), height change, per-joint knee/ankle/hip
        pitch deflections (actual link minus commanded, rad), spring torques,
        whether it stayed up, and decimated series.
    """
    params = params or make_env_params()
    q0, _ = standing_posture()
    n = int(round(duration_s / float(params.control_period_s)))
    s0 = _reset(jax.random.PRNGKey(seed), params)
    _, rec = run(params, s0, np.broadcast_to(q0, (n, NU)), np.zeros((n, 3)))
    p0 = np.asarray(s0.data.qpos[:3])
    drift = rec["pelvis_m"] - p0
    out = dict(duration_s=duration_s, stayed_up=bool(rec["pelvis_m"][:, 2].min() > p0[2] - 0.1),
               pelvis_drift_xy_m=float(np.linalg.norm(drift[-1, :2])),
               pelvis_max_drift_xy_m=float(np.linalg.norm(drift[:, :2], axis=1).max()),
               pelvis_height_change_m=float(drift[-1, 2]))
    k = np.asarray(params.actuator.spring_stiffness_nm_per_rad)
    for j in ("RHipSag", "RKneeSag", "RAnkSag", "LHipSag", "LKneeSag", "LAnkSag"):
        i = JOINT_INDEX[j]
        out[f"{j}_actual_minus_commanded_rad"] = float(rec["q_rad"][-1, i] - q0[i])
        out[f"{j}_spring_deflection_rad"] = float(rec["motor_rad"][-1, i] - rec["q_rad"][-1, i])
        out[f"{j}_spring_torque_nm"] = float(k[i] * (rec["motor_rad"][-1, i] - rec["q_rad"][-1, i]))
    out["series"] = dict(t=rec["time_s"][::50], pelvis_m=rec["pelvis_m"][::50], q_rad=rec["q_rad"][::50],
                         motor_rad=rec["motor_rad"][::50], root_quat=rec["root_quat"][::50])
    out["commanded_rad"] = np.asarray(q0)
    return out


def ankle_stiffness(max_pull_n: float = 7.0, ramp_s: float = 4.0, hold_s: float = 1.0,
                    params: EnvParams | None = None, settle_s: float = 2.0) -> dict:
    """Pull the upper torso forward with a force ramping to ``max_pull_n`` (seed Figure 20).

    The robot first settles for ``settle_s`` (baseline), then the force ramps
    linearly over ``ramp_s`` and is held for ``hold_s``. Per ankle, the
    effective stiffness is the least-squares slope of the ankle pitch torque
    (F/T moment about the ankle axis) against the ankle pitch link angle from
    half-way through the settling on; the end-point changes are reported too.

    Returns:
        pelvis and torso displacement (m), per-ankle torque, angle and
        effective stiffness, the series prediction and decimated series.
    """
    params = params or make_env_params()
    q0, _ = standing_posture()
    dt = float(params.control_period_s)
    n0, n1, n2 = (int(round(x / dt)) for x in (settle_s, ramp_s, hold_s))
    force = np.concatenate([np.zeros(n0), np.linspace(0, max_pull_n, n1), np.full(n2, max_pull_n)])
    forces = np.zeros((force.size, 3), np.float32)
    forces[:, 0] = force
    s0 = _reset(jax.random.PRNGKey(0), params)
    _, rec = run(params, s0, np.broadcast_to(q0, (force.size, NU)), forces)
    b, e = n0 - 1, -1
    out = dict(max_pull_n=max_pull_n,
               pelvis_displacement_m=float(np.mean(rec["pelvis_m"][e - 50:, 0]) - np.mean(rec["pelvis_m"][b - 50:b, 0])))
    stiff = []
    for side, ft in (("R", "ft_r"), ("L", "ft_l")):
        i = JOINT_INDEX[side + "AnkSag"]
        # The F/T site is 0.065 m below the ankle axis: moment about the axis = m_y - f_x * 0.065.
        tau = rec[ft][:, 4] - rec[ft][:, 0] * 0.065
        dtau = float(np.mean(tau[e - 50:]) - np.mean(tau[b - 50:b]))
        dq = float(np.mean(rec["q_rad"][e - 50:, i]) - np.mean(rec["q_rad"][b - 50:b, i]))
        out[f"{side}_ankle_torque_change_nm"] = dtau
        out[f"{side}_ankle_angle_change_rad"] = dq
        # Slope of torque against angle over the pull (least squares): robust to the
        # slow body sway that the end points alone would pick up.
        slope = np.polyfit(rec["q_rad"][n0 // 2:, i], tau[n0 // 2:], 1)[0]
        out[f"{side}_effective_stiffness_nm_per_rad"] = float(abs(slope))
        stiff.append(out[f"{side}_effective_stiffness_nm_per_rad"])
    out["mean_effective_stiffness_nm_per_rad"] = float(np.mean(stiff))
    k_series = np.asarray(series_stiffness_nm_per_rad(params.actuator))[JOINT_INDEX["RAnkSag"]]
    out["spring_nm_per_rad"] = float(np.asarray(params.actuator.spring_stiffness_nm_per_rad)[JOINT_INDEX["RAnkSag"]])
    out["position_loop_nm_per_rad"] = float(
        np.asarray(params.actuator.kp_v_per_rad / params.actuator.beta_v_per_nm)[JOINT_INDEX["RAnkSag"]])
    out["series_prediction_nm_per_rad"] = float(k_series)
    # The seed's estimate: lean angle from the pelvis displacement over the hip
    # height, pull moment F h over the lean, shared by two ankles; it leaves out
    # the toppling moment of gravity (m g h_com per radian), so it reads lower
    # than the ankles' own stiffness.
    hip_h = float(np.asarray(s0.data.qpos[2]))
    pull_h = float(np.asarray(s0.data.site_xpos[model_ids()["torso_site"], 2]))
    lean = out["pelvis_displacement_m"] / hip_h
    out["paper_style_lean_rad"] = lean
    out["pull_height_m"] = pull_h
    out["paper_style_stiffness_nm_per_rad"] = max_pull_n * pull_h / (2 * lean) if lean else float("inf")
    out["series"] = dict(t=rec["time_s"][::25], force_n=force[::25], pelvis_x_m=rec["pelvis_m"][::25, 0] - rec["pelvis_m"][0, 0])
    return out


def knee_step(step_rad: float = 1.0, duration_s: float = 0.8, params: EnvParams | None = None) -> dict:
    """Step the right knee target by ``step_rad`` on the robot floating without gravity.

    Gravity is switched off through ``mjx.Model.opt.gravity`` (no recompile)
    and the robot lifted 5 cm, so the knee drives only the shank and foot.

    Returns:
        peak and plateau motor and link velocities (rad/s), the peak voltage
        proxy and the seed's bound ``supply / (alpha + beta A_c)``.
    """
    params = params or make_env_params()
    # ``gravity * 0`` keeps the array committed to the device like the other
    # model leaves, so the compiled chunk is reused (a fresh jnp.zeros recompiles).
    model = params.model.replace(opt=params.model.opt.replace(gravity=params.model.opt.gravity * 0.0))
    params = dataclasses.replace(params, model=model)
    q0, _ = standing_posture()
    s0 = _reset(jax.random.PRNGKey(0), params)
    s0 = s0._replace(data=s0.data.replace(qpos=s0.data.qpos.at[2].add(0.05)))
    n = int(round(duration_s / float(params.control_period_s)))
    i = JOINT_INDEX["RKneeSag"]
    tgt = np.array(q0, np.float32)
    tgt[i] += step_rad
    _, rec = run(params, s0, np.broadcast_to(tgt, (n, NU)), np.zeros((n, 3)))
    a = params.actuator
    bound = float(a.supply_v / (a.alpha_v_s_per_rad[i] + a.beta_v_per_nm[i] * a.friction_nms_per_rad[i]))
    mv = rec["motor_vel"][:, i]
    return dict(
        step_rad=step_rad,
        peak_motor_vel_rad_per_s=float(mv.max()),
        peak_link_vel_rad_per_s=float(rec["link_vel"][:, i].max()),
        seed_bound_rad_per_s=bound,
        final_knee_rad=float(rec["q_rad"][-1, i]),
        target_knee_rad=float(tgt[i]),
        series=dict(t=rec["time_s"], motor_vel=mv, link_vel=rec["link_vel"][:, i], knee_rad=rec["q_rad"][:, i]),
    )


def _jsonable(d: dict) -> dict:
    return {k: v for k, v in d.items() if k not in ("series", "commanded_rad")}


def main(argv=None) -> int:
    prog = "python -m mjx_coman.experiments"
    ap = Parser(prog=prog, description=__doc__.split("\n")[0])
    ap.add_argument("experiment", choices=["stand", "ankle", "knee"])
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    ap.add_argument("--duration", type=float, default=None, help="stand: seconds (default 10)")
    ap.add_argument("--spring", type=float, default=390.0, help="series spring stiffness, N m/rad")
    args = ap.parse_args(argv)
    try:
        if args.duration is not None and not (math.isfinite(args.duration) and 0 < args.duration <= 600):
            raise ValueError(f"--duration must lie in (0, 600] s, got {args.duration}")
        if args.duration is not None and args.experiment != "stand":
            raise ValueError(f"--duration applies to stand only, got it with {args.experiment}")
        params = make_env_params(actuator=make_actuator_params(spring_stiffness_nm_per_rad=args.spring))
    except ValueError as e:
        return refuse(prog, e)
    try:
        if args.experiment == "stand":
            res = stand(10.0 if args.duration is None else args.duration, params)
        elif args.experiment == "ankle":
            res = ankle_stiffness(params=params)
        else:
            res = knee_step(params=params)
    except KeyboardInterrupt:
        return interrupted(prog)
    res = _jsonable(res)
    if args.json:
        print(strict_json(res, indent=2))
    else:
        for k, v in res.items():
            print(f"{k:45s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
