"""The seed 000 walks: 10-second scatter, drag and speeds (Figures 14, 18, 19), one-switch ablation, identification."""

from __future__ import annotations

import math
import time

import jax
import numpy as np

from mjx_coman import controllers
from mjx_coman import rollout as ro
from mjx_coman.controllers.base import joystick
from mjx_coman.seed000.common import (FAMILY, PUSH_DURATION_S, VARIANTS, config, median_steps_to_recover, push_start_s,
                                     run_batch)


def relative_footsteps(res, skip: int = 1) -> list[dict]:
    """The landing foot minus the pelvis at each touchdown after the first ``skip``, split by foot; per rollout."""
    rel = res.log.foot_m - res.log.pelvis_m  # (b, n, 3)
    out = []
    for b in range(rel.shape[0]):
        k = int(res.touchdowns[b])
        r, foot = rel[b, skip:k, :2], res.log.foot[b, skip:k]
        out.append({"left": r[foot == 0].tolist(), "right": r[foot == 1].tolist()})
    return out


def footstep_spread_m(rel: dict) -> dict:
    """Standard deviation (sagittal, lateral) of each foot's position relative to the pelvis, and their mean."""
    out = {}
    for foot in ("left", "right"):
        a = np.asarray(rel[foot])
        out[foot] = np.std(a, axis=0, ddof=1).tolist() if len(a) > 1 else [float("nan")] * 2
    out["mean_sagittal_m"] = float(np.mean([out["left"][0], out["right"][0]]))
    out["mean_lateral_m"] = float(np.mean([out["left"][1], out["right"][1]]))
    return out


def ten_second_walks(seconds: float = 10.0, drag_forces_n=(1.0, 0.0, -1.0), speeds=(0.1, 0.2), seed: int = 0,
                     which=("scatter", "drag", "speeds"), overrides: dict | None = None) -> dict:
    """The 10-second experiments in one batch of one compiled walk: scatter (Figure 14), drag (18), speeds (19).

    ``which`` picks the experiments of the batch; ``overrides`` changes settings in every variant.
    """
    ov = overrides or {}
    env = ro.walking_env_params()
    spec = ro.WalkSpec(seconds=seconds)
    save = ro.SaveAt(ro.pelvis_and_com, every=50)
    names, cfgs, pushes, vs = [], [], [], []
    for v in VARIANTS if "scatter" in which else ():
        names.append(("scatter", v))
        cfgs.append(config(v, **ov))
        pushes.append(ro.no_push())
        vs.append(0.0)
    for f in drag_forces_n if "drag" in which else ():
        names.append(("drag", f))
        cfgs.append(config("open-loop", **ov))
        pushes.append(ro.make_push(0.0, seconds + 1.0, (f, 0.0, 0.0)))
        vs.append(0.0)
    for v in speeds if "speeds" in which else ():
        names.append(("speed", v))
        cfgs.append(config(**ov))
        pushes.append(ro.no_push())
        vs.append(v)
    t0 = time.perf_counter()
    res = run_batch(env, cfgs, pushes, spec, seed, speeds=vs, save=save)
    wall = time.perf_counter() - t0
    rel = relative_footsteps(res)
    out = {"seconds": seconds, "rollouts": len(cfgs), "wall_s": round(wall, 1), "scatter": {}, "drag": {},
           "speeds": {}}
    for b, (kind, val) in enumerate(names):
        common = {"fell": bool(res.fell[b]), "touchdowns": int(res.touchdowns[b]),
                  "mean_speed_mps": float(res.mean_speed_mps[b]),
                  "max_abs_footstep_adjustment_m": float(res.max_abs_footstep_adjustment_m[b])}
        if kind == "scatter":
            out["scatter"][val] = {**common, "spread": footstep_spread_m(rel[b]), "footsteps_rel_pelvis_m": rel[b]}
        elif kind == "drag":
            k = int(res.touchdowns[b])
            x, t = res.log.pelvis_m[b, :k, 0], res.log.time_s[b, :k]
            out["drag"][f"{val:+g}N"] = {**common, "force_n": val,
                                          "overall_speed_mps": float((x[-1] - x[0]) / max(t[-1] - t[0], 1e-9))
                                          if k > 1 else 0.0,
                                          "peak_step_speed_mps": float(np.max(np.abs(np.diff(x) / np.diff(t))))
                                          if k > 1 else 0.0,
                                          "final_pelvis_m": res.saved["pelvis_m"][b, -1].tolist()}
        else:
            out["speeds"][f"{val:g}"] = {**common, "commanded_mps": val,
                                         "within_25_percent": bool(abs(res.mean_speed_mps[b] - val) <= 0.25 * val)}
    sc = out["scatter"]
    if all(k in sc for k in (FAMILY, "no-deadzone")):
        out["deadzone_no_larger_scatter"] = bool(
            sc[FAMILY]["spread"]["mean_sagittal_m"] <= sc["no-deadzone"]["spread"]["mean_sagittal_m"])
    out["raw"] = res
    return out


# Each switch is a set of overrides of the time-projection settings; "default" is the registered configuration.
SWITCHES = {
    "default": {},
    "no-deadzone": {"deadzone": (1e-7, 1e-7, 1e-7, 1e-7)},
    "identified-deadzone": {"deadzone": (0.0169, 0.0076, 0.152, 0.043)},
    "attack-all": {"hip_attack": 1.0},
    "attack-half": {"hip_attack": 0.5},
    "light-filter": {"zeta": 0.3},
    "no-filter": {"zeta": 1.0},
    "open-loop": {"footstep_gain": 0.0},
    "pelvis-over-foot": {"pelvis_offset_m": 0.0},
    "pelvis-back": {"pelvis_offset_m": -0.05},
    "stiff-ankle": {"ankle_compliance": 0.0},
    "stance-feedback": {"stance_feedback": 0.5},
    "ankle-compliance-0.3": {"ankle_compliance": 0.3},
    "ankle-compliance-0.5": {"ankle_compliance": 0.5},
    "ankle-compliance-0.85": {"ankle_compliance": 0.85},
    "free-ankle": {"ankle_compliance": 1.0},
    "footstep-gain-1.5": {"footstep_gain": 1.5},
    "footstep-gain-2": {"footstep_gain": 2.0},
}


def ablate(switches: dict | None = None, seconds: float = 20.0, impulse_ns: float = 4.5,
           phases=(0.0, 0.25, 0.5, 0.75), push_step: int = 12, seed: int = 0, overrides: dict | None = None) -> dict:
    """Switch one block at a time: in-place drift and steps to recover of forward and backward pushes.

    Every switch walks in place for ``seconds`` unpushed (the drift is the ground-truth CoM speed over the
    last half of its touchdowns, ``mean_speed_mps``) and once per push: 0.1 s, ``impulse_ns`` forward and
    backward, at each phase of step ``push_step`` (12: after the start-up transient, which takes about 4 s
    from standing). One batch of one compiled walk.
    """
    switches = SWITCHES if switches is None else switches
    if not (math.isfinite(impulse_ns) and impulse_ns > 0):
        raise ValueError(f"impulse_ns={impulse_ns} must be finite and positive")
    if not (math.isfinite(seconds) and seconds > push_start_s(push_step + 10, 0.0)):
        raise ValueError(f"seconds={seconds} leaves fewer than 10 steps after the push step")
    env = ro.walking_env_params()
    spec = ro.WalkSpec(seconds=seconds)
    rows, cfgs, pushes = [], [], []
    for name, ov in switches.items():
        cfg = config(FAMILY, **{**(overrides or {}), **ov})
        for d, ang in (("none", 0.0), ("forward", 0.0), ("backward", math.pi)):
            for ph in (phases if d != "none" else (0.0,)):
                rows.append((name, d, ph))
                cfgs.append(cfg)
                pushes.append(ro.no_push() if d == "none" else ro.make_push(
                    float(push_start_s(push_step, ph)), PUSH_DURATION_S, impulse_ns=impulse_ns, direction_rad=ang))
    t0 = time.perf_counter()
    res = run_batch(env, cfgs, pushes, spec, seed, chunk=min(len(rows), 64))
    out = {"seconds": seconds, "impulse_ns": impulse_ns, "phases": list(phases), "rollouts": len(rows),
           "wall_s": round(time.perf_counter() - t0, 1), "switches": {}}
    for name, ov in switches.items():
        idx = [i for i, r in enumerate(rows) if r[0] == name]
        free = idx[0]
        s2r = np.array([int(res.steps_to_recover[i]) for i in idx[1:]])
        fell = np.array([bool(res.fell[i]) for i in idx[1:]])
        k = int(res.touchdowns[free])
        sv = res.step_velocity_mps[free, k // 2:k]  # the unpushed walk's second half: its scatter about the cycle
        out["switches"][name] = {
            "overrides": {k: list(v) if isinstance(v, tuple) else v for k, v in ov.items()},
            "in_place_fell": bool(res.fell[free]), "in_place_drift_mps": float(res.mean_speed_mps[free]),
            "in_place_step_velocity_std_mps": np.nanstd(sv, axis=0).tolist() if sv.size else None,
            "pushes_fell": int(fell.sum()), "pushes_settled": int((s2r > 0).sum()), "pushes": len(s2r),
            "steps_to_recover": s2r.tolist(),
            "median_steps_to_recover": median_steps_to_recover(s2r),
        }
    out["raw"] = res
    return out


def open_loop_walk(env_params, *, seconds: float = 10.0, seed: int = 0, overrides: dict | None = None):
    """The seed's identification walk, recorded every tick: open loop, in place (``SaveAt(trace, every=1)``).

    Seed 000 identifies both the dead-zones and the knee deflections on this
    gait: speed 0, no footstep adjustment (adaptive lift and foot orientation
    feedback on). Pass the result to both ``identify_deadzones`` and
    ``identify_knee_deflection`` (:mod:`mjx_coman.controllers.time_projection.identification`).

    Raises:
        ValueError: a non-positive duration.
    """
    from mjx_coman.controllers.time_projection.trace import trace

    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"seconds must be finite and positive, got {seconds}")
    ctrl, cfg = controllers.load("open-loop", overrides)
    fn = ro.jit_walk(ctrl, ro.WalkSpec(seconds=float(seconds)), ro.SaveAt(trace, every=1))
    return fn(cfg, env_params, ro.no_push(), jax.random.PRNGKey(seed), joystick())


def identify(seconds: float = 10.0, settle_s: float = 2.0, seed: int = 0, overrides: dict | None = None) -> dict:
    """Dead-zone thresholds (Figure 9) and knee deflections (Figure 7) from the open-loop in-place walk."""
    from mjx_coman.controllers.time_projection import identification as idn

    if not settle_s < seconds:
        raise ValueError(f"settle_s={settle_s} must be shorter than the walk ({seconds} s)")
    env = ro.walking_env_params()
    t0 = time.perf_counter()
    r = jax.tree_util.tree_map(np.asarray, open_loop_walk(env, seconds=seconds, seed=seed, overrides=overrides))
    wall = time.perf_counter() - t0
    dz = idn.identify_deadzones(r, settle_s=settle_s)
    dz_pc = idn.identify_deadzones(r, settle_s=settle_s, at_phase_change=True)
    kn = idn.identify_knee_deflection(r, idn.total_weight_n(env.model), settle_s=settle_s)
    k = float(np.asarray(env.actuator.spring_stiffness_nm_per_rad)[idn.LEFT_KNEE])
    return {
        "seconds": seconds, "settle_s": settle_s, "fell": bool(r.fell), "touchdowns": int(r.touchdowns),
        "wall_s": round(wall, 1), "deadzone_names": list(idn.ERROR_NAMES),
        "deadzone_thresholds": np.asarray(dz.thresholds).tolist(), "error_mean": np.asarray(dz.mean).tolist(),
        "deadzone_thresholds_at_phase_change": np.asarray(dz_pc.thresholds).tolist(),
        "samples": int(dz.n_samples),
        "mu_left_rad": float(kn.mu_left_rad), "mu_right_rad": float(kn.mu_right_rad),
        "mu_full_support_mean_rad": np.asarray(kn.full_support_mean_rad).tolist(),
        "knee_fit_residual_std_rad": np.asarray(kn.residual_std_rad).tolist(),
        "knee_spring_nm_per_rad": k,
    }
