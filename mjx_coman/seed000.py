"""The walking experiments of seed 000 on the simulated COMAN, each printing JSON.

``python -m mjx_coman.seed000 {push-table,drag,scatter,speeds,ten,ablate,identify} [--set KEY=VALUE ...] [options] [--json]``

* ``push-table``: 0.1 s pushes on the torso, forward and backward, starting
  at 8 phases of one step of the in-place gait, over a grid of impulses, for
  ``time-projection`` (the closed loop) and ``open-loop`` (no footstep
  adjustment): recovered (no fall in the ``--steps-after`` steps that follow)
  or fell, settled (the ground truth's ``steps_to_recover >= 0``, see
  :mod:`mjx_coman.ground_truth`) and steps to recover (seed "Intermittent Push
  Recovery", Figures 16-17). The claim checked: at every phase the closed
  loop recovers an impulse at least twice the largest that the open loop
  recovers at every phase.
* ``drag``: a constant forward or backward force on the torso for the whole
  walk on the open-loop in-place gait (seed Figure 18): drift speed, no fall.
  The default forces are +-1 N (and 0 N for reference): on the simulated
  robot 2 N and more topple the open loop within 10 s.
* ``scatter``: in-place walking for 10 s (25 steps) open loop, closed loop,
  and closed loop without dead-zones; the landing foot relative to the pelvis
  at every touchdown (seed Figure 14) and its spread.
* ``speeds``: closed-loop walking at 0.1 and 0.2 m/s (seed Figure 19): mean speed.
* ``ten``: ``scatter``, ``drag`` and ``speeds`` in one batch (one compilation).
* ``ablate``: one block switched at a time (dead-zones, attack-angle share,
  filter): in-place drift over 20 s and steps to recover from forward and
  backward pushes, ground truth.
* ``identify``: dead-zone thresholds and knee deflections from the open-loop
  in-place walk (seed Figures 7 and 9;
  :mod:`mjx_coman.controllers.time_projection.identification`).

The variants are the registered configurations of the time-projection family
(``time-projection``, ``open-loop``, ``no-deadzone``), so every variant of a
table is one batch of one compiled walk (``batched_walk`` over configs,
pushes, keys and joysticks). Each function returns a dict of plain numbers
(and the batch's results under ``"raw"``, left out of the JSON).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from mjx_coman import controllers
from mjx_coman import rollout as ro
from mjx_coman.controllers.base import joystick

STEP_TIME_S = 0.4
PUSH_DURATION_S = 0.1
PUSH_TABLE_IMPULSES_NS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)  # default grid, 1 N s apart
MARGIN_NS = 0.5  # the margin over twice the open loop's impulse that the push table counts per phase
DIRECTIONS = ("forward", "backward", "left", "right")


FAMILY = "time-projection"
VARIANTS = ("time-projection", "open-loop", "no-deadzone")


def _stack(items):
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *items)


def config(name: str = FAMILY, **overrides):
    """The config of a registered time-projection variant (``time-projection``, ``open-loop``, ``no-deadzone``, ``dlqr``)."""
    ctrl, cfg = controllers.load(name, overrides)
    if ctrl.core() != controllers.get(FAMILY).core():
        raise ValueError(f"{name!r} is not a time-projection variant")
    return cfg


def push_start_s(push_step, push_phase, cfg=None) -> float:
    """Start of a push at phase ``push_phase`` of walking step ``push_step`` (after the start-up phase), s."""
    gait = controllers.get(FAMILY).gait(config() if cfg is None else cfg)
    return gait.first_step_s + (np.asarray(push_step) + push_phase) * gait.step_time_s


@functools.lru_cache(maxsize=None)
def _walker(spec, save):
    return ro.batched_walk(controllers.get(FAMILY), spec, save, config_axes=0, joystick_axes=0)


def run_batch(env_params, configs, pushes, spec, seed: int = 0, chunk: int = 64, speeds=None, save=None):
    """Walk every (config, push, speed) of the lists, in chunks of one compiled vmap.

    Returns:
        The :class:`~mjx_coman.rollout.WalkResult` with a leading batch axis, as NumPy arrays.
    """
    n = len(configs)
    if n != len(pushes) or n == 0:
        raise ValueError(f"need as many pushes as configs (> 0), got {len(pushes)} and {n}")
    speeds = [0.0] * n if speeds is None else list(speeds)
    size = min(chunk, n)
    fn = _walker(spec, save)
    keys = jax.random.split(jax.random.PRNGKey(seed), n)
    outs = []
    for i in range(0, n, size):
        idx = list(range(i, min(i + size, n)))
        idx += [idx[-1]] * (size - len(idx))  # pad the last chunk: one compiled batch size
        joy = _stack([joystick(speeds[j]) for j in idx])
        res = fn(_stack([configs[j] for j in idx]), env_params, _stack([pushes[j] for j in idx]),
                 keys[np.array(idx)], joy)
        outs.append(jax.tree_util.tree_map(np.asarray, res))
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs)[:n], *outs)


def largest_recovered(impulses, recovered) -> np.ndarray:
    """Largest impulse below which every impulse of the grid was recovered (0 if the smallest fell).

    Args:
        impulses: (m,) increasing grid.
        recovered: (..., m) bool.
    """
    rec = np.asarray(recovered, bool)
    ok = np.cumprod(rec, axis=-1).astype(bool)
    grid = np.concatenate([[0.0], np.asarray(impulses, float)])
    return grid[ok.sum(axis=-1)]


def push_table(impulses=PUSH_TABLE_IMPULSES_NS, n_phases: int = 8, push_step: int = 4,
               steps_after: int = 8, directions=("forward", "backward"), variants=("time-projection", "open-loop"),
               seed: int = 0, chunk: int = 64, overrides: dict | None = None) -> dict:
    """Recovered/fell and steps to recover over push phase x impulse (0.1 s pushes, in place).

    ``overrides``: settings changed in every variant (``--set``).
    """
    imp = np.asarray(sorted(impulses), float)
    if imp.size == 0 or np.any(imp <= 0):
        raise ValueError(f"impulses must be a non-empty list of positive numbers, got {impulses}")
    env = ro.walking_env_params()
    phases = np.arange(n_phases) / n_phases
    seconds = float(push_start_s(push_step + 1 + steps_after, 0.0))
    spec = ro.WalkSpec(seconds=seconds)
    sign = {"forward": 0.0, "backward": math.pi, "left": math.pi / 2, "right": -math.pi / 2}
    ctrl, pushes, index = [], [], []
    for c in variants:
        cp = config(c, **(overrides or {}))
        for dname in directions:
            for ph in phases:
                for m in imp:
                    ctrl.append(cp)
                    pushes.append(ro.make_push(float(push_start_s(push_step, ph)), PUSH_DURATION_S,
                                               impulse_ns=m, direction_rad=sign[dname]))
                    index.append((c, dname, ph, m))
    t0 = time.perf_counter()
    res = run_batch(env, ctrl, pushes, spec, seed, chunk)
    wall = time.perf_counter() - t0
    shape = (len(variants), len(directions), n_phases, imp.size)
    fell = res.fell.reshape(shape)
    s2r = res.steps_to_recover.reshape(shape)
    out = {"impulses_ns": imp.tolist(), "phases": phases.tolist(), "push_step": push_step,
           "push_duration_s": PUSH_DURATION_S, "seconds": seconds, "rollouts": len(ctrl),
           "wall_s": round(wall, 1), "tables": {}}
    every = {}
    for i, c in enumerate(variants):
        for j, dname in enumerate(directions):
            largest = largest_recovered(imp, ~fell[i, j])
            every[(c, dname)] = float(largest.min())
            out["tables"][f"{c}/{dname}"] = {
                "recovered": (~fell[i, j]).astype(int).tolist(),  # [phase][impulse]: no fall in the window
                "settled": (s2r[i, j] >= 0).astype(int).tolist(),  # error back within the tolerance too
                "steps_to_recover": s2r[i, j].tolist(),
                "largest_recovered_ns_per_phase": largest.tolist(),
                "recovered_at_every_phase_ns": every[(c, dname)],
            }
            out["tables"][f"{c}/{dname}"]["median_steps_to_recover"] = median_steps_to_recover(
                out["tables"][f"{c}/{dname}"])
    if FAMILY in variants and "open-loop" in variants:
        out["claim"] = {}
        for dname in directions:
            cl, ol = every[(FAMILY, dname)], every[("open-loop", dname)]
            cl_ph = np.asarray(out["tables"][f"{FAMILY}/{dname}"]["largest_recovered_ns_per_phase"])
            ol_ph = np.asarray(out["tables"][f"open-loop/{dname}"]["largest_recovered_ns_per_phase"])
            margin = cl_ph - 2.0 * ol_ph
            out["claim"][dname] = {
                "closed_loop_ns": cl, "open_loop_ns": ol, "ratio": (cl / ol) if ol > 0 else None,
                "holds": bool(cl >= 2 * ol and cl > 0),
                "ratio_per_phase": [float(c / o) if o > 0 else None for c, o in zip(cl_ph, ol_ph)],
                "twice_open_loop_at_every_phase": bool(np.all(margin >= 0) and np.all(cl_ph > 0)),
                "phases_with_half_ns_margin": int(np.sum(margin >= MARGIN_NS - 1e-9)),
            }
    out["raw"] = res
    return out


def median_steps_to_recover(table: dict) -> float | None:
    """Median ground-truth steps to recover over the settled pushes of one push-table entry (None if none)."""
    s2r = np.asarray(table["steps_to_recover"])
    settled = s2r[s2r > 0]
    return float(np.median(settled)) if settled.size else None


def impulse_grid(step_ns: float, max_ns: float) -> list[float]:
    """``step, 2 step, ..., max`` (N s): the push table's grid at a resolution.

    Raises:
        ValueError: a non-finite or non-positive step or a maximum below it.
    """
    if not (math.isfinite(step_ns) and step_ns > 0 and math.isfinite(max_ns) and max_ns >= step_ns):
        raise ValueError(f"impulse step must be positive and at most the maximum, got step {step_ns} and max {max_ns}")
    n = int(math.floor(max_ns / step_ns + 1e-9))
    return [round(step_ns * (k + 1), 9) for k in range(n)]


def _relative_footsteps(res, skip: int = 1) -> list[dict]:
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
    rel = _relative_footsteps(res)
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
            "median_steps_to_recover": float(np.median(s2r[s2r > 0])) if np.any(s2r > 0) else None,
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


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def _floats(text: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return vals


def _names(allowed):
    def parse(text: str) -> list[str]:
        vals = [v.strip() for v in text.split(",") if v.strip()]
        bad = [v for v in vals if v not in allowed]
        if not vals or bad or len(set(vals)) != len(vals):
            raise argparse.ArgumentTypeError(f"expected distinct names of {','.join(allowed)}, got {text!r}")
        return vals
    return parse


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items() if k != "raw"}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _run(args):
    ov = controllers.parse_overrides(controllers.get(FAMILY), args.set)
    config(FAMILY, **ov)  # a bad value is a ValueError naming it, before anything walks
    if args.experiment == "push-table":
        if args.phases < 1 or args.push_step < 0 or args.steps_after < 1 or min(args.impulses) <= 0:
            sys.stderr.write("python -m mjx_coman.seed000: error: --phases, --steps-after >= 1, "
                             "--push-step >= 0 and --impulses > 0 required\n")
            return None
        imp = args.impulses if args.impulse_step is None else impulse_grid(args.impulse_step, args.max_impulse)
        res = push_table(imp, args.phases, args.push_step, args.steps_after, tuple(args.directions),
                         tuple(args.variants), seed=args.seed, overrides=ov)
    elif args.experiment == "ablate":
        names = args.switches or list(SWITCHES)
        res = ablate({n: SWITCHES[n] for n in names}, args.seconds, args.impulse, seed=args.seed, overrides=ov)
    elif args.experiment == "identify":
        res = identify(args.seconds, args.settle, args.seed, overrides=ov)
    else:
        if not 0 < args.seconds <= 600:
            sys.stderr.write(f"python -m mjx_coman.seed000: error: --seconds must lie in (0, 600], "
                             f"got {args.seconds}\n")
            return None
        which = ("scatter", "drag", "speeds") if args.experiment == "ten" else (args.experiment,)
        res = ten_second_walks(args.seconds, tuple(args.drag_forces), tuple(args.speeds), args.seed, which, ov)
    return res


def main(argv=None) -> int:
    ap = _Parser(prog="python -m mjx_coman.seed000", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="experiment", required=True, parser_class=_Parser)
    pt = sub.add_parser("push-table")
    pt.add_argument("--impulses", type=_floats, default=list(PUSH_TABLE_IMPULSES_NS), help="N s")
    pt.add_argument("--phases", type=int, default=8)
    pt.add_argument("--push-step", type=int, default=4)
    pt.add_argument("--steps-after", type=int, default=8)
    pt.add_argument("--impulse-step", type=float, default=None,
                    help="N s: the grid step, max-impulse/step, ..., max-impulse (instead of --impulses)")
    pt.add_argument("--max-impulse", type=float, default=10.0, help="N s, with --impulse-step")
    pt.add_argument("--directions", type=_names(DIRECTIONS), default=["forward", "backward"],
                    help=f"comma-separated, of {','.join(DIRECTIONS)}")
    pt.add_argument("--variants", type=_names(VARIANTS + ("dlqr",)), default=[FAMILY, "open-loop"],
                    help="comma-separated registered time-projection variants")
    for name in ("drag", "scatter", "speeds", "ten"):  # "ten": all three in one batch
        sp = sub.add_parser(name)
        sp.add_argument("--seconds", type=float, default=10.0)
        sp.add_argument("--drag-forces", type=_floats, default=[1.0, 0.0, -1.0], help="N (x; + forward)")
        sp.add_argument("--speeds", type=_floats, default=[0.1, 0.2], help="m/s")
    ab = sub.add_parser("ablate")
    ab.add_argument("--switches", type=_names(tuple(SWITCHES)), default=None,
                    help=f"comma-separated, of {','.join(SWITCHES)} (default: all)")
    ab.add_argument("--seconds", type=float, default=20.0)
    ab.add_argument("--impulse", type=float, default=4.5, help="N s, forward and backward")
    idp = sub.add_parser("identify")
    idp.add_argument("--seconds", type=float, default=10.0)
    idp.add_argument("--settle", type=float, default=2.0)
    for sp in sub.choices.values():
        sp.add_argument("--seed", type=int, default=0)
        sp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a setting of the time-projection family, changed in every variant of the experiment")
        sp.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    # mujoco.mjx prints "Failed to import warp" on stdout when Warp is absent: keep stdout for the JSON.
    try:
        with contextlib.redirect_stdout(sys.stderr):
            res = _run(args)
    except ValueError as e:
        sys.stderr.write(f"python -m mjx_coman.seed000: error: {' '.join(str(e).split())}\n")
        return 2
    if res is None:
        return 2
    print(json.dumps(_jsonable(res), indent=2 if args.json else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
