"""The same pushes on both physics engines (``mjx``: MuJoCo MJX; ``native``: MuJoCo C), and what differs.

:func:`outcome_agreement` compares two sweeps of one grid row by row: the fraction of rollouts with the same
outcome (fell or recovered), the pushes that differ and how far each lies from the MJX map's basin boundary
in its lane (same phase and direction), and the agreement of the steps to recover where both recovered.
:func:`pelvis_distance` walks one unpushed walk on each engine and measures the distance between the two
pelvis trajectories (world frame, every record until either falls).
"""

from __future__ import annotations

import numpy as np

ROW_KEYS = ("index", "phase", "impulse_ns", "direction_rad")


def boundary_gap_ns(results: dict) -> np.ndarray:
    """Per rollout, the distance in impulse to the nearest change of outcome in its lane (same phase and
    direction) of ``results`` (``inf`` in a lane with one outcome)."""
    gap = np.full(len(results["fell"]), np.inf)
    lanes = np.stack([results["phase"], results["direction_rad"]], 1)
    for lane in np.unique(lanes, axis=0):
        rows = np.flatnonzero(np.all(lanes == lane, axis=1))
        rows = rows[np.argsort(results["impulse_ns"][rows])]
        imp, fell = results["impulse_ns"][rows], np.asarray(results["fell"][rows], bool)
        flips = 0.5 * (imp[1:] + imp[:-1])[fell[1:] != fell[:-1]]
        if flips.size:
            gap[rows] = np.min(np.abs(imp[:, None] - flips[None, :]), axis=1)
    return gap


def outcome_agreement(mjx: dict, native: dict) -> dict:
    """Row-by-row agreement of two sweeps' results (``results.npz`` contents) of the same grid.

    Raises:
        ValueError: the two do not hold the same rows.
    """
    for k in ROW_KEYS:
        a, b = np.asarray(mjx[k]), np.asarray(native[k])
        if a.shape != b.shape or not np.allclose(a, b):
            raise ValueError(f"the two sweeps differ in {k}: not the same grid")
    fa, fb = np.asarray(mjx["fell"], bool), np.asarray(native["fell"], bool)
    same = fa == fb
    up = ~fa & ~fb
    sa, sb = np.asarray(mjx["steps_to_recover"])[up], np.asarray(native["steps_to_recover"])[up]
    gap = boundary_gap_ns(mjx)
    differ = [dict(phase=float(mjx["phase"][i]), impulse_ns=float(mjx["impulse_ns"][i]),
                   direction_deg=float(np.degrees(mjx["direction_rad"][i])), fell_mjx=bool(fa[i]),
                   fell_native=bool(fb[i]), boundary_gap_ns=float(gap[i])) for i in np.flatnonzero(~same)]
    return dict(rollouts=int(same.size), identical=int(same.sum()), identical_fraction=float(same.mean()),
                fell_mjx=int(fa.sum()), fell_native=int(fb.sum()),
                steps_to_recover_identical_fraction=float(np.mean(sa == sb)) if up.any() else None,
                steps_to_recover_mean_abs_difference=float(np.mean(np.abs(sa - sb))) if up.any() else None,
                differing=differ)


def pelvis_distance(controller: str, seconds: float = 10.0, speed_mps: float = 0.0, overrides=()) -> dict:
    """One unpushed walk of ``controller`` on each engine (noise-free sensors, the same key): the RMS and
    largest distance between the pelvis positions, every 10 ms until either walk falls."""
    import jax

    from mjx_coman import controllers, rollout as ro
    from sweeps.models.mjx import nominal_env

    ctrl, cfg = controllers.load(controller, dict(overrides))
    g = ctrl.gait(cfg)
    fn = ro.jit_walk(ctrl, ro.WalkSpec(seconds=seconds), ro.SaveAt(ro.pelvis_and_com, 5))
    runs = {e: fn(cfg, nominal_env(0.0, g.plant, e), ro.no_push(), jax.random.key(0), controllers.joystick(speed_mps))
            for e in ("mjx", "native")}
    a, b = runs["mjx"], runs["native"]
    up = np.asarray(a.time_s) <= min(float(a.fall_time_s), float(b.fall_time_s))
    d = np.linalg.norm(np.asarray(a.saved["pelvis_m"]) - np.asarray(b.saved["pelvis_m"]), axis=1)[up]
    return dict(controller=controller, seconds=seconds, speed_mps=speed_mps, records=int(up.sum()),
                rms_m=float(np.sqrt(np.mean(d ** 2))) if d.size else None, max_m=float(d.max()) if d.size else None,
                fell_mjx=bool(a.fell), fell_native=bool(b.fell),
                travel_mjx_m=float(np.linalg.norm(np.asarray(a.saved["pelvis_m"])[-1, :2]
                                                  - np.asarray(a.saved["pelvis_m"])[0, :2])))
