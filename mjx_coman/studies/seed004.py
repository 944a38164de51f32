"""Seed 004's experiments on COMAN for any walking controller (the straight-leg family's comparisons among them).

* ``flat``: walking at COMAN's scale of Atlas's 0.26 m/s (Fig. 9): speeds scale with the square root of the
  leg length (0.43 m against about 0.85 m), so 0.26 x 0.71 = 0.19 m/s (and 0.1 m/s beside it); 20 s, with the stance knee at
  mid-stance, the knee torque and power and the CoM height over the cycle from ground truth. Run it for
  ``straight-leg`` and ``bent-knee`` to compare knee torque (the paper's central claim).
* ``mid-swing-push``: 0.1 s pushes on the torso in 8 directions at mid-swing of walking step 4, impulses
  1-12 N s, walking at 0.15 m/s: the largest recovered impulse per direction (every smaller one recovered
  too) and the steps to recover (ground truth). Mid-swing is the middle of the swing after any transfer
  (``transfer_s`` of a controller that has one).

* ``toe-off``: the flat walk at 0.1, 0.15 and the scaled 0.19 m/s for 20 s: the stance knee at mid-stance, the
  fraction of steps with toe-off and the step length (ground truth), and down ``stairs:-5`` at 0.1 m/s. Run it
  for ``straight-leg`` and
  ``straight-leg-no-toe-off`` (seed 004, sec. IV: toe-off lets the trailing leg extend).
* ``stairs``: up ``stairs:CM`` and down ``stairs:-CM`` (:mod:`mjx_coman.scenarios.terrain`: 0.3 m treads) at
  0.1 m/s for 16 s, risers 3-10 cm (Atlas climbed and descended 19.7 cm with a leg about twice COMAN's: ~10 cm
  scaled); a controller with a ``terrain`` setting plans its footholds on the stairs
  (:mod:`mjx_coman.studies.batch`). Each riser is a scene of its own (a compilation each). Climbed: no fall and
  the CoM risen (descended: fallen) by at least two risers.
"""

from __future__ import annotations

import math

import numpy as np

from mjx_coman import controllers
from mjx_coman import scenarios as sc
from mjx_coman.studies.batch import Row
from mjx_coman.studies.seed001 import SMALL_S, Experiment, Plan, _by, _small, _table, largest_tolerated

FROUDE = math.sqrt(0.432 / 0.85)  # COMAN's hip-to-ankle against Atlas's leg
FLAT_MPS = round(0.26 * FROUDE, 2)
PUSH_MPS = 0.15
PUSH_STEP = 4
PUSH_DURATION_S = 0.1
DIRECTIONS_DEG = (0, 45, 90, 135, 180, 225, 270, 315)
IMPULSES_NS = tuple(float(j) for j in range(1, 13))


def mid_swing_phase(name: str) -> float:
    """Phase of the step at mid-swing: ``(transfer + swing / 2) / step`` for a controller with a transfer, else 0.5."""
    cfg = controllers.default_config(name)
    transfer = float(getattr(cfg, "transfer_s", 0.0) or 0.0)
    step = float(controllers.get(name).gait(cfg).step_time_s)
    return (transfer + 0.5 * (step - transfer)) / step


def _flat_plan(name, size, gait):
    vs = [min(FLAT_MPS, gait.max_forward_mps), 0.1]  # the scaled speed, and a slower walk beside it
    return _small(Plan([Row(forward_mps=v) for v in vs], [{"speed_mps": v} for v in vs], 20.0, {}), size)


def _flat_reduce(plan, res):
    rows = _table(plan, res)
    return {"rows": rows, "scaled_from": "Atlas: 0.35 m steps at 0.26 m/s (Fig. 9), speed x sqrt(0.432 / 0.85)",
            "paper": "straight legs lower the knee torque and the CoM follows an inverted-pendulum height profile"}


def _push_plan(name, size, gait):
    phase = mid_swing_phase(name)
    step = PUSH_STEP if size == "full" else 0
    start = gait.first_step_s + (step + phase) * gait.step_time_s
    rows, labels = [], []
    for deg in DIRECTIONS_DEG:
        for j in IMPULSES_NS:
            rows.append(Row(forward_mps=PUSH_MPS, push_ns=j, push_dir_rad=math.radians(deg), push_start_s=start,
                            push_duration_s=PUSH_DURATION_S))
            labels.append({"direction_deg": deg, "impulse_ns": j, "phase": round(phase, 4)})
    order = sorted(range(len(rows)), key=lambda i: (labels[i]["impulse_ns"] != 4.0, labels[i]["direction_deg"]))
    plan = Plan([rows[i] for i in order], [labels[i] for i in order], 10.0, {})
    return _small(plan, size)


def _push_reduce(plan, res):
    rows = _table(plan, res)
    per_dir = {}
    for deg in sorted({x["direction_deg"] for x in rows}):
        js, ok = _by(plan, res, "impulse_ns", lambda lab, d=deg: lab["direction_deg"] == d)
        best = largest_tolerated(js, ok)
        steps = [x["steps_to_recover"] for x in rows if x["direction_deg"] == deg and not x["fell"]
                 and x["steps_to_recover"] is not None and (best is None or x["impulse_ns"] <= best)]
        per_dir[str(deg)] = {"largest_recovered_ns": best,
                             "median_steps_to_recover": float(np.median(steps)) if steps else None}
    return {"rows": rows, "by_direction_deg": per_dir,
            "reference": "a common ICP-stack test: 0.35 m g for 0.1 s mid-swing, about 10 N s for COMAN"}


TOE_OFF_MPS = (0.1, PUSH_MPS, FLAT_MPS)
STAIR_MPS = 0.1
STAIR_S = 16.0
RISERS_CM = (3, 5, 7, 10, -3, -5, -7, -10)  # up, then down


TOE_OFF_STAIRS = "stairs:-5"  # and down a staircase (sec. IV: toe-off matters most stepping down)


def _toe_off_plan(name, size, gait):
    vs = [v for v in TOE_OFF_MPS if v <= gait.max_forward_mps + 1e-9]
    rows = [Row(forward_mps=v) for v in vs] + [Row(forward_mps=STAIR_MPS, scenario=sc.Scenario(terrain=TOE_OFF_STAIRS))]
    labels = [{"speed_mps": v, "terrain": "flat"} for v in vs] + [{"speed_mps": STAIR_MPS, "terrain": TOE_OFF_STAIRS}]
    return _small(Plan(rows, labels, 20.0, {}), size)


def _toe_off_reduce(plan, res):
    keep = ("speed_mps", "terrain", "fell", "stance_knee_mid_rad", "toe_off_fraction", "step_length_m",
            "mean_speed_mps", "mean_abs_knee_torque_nm")
    rows = _table(plan, res)
    pick = lambda flat: [{k: x.get(k) for k in keep} for x in rows if (x["terrain"] == "flat") == flat]  # noqa: E731
    return {"rows": rows, "by_speed": pick(True), "down_stairs": pick(False),
            "paper": "toe-off lets the trailing leg extend, the leading leg bend less (sec. IV)"}


def _stairs_plan(name, size, gait):
    risers = RISERS_CM if size == "full" else RISERS_CM[:1]
    rows = [Row(forward_mps=STAIR_MPS, scenario=sc.Scenario(terrain=f"stairs:{h}")) for h in risers]
    plan = Plan(rows, [{"riser_cm": h} for h in risers], STAIR_S, {})
    return plan if size == "full" else Plan(plan.rows, plan.labels, SMALL_S, {})


def climbed(row: dict, riser_cm: float) -> bool:
    """No fall, and the CoM rose (a negative riser: fell) by at least two risers (ground truth)."""
    rise = (row.get("com_rise_m") or 0.0) * (1.0 if riser_cm > 0 else -1.0)
    return (not row["fell"]) and rise >= 2 * abs(riser_cm) / 100.0 - 1e-3


def _stairs_reduce(plan, res):
    rows = _table(plan, res)
    ok = [climbed(x, x["riser_cm"]) for x in rows]
    best = {}
    for key, sign in (("largest_riser_up_cm", 1), ("largest_riser_down_cm", -1)):
        pick = [(abs(x["riser_cm"]), o) for x, o in zip(rows, ok) if x["riser_cm"] * sign > 0]
        best[key] = largest_tolerated([h for h, _ in pick], [o for _, o in pick]) if pick else None
    return {"rows": rows, "climbed": dict(zip([str(x["riser_cm"]) for x in rows], ok)), **best,
            "paper": "Atlas climbed and descended 19.685 cm risers in simulation (Fig. 10)"}


EXPERIMENTS = {e.name: e for e in (
    Experiment("flat", "walking at COMAN's scale of Atlas's 0.26 m/s for 20 s: knees, knee torque (Fig. 9)",
               _flat_plan, _flat_reduce),
    Experiment("toe-off", "flat walks at 0.1-0.19 m/s for 20 s: stance knee, toe-off fraction, step length",
               _toe_off_plan, _toe_off_reduce),
    Experiment("stairs", "up stairs of 2-10 cm risers at 0.1 m/s for 16 s: the largest climbed (Fig. 10)",
               _stairs_plan, _stairs_reduce),
    Experiment("mid-swing-push", "0.1 s pushes at mid-swing in 8 directions, 1-12 N s, at 0.15 m/s", _push_plan,
               _push_reduce),
)}
