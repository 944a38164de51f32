"""Ground-truth figures of one walk's result (:class:`mjx_coman.rollout.WalkResult` saved with pelvis, CoM, yaw)."""

from __future__ import annotations

import numpy as np

CYCLE_S = 4.0  # the limit cycle is read over the last this-many seconds before the end (or the fall)


def _alive(res) -> np.ndarray:
    """Mask of the records before any fall."""
    t = np.asarray(res.time_s)
    return t <= float(res.fall_time_s) if bool(res.fell) else np.ones(t.shape, bool)


def heading_change_rad(res) -> float | None:
    """Ground-truth pelvis yaw, unwrapped, from the first record to the last before any fall, rad (+ left)."""
    yaw = np.unwrap(np.asarray(res.saved["pelvis_yaw_rad"], np.float64))[_alive(res)]
    return float(yaw[-1] - yaw[0]) if len(yaw) > 1 else None


def com_velocity_mps(res) -> tuple[np.ndarray, np.ndarray]:
    """``(time_s, velocity)``: the horizontal CoM velocity (n-1, 2) by differences of the records, before any fall."""
    t = np.asarray(res.time_s, np.float64)[_alive(res)]
    com = np.asarray(res.saved["com_m"], np.float64)[_alive(res)][:, :2]
    if len(t) < 2:
        return np.zeros(0), np.zeros((0, 2))
    return 0.5 * (t[1:] + t[:-1]), np.diff(com, axis=0) / np.diff(t)[:, None]


def cycle(res, seconds: float = CYCLE_S) -> dict:
    """The CoM-velocity limit cycle over the last ``seconds`` before the end or the fall: the forward and
    lateral velocities' least, largest and mean (m/s), ``None`` when fewer than ``seconds`` were walked."""
    t, v = com_velocity_mps(res)
    if len(t) == 0 or t[-1] - t[0] < seconds:
        return {"forward_min_mps": None, "forward_max_mps": None, "forward_mean_mps": None,
                "lateral_min_mps": None, "lateral_max_mps": None}
    last = v[t >= t[-1] - seconds]
    return {"forward_min_mps": float(last[:, 0].min()), "forward_max_mps": float(last[:, 0].max()),
            "forward_mean_mps": float(last[:, 0].mean()), "lateral_min_mps": float(last[:, 1].min()),
            "lateral_max_mps": float(last[:, 1].max())}


KNEE_AFTER_S = 2.0  # the knee metrics leave out the start and the first steps


def knee_metrics(res, knee_rad, knee_torque_nm, record_period_s: float, after_s: float = KNEE_AFTER_S) -> dict:
    """Knee figures of a walk from the simulator (ground truth), past ``after_s`` and before any fall.

    Args:
        res: the walk's result (its records' ``time_s``, the fall and the touchdown log).
        knee_rad, knee_torque_nm: (n_rec, 2) the (right, left) knee angles and link torques at the records.
        record_period_s: time between records, s.

    Returns:
        ``stance_knee_mid_rad``: the mean knee angle of the stance leg at mid-stance, the midpoint between a
        touchdown and the next (the foot that landed first stands alone there); ``mean_abs_knee_torque_nm``:
        the mean |link torque| of both knees; ``mean_abs_knee_power_w``: the mean |torque x joint rate| (rates
        by central differences of the recorded angles); ``None`` where the walk has too few records.
    """
    from mjx_coman.ground_truth import RIGHT

    t = np.asarray(res.time_s)
    end = float(res.fall_time_s) if bool(res.fell) else np.inf
    knees, tau = np.asarray(knee_rad, np.float64), np.asarray(knee_torque_nm, np.float64)
    ok = (t > after_s) & (t <= end)
    out = {"stance_knee_mid_rad": None, "mean_abs_knee_torque_nm": None, "mean_abs_knee_power_w": None}
    if ok.sum() >= 3:
        rate = np.gradient(knees, record_period_s, axis=0)
        out["mean_abs_knee_torque_nm"] = float(np.mean(np.abs(tau[ok])))
        out["mean_abs_knee_power_w"] = float(np.mean(np.abs(tau[ok] * rate[ok])))
    k = int(res.touchdowns)
    td, foot = np.asarray(res.log.time_s)[:k], np.asarray(res.log.foot)[:k]
    mids = [(0.5 * (a + b), 0 if f == RIGHT else 1) for a, b, f in zip(td[:-1], td[1:], foot[:-1])
            if 0.5 * (a + b) > after_s and b <= end]
    if mids and len(t):
        out["stance_knee_mid_rad"] = float(np.mean([knees[np.argmin(np.abs(t - m)), leg] for m, leg in mids]))
    return out


TOE_CONTACT_M = 0.004  # a front corner this close to the ground touches it (the contact spheres' sites)
HEEL_LIFT_M = 0.008  # the heel this far above the front corners: the foot has rolled onto its toe


def corner_positions_m(qpos) -> np.ndarray:
    """(n, 2, 4, 3) sole corners of the poses ``qpos`` (n, nq) by MuJoCo's kinematics."""
    import mujoco

    import mjx_coman
    from mjx_coman.floating_base import corner_site_ids

    model = mjx_coman.load_model()
    data = mujoco.MjData(model)
    ids = corner_site_ids(model).reshape(-1)
    out = []
    for q in np.asarray(qpos, np.float64):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out.append(data.site_xpos[ids].reshape(2, 4, 3).copy())
    return np.asarray(out).reshape(-1, 2, 4, 3)


def toe_off_fraction(res, corners_m, terrain: str = "flat", after_s: float = KNEE_AFTER_S) -> float | None:
    """Fraction of steps, past ``after_s`` and before any fall, in which the trailing foot rolled onto its toe
    (ground truth, from the recorded sole corners ``corners_m`` (n_rec, 2, 4, 3), right foot first): between a
    touchdown and the next, some record has the trailing foot's front corners within :data:`TOE_CONTACT_M` of
    the terrain and its heel corners :data:`HEEL_LIFT_M` above them. ``None`` without such steps."""
    from mjx_coman.ground_truth import RIGHT
    from mjx_coman.scenarios.terrain import terrain_height_m

    corners = np.asarray(corners_m, np.float64)
    ground = np.asarray(terrain_height_m(terrain, corners[..., 0], corners[..., 1]), np.float64)
    z = corners[..., 2] - ground  # (n_rec, 2, 4): front left, front right, heel left, heel right
    rolled_now = (z[..., :2].min(-1) < TOE_CONTACT_M) & (z[..., 2:].mean(-1) > z[..., :2].mean(-1) + HEEL_LIFT_M)
    t = np.asarray(res.time_s)
    end = float(res.fall_time_s) if bool(res.fell) else np.inf
    k = int(res.touchdowns)
    td, foot = np.asarray(res.log.time_s)[:k], np.asarray(res.log.foot)[:k]
    rolled = [bool(np.any(rolled_now[(t >= a) & (t < b), 1 if f == RIGHT else 0]))  # the foot that did not land
              for a, b, f in zip(td[:-1], td[1:], foot[:-1]) if a > after_s and b <= end]
    return float(np.mean(rolled)) if rolled else None


def step_length_m(res, after_s: float = KNEE_AFTER_S) -> float | None:
    """Mean |distance| along the heading from the trailing foot to the landing one at each touchdown past
    ``after_s`` and before any fall (ground truth); ``None`` without one."""
    k = int(res.touchdowns)
    t = np.asarray(res.log.time_s)[:k]
    end = float(res.fall_time_s) if bool(res.fell) else np.inf
    d = (np.asarray(res.log.foot_m) - np.asarray(res.log.other_foot_m))[:k, :2]
    yaw = np.asarray(res.log.yaw_rad)[:k]
    along = np.abs(np.cos(yaw) * d[:, 0] + np.sin(yaw) * d[:, 1])[(t > after_s) & (t <= end)]
    return float(along.mean()) if along.size else None


def summary(res, pushed: bool = False, record_period_s: float | None = None, terrain: str = "flat") -> dict:
    """The figures of one walk: verdict, mean speed, heading change, CoM-velocity cycle, the knee figures and the
    toe-off fraction where the records have them, and (key ``series``, NumPy arrays for plots) time, CoM
    velocity, CoM position and yaw."""
    fell = bool(res.fell)
    s2r = int(res.steps_to_recover)
    t, v = com_velocity_mps(res)
    alive = _alive(res)
    knees = {}
    if record_period_s is not None and "knee_rad" in res.saved:
        knees = knee_metrics(res, res.saved["knee_rad"], res.saved["knee_torque_nm"], record_period_s)
        z = np.asarray(res.saved["com_m"])[:, 2][alive & (np.asarray(res.time_s) > KNEE_AFTER_S)]
        knees["com_height_m"] = {"min": float(z.min()), "mean": float(z.mean()), "max": float(z.max())} if len(z) else None
    if "corners_m" in res.saved:
        knees["toe_off_fraction"] = toe_off_fraction(res, res.saved["corners_m"], terrain)
        knees["step_length_m"] = step_length_m(res)
        com = np.asarray(res.saved["com_m"])[alive]
        knees["com_rise_m"] = float(com[-1, 2] - com[0, 2]) if len(com) else None
    return {
        "fell": fell,
        "fall_time_s": float(res.fall_time_s) if fell else None,
        "nan": bool(res.nan),
        "solve_failed": bool(res.solve_failed),
        "touchdowns": int(res.touchdowns),
        "mean_speed_mps": float(res.mean_speed_mps) if np.isfinite(res.mean_speed_mps) else None,
        "steps_to_recover": (s2r if s2r >= 0 else None) if pushed else None,
        "heading_change_rad": heading_change_rad(res),
        "cycle": cycle(res),
        **knees,
        "series": {"time_s": t, "com_vel_mps": v,
                   "com_m": np.asarray(res.saved["com_m"])[alive],
                   "yaw_rad": np.unwrap(np.asarray(res.saved["pelvis_yaw_rad"], np.float64))[alive]},
    }
