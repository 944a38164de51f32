"""The push table (seed 000, "Intermittent Push Recovery", Figures 16-17): phase x impulse per direction and variant."""

from __future__ import annotations

import math
import time

import numpy as np

from mjx_coman import rollout as ro
from mjx_coman.seed000.common import (FAMILY, MARGIN_NS, PUSH_DURATION_S, PUSH_TABLE_IMPULSES_NS,
                                     SUPPLY_V, config, largest_recovered, median_steps_to_recover, plant, push_start_s,
                                     run_batch)


def push_table(impulses=PUSH_TABLE_IMPULSES_NS, n_phases: int = 8, push_step: int = 4,
               steps_after: int = 8, directions=("forward", "backward"), variants=("time-projection", "open-loop"),
               seed: int = 0, chunk: int = 64, overrides: dict | None = None, supply_v: float = SUPPLY_V,
               friction_scale: float = 1.0, truth_estimate: bool = False, phases=None) -> dict:
    """Recovered/fell and steps to recover over push phase x impulse (0.1 s pushes, in place).

    ``overrides``: settings changed in every variant (``--set``); ``supply_v`` and ``friction_scale``
    switch two limits of the plant (:func:`~mjx_coman.seed000.common.plant`); ``truth_estimate`` the
    estimate (the simulator's true relative positions, see :func:`~mjx_coman.seed000.common.run_batch`).
    ``phases``: the push phases in [0, 1) instead of ``n_phases`` evenly spaced ones (a finer look at a few).
    """
    imp = np.asarray(sorted(impulses), float)
    if imp.size == 0 or np.any(imp <= 0):
        raise ValueError(f"impulses must be a non-empty list of positive numbers, got {impulses}")
    if phases is None:
        phases = np.arange(n_phases) / n_phases
    phases = np.asarray(phases, float).reshape(-1)
    if phases.size == 0 or not np.all((phases >= 0) & (phases < 1)):
        raise ValueError(f"phases must be a non-empty list of numbers in [0, 1), got {list(phases)}")
    env = plant(supply_v, friction_scale)
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
    res = run_batch(env, ctrl, pushes, spec, seed, chunk, truth_estimate=truth_estimate)
    wall = time.perf_counter() - t0
    shape = (len(variants), len(directions), phases.size, imp.size)
    fell = res.fell.reshape(shape)
    s2r = res.steps_to_recover.reshape(shape)
    out = {"impulses_ns": imp.tolist(), "phases": phases.tolist(), "push_step": push_step,
           "push_duration_s": PUSH_DURATION_S, "seconds": seconds, "rollouts": len(ctrl),
           "wall_s": round(wall, 1), "supply_v": supply_v, "friction_scale": friction_scale,
           "truth_estimate": truth_estimate, "tables": {}}
    every, per_phase = {}, {}
    for i, c in enumerate(variants):
        for j, dname in enumerate(directions):
            largest = per_phase[(c, dname)] = largest_recovered(imp, ~fell[i, j])
            every[(c, dname)] = float(largest.min())
            out["tables"][f"{c}/{dname}"] = {
                "recovered": (~fell[i, j]).astype(int).tolist(),  # [phase][impulse]: no fall in the window
                "settled": (s2r[i, j] >= 0).astype(int).tolist(),  # error back within the tolerance too
                "steps_to_recover": s2r[i, j].tolist(),
                "largest_recovered_ns_per_phase": largest.tolist(),
                "recovered_at_every_phase_ns": every[(c, dname)],
                "median_steps_to_recover": median_steps_to_recover(s2r[i, j]),
            }
    if FAMILY in variants and "open-loop" in variants:
        out["claim"] = {}
        for dname in directions:
            cl, ol = every[(FAMILY, dname)], every[("open-loop", dname)]
            cl_ph, ol_ph = per_phase[(FAMILY, dname)], per_phase[("open-loop", dname)]
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


def impulse_grid(step_ns: float, max_ns: float) -> list[float]:
    """``step, 2 step, ..., max`` (N s): the push table's grid at a resolution.

    Raises:
        ValueError: a non-finite or non-positive step or a maximum below it.
    """
    if not (math.isfinite(step_ns) and step_ns > 0 and math.isfinite(max_ns) and max_ns >= step_ns):
        raise ValueError(f"impulse step must be positive and at most the maximum, got step {step_ns} and max {max_ns}")
    n = int(math.floor(max_ns / step_ns + 1e-9))
    return [round(step_ns * (k + 1), 9) for k in range(n)]
