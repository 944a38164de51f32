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


def summary(res, pushed: bool = False) -> dict:
    """The figures of one walk: verdict, mean speed, heading change, CoM-velocity cycle and (key ``series``,
    NumPy arrays for plots) time, CoM velocity, CoM position and yaw."""
    fell = bool(res.fell)
    s2r = int(res.steps_to_recover)
    t, v = com_velocity_mps(res)
    alive = _alive(res)
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
        "series": {"time_s": t, "com_vel_mps": v,
                   "com_m": np.asarray(res.saved["com_m"])[alive],
                   "yaw_rad": np.unwrap(np.asarray(res.saved["pelvis_yaw_rad"], np.float64))[alive]},
    }
