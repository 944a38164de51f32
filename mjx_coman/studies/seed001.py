"""Seed 001's experiments (sec. V, Fig. 3-5) for any walking controller: what each runs and what it reports.

Each :class:`Experiment` turns (controller, size) into a :class:`Plan` (rows of :mod:`.batch`, their labels,
the walk's duration, shared settings) and reduces the rows' ground-truth figures to its JSON result. Size
``full`` is the paper's experiment; ``small`` runs two short rows of it (tests and the notebook: every flat
experiment then shares one compilation).
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

from mjx_coman import controllers
from mjx_coman.controllers.base import Gait
from mjx_coman.scenarios import Scenario
from mjx_coman.studies.batch import Row

SMALL_S = 1.2  # every small experiment's walk: one compilation for all of them
SMALL_ROWS = 2
WALK_MPS = 0.2  # seed 001's nominal speed for the disturbance tests
PUSH_NS, PUSH_S = 3.0, 0.3  # seed 001, Fig. 5A: 10 N for 0.3 s
PUSH_STEP = 5  # pushes land on this walking step (small: step 0)
BACKPACK_COM_M = (-0.01, 0.0, 0.0)  # seed 001, Fig. 5B: 1 cm back


class Plan(NamedTuple):
    rows: list  # [Row]
    labels: list  # [dict]: each row's coordinates in the experiment
    seconds: float
    overrides: dict


class Experiment(NamedTuple):
    name: str
    description: str
    plan: Callable[[str, str, Gait], Plan]
    reduce: Callable[[Plan, list], dict]


def _small(plan: Plan, size: str) -> Plan:
    if size == "full":
        return plan
    return Plan(plan.rows[:SMALL_ROWS], plan.labels[:SMALL_ROWS], SMALL_S, plan.overrides)


def _figures(r: dict) -> dict:
    return {k: v for k, v in r.items() if k != "series"}


def _table(plan: Plan, res: list) -> list[dict]:
    """Each row's labels and figures (no series): an experiment's JSON rows."""
    return [{**lab, **_figures(r)} for lab, r in zip(plan.labels, res)]


def largest_tolerated(values, walked) -> float | None:
    """The largest value whose walk and every smaller one's (by magnitude) did not fall; ``None``: the
    smallest fell."""
    best = None
    for v, ok in sorted(zip(values, walked), key=lambda p: abs(p[0])):
        if not ok:
            break
        best = v
    return best


def _by(plan: Plan, res: list, key: str, where=lambda lab: True) -> tuple[list, list]:
    pairs = [(lab[key], not r["fell"]) for lab, r in zip(plan.labels, res) if key in lab and where(lab)]
    return [p[0] for p in pairs], [p[1] for p in pairs]


# --- speeds (Fig. 3) ----------------------------------------------------------------------------------------

def _speeds_plan(name, size, gait):
    vs = [round(v, 1) for v in (-0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4) if abs(v) <= gait.max_forward_mps + 1e-9]
    vs = sorted(vs, key=lambda v: (v != 0.2, v != 0.0, v))  # small: 0.2 and in place first
    plan = Plan([Row(forward_mps=v) for v in vs], [{"speed_mps": v} for v in vs], 20.0, {})
    return _small(plan, size)


def _speeds_reduce(plan, res):
    rows = []
    for lab, r in zip(plan.labels, res):
        err = None if r["mean_speed_mps"] is None else r["mean_speed_mps"] - lab["speed_mps"]
        rows.append({**lab, **_figures(r), "speed_error_mps": err})
    rows.sort(key=lambda x: x["speed_mps"])
    ok = [x["speed_mps"] for x in rows if not x["fell"]]
    return {"rows": rows, "walked_speeds_mps": ok,
            "tracked_within_0.05_mps": [x["speed_mps"] for x in rows if not x["fell"] and x["speed_error_mps"]
                                        is not None and abs(x["speed_error_mps"]) <= 0.05],
            "paper": "walks -0.2 to 0.4 m/s (Fig. 3); tracking worse backwards"}


# --- steer (Fig. 4) -----------------------------------------------------------------------------------------

STEER_RAMP_S = 3.0


def _ramp(name: str) -> dict:
    known = controllers.get(name).defaults()
    return {"joystick_ramp_s": STEER_RAMP_S} if "joystick_ramp_s" in known else {}


def _steer_plan(name, size, gait):
    if gait.max_turn_rad_per_s <= 0:
        raise ValueError(f"steer: {name} does not steer (its largest turn rate is 0)")
    speeds = [v for v in (0.0, 0.1, 0.2, 0.3) if v <= gait.max_forward_mps]
    turns = [w for w in (0.2, 0.4, 0.6) if w <= gait.max_turn_rad_per_s + 1e-9]
    combos = [(0.1, turns[0])] + [(v, w) for v in speeds for w in turns if (v, w) != (0.1, turns[0])]
    plan = Plan([Row(forward_mps=v, turn_rad_per_s=w) for v, w in combos],
                [{"speed_mps": v, "turn_rad_per_s": w} for v, w in combos], 10.0, _ramp(name))
    return _small(plan, size)


def commanded_heading_rad(turn_rad_per_s: float, seconds: float, ramp_s: float) -> float:
    """Integral of a steering rate ramped linearly in over ``ramp_s`` from 0 to ``seconds``, rad."""
    if seconds >= ramp_s:
        return turn_rad_per_s * (seconds - 0.5 * ramp_s)
    return turn_rad_per_s * seconds ** 2 / (2.0 * ramp_s)


def _steer_reduce(plan, res):
    ramp = plan.overrides.get("joystick_ramp_s", 0.0)
    rows = []
    for lab, r in zip(plan.labels, res):
        until = r["fall_time_s"] if r["fell"] else plan.seconds
        cmd = commanded_heading_rad(lab["turn_rad_per_s"], until, ramp)
        got = r["heading_change_rad"]
        rows.append({**lab, **_figures(r), "commanded_heading_rad": cmd,
                     "heading_ratio": None if got is None or cmd == 0 else got / cmd})
    largest = {}
    for v in sorted({x["speed_mps"] for x in rows}):
        ws, ok = _by(plan, res, "turn_rad_per_s", lambda lab, v=v: lab["speed_mps"] == v)
        largest[str(v)] = largest_tolerated(ws, ok)
    return {"rows": rows, "ramp_s": ramp, "largest_turn_rad_per_s_by_speed": largest,
            "paper": "four largest stable combinations (Fig. 4); steering limits the forward speed"}


# --- push (Fig. 5A) -----------------------------------------------------------------------------------------

DIRECTIONS_DEG = (0, 45, 90, 135, 180, 225, 270, 315)
PHASES = (0.0, 0.25, 0.5, 0.75)
IMPULSES_NS = (1.5, 3.0, 4.5, 6.0, 9.0)


def _push_plan(name, size, gait):
    step = PUSH_STEP if size == "full" else 0
    start = lambda ph: gait.first_step_s + (step + ph) * gait.step_time_s  # noqa: E731
    rows, labels = [], []
    for deg in DIRECTIONS_DEG:
        for ph in PHASES:
            rows.append(Row(forward_mps=WALK_MPS, push_ns=PUSH_NS, push_dir_rad=math.radians(deg),
                            push_start_s=start(ph), push_duration_s=PUSH_S))
            labels.append({"direction_deg": deg, "phase": ph, "impulse_ns": PUSH_NS})
    for deg in DIRECTIONS_DEG:
        for j in (j for j in IMPULSES_NS if j != PUSH_NS):
            rows.append(Row(forward_mps=WALK_MPS, push_ns=j, push_dir_rad=math.radians(deg),
                            push_start_s=start(0.25), push_duration_s=PUSH_S))
            labels.append({"direction_deg": deg, "phase": 0.25, "impulse_ns": j})
    order = sorted(range(len(rows)), key=lambda i: (labels[i]["phase"] != 0.25, labels[i]["direction_deg"] % 180,
                                                    labels[i]["impulse_ns"] != PUSH_NS))
    plan = Plan([rows[i] for i in order], [labels[i] for i in order], 10.0, {})
    return _small(plan, size)


def _push_reduce(plan, res):
    rows = _table(plan, res)
    per_dir = {}
    for deg in sorted({x["direction_deg"] for x in rows}):
        at3 = [x for x in rows if x["direction_deg"] == deg and x["impulse_ns"] == PUSH_NS]
        js, ok = _by(plan, res, "impulse_ns", lambda lab, d=deg: lab["direction_deg"] == d and lab["phase"] == 0.25)
        steps = [x["steps_to_recover"] for x in at3 if not x["fell"] and x["steps_to_recover"] is not None]
        per_dir[str(deg)] = {"recovered_at_3ns": sum(not x["fell"] for x in at3), "pushes_at_3ns": len(at3),
                             "mean_steps_to_recover": sum(steps) / len(steps) if steps else None,
                             "largest_recovered_ns": largest_tolerated(js, ok)}
    return {"rows": rows, "by_direction_deg": per_dir,
            "paper": "3 N s (10 N, 0.3 s) on the torso at 0.2 m/s recovered in every direction shown (Fig. 5A)"}


# --- model error, slope (Fig. 5B) ---------------------------------------------------------------------------

MASS_BODIES = {"DWYTorso": (0.5, 1.0, 2.0, 3.0, 4.0), "Waist": (1.0, 2.0, 4.0), "RThighLowLeg": (0.5, 1.0, 2.0),
               "RLowLeg": (0.5, 1.0, 2.0), "RFoot": (0.25, 0.5, 1.0)}


def _mass_plan(name, size, gait):
    rows, labels = [Row(forward_mps=WALK_MPS)], [{"body": "none", "payload_kg": 0.0}]
    order = sorted(((b, kg) for b, kgs in MASS_BODIES.items() for kg in kgs), key=lambda p: (p[1] != 1.0, p))
    for body, kg in order:
        com = BACKPACK_COM_M if body == "DWYTorso" else (0.0, 0.0, 0.0)
        rows.append(Row(forward_mps=WALK_MPS, scenario=Scenario(payload_kg=kg, payload_body=body, payload_com_m=com)))
        labels.append({"body": body, "payload_kg": kg})
    return _small(Plan(rows[1:] + rows[:1], labels[1:] + labels[:1], 10.0, {}), size)


def _mass_reduce(plan, res):
    rows = _table(plan, res)
    nominal = [x for x in rows if x["body"] == "none"]
    largest = {}
    for body in MASS_BODIES:
        kgs, ok = _by(plan, res, "payload_kg", lambda lab, b=body: lab["body"] == b)
        if kgs:
            largest[body] = largest_tolerated(kgs, ok)
    return {"rows": rows, "nominal_fell": nominal[0]["fell"] if nominal else None, "largest_tolerated_kg": largest,
            "paper": "1 kg torso backpack, CoM 1 cm back, and extra weights elsewhere tolerated (Fig. 5B)"}


SLOPES_DEG = (2.5, 5.0, 7.5, 10.0, 12.5, 15.0, 20.0)


def _slope_plan(name, size, gait):
    vals = [s for a in SLOPES_DEG for s in (a, -a)]
    plan = Plan([Row(forward_mps=WALK_MPS, scenario=Scenario(slope_deg=s)) for s in vals],
                [{"slope_deg": s} for s in vals], 10.0, {})
    return _small(plan, size)


def _slope_reduce(plan, res):
    rows = _table(plan, res)
    up = _by(plan, res, "slope_deg", lambda lab: lab["slope_deg"] > 0)
    down = _by(plan, res, "slope_deg", lambda lab: lab["slope_deg"] < 0)
    return {"rows": rows, "largest_up_deg": largest_tolerated(*up), "largest_down_deg": largest_tolerated(*down),
            "paper": "15 deg is the largest tolerated slope (Fig. 5B)"}


# --- noise, delay (Fig. 5C) ---------------------------------------------------------------------------------

IMU_NOISE_DEG = (0.25, 0.5, 1.0, 2.0, 3.0, 4.0)
JOINT_NOISE_DEG = (0.25, 0.5, 1.0, 2.0)


def _noise_plan(name, size, gait):
    rows, labels = [], []
    for d in IMU_NOISE_DEG:
        rows.append(Row(forward_mps=WALK_MPS, scenario=Scenario(imu_noise_deg=d, joint_noise_deg=1.0)))
        labels.append({"imu_noise_deg": d, "joint_noise_deg": 1.0, "axis": "imu"})
    for d in JOINT_NOISE_DEG:
        rows.append(Row(forward_mps=WALK_MPS, scenario=Scenario(imu_noise_deg=0.0, joint_noise_deg=d)))
        labels.append({"imu_noise_deg": 0.0, "joint_noise_deg": d, "axis": "joint"})
    order = sorted(range(len(rows)), key=lambda i: labels[i]["imu_noise_deg"] != 3.0)
    return _small(Plan([rows[i] for i in order], [labels[i] for i in order], 10.0, {}), size)


def _noise_reduce(plan, res):
    rows = _table(plan, res)
    imu = _by(plan, res, "imu_noise_deg", lambda lab: lab["axis"] == "imu")
    joint = _by(plan, res, "joint_noise_deg", lambda lab: lab["axis"] == "joint")
    return {"rows": rows, "largest_imu_noise_deg_with_1deg_joint": largest_tolerated(*imu),
            "largest_joint_noise_deg_alone": largest_tolerated(*joint),
            "paper": "IMU noise std 3 deg with joint noise std 1 deg tolerated (Fig. 5C)"}


DELAYS_MS = (2.0, 4.0, 6.0, 8.0, 10.0, 14.0, 20.0)


def _delay_plan(name, size, gait):
    vals = sorted(DELAYS_MS, key=lambda d: d != 10.0)
    plan = Plan([Row(forward_mps=WALK_MPS, scenario=Scenario(delay_ms=d)) for d in vals],
                [{"delay_ms": d} for d in vals], 10.0, {})
    return _small(plan, size)


def _delay_reduce(plan, res):
    rows = _table(plan, res)
    return {"rows": rows, "largest_delay_ms": largest_tolerated(*_by(plan, res, "delay_ms")),
            "paper": "10 ms controller-to-robot delay tolerated (Fig. 5C)"}


# --- terrain (Fig. 5D), actuators ---------------------------------------------------------------------------

TERRAIN_CM = 5
TERRAIN_SEEDS = (0, 1, 2)


def _terrain_plan(name, size, gait):
    seeds = TERRAIN_SEEDS if size == "full" else TERRAIN_SEEDS[:1]
    return Plan([Row(forward_mps=WALK_MPS, scenario=Scenario(terrain=f"rough:{TERRAIN_CM}:{s}")) for s in seeds],
                [{"terrain": f"rough:{TERRAIN_CM}:{s}", "terrain_seed": s} for s in seeds],
                30.0 if size == "full" else SMALL_S, {})


def _terrain_reduce(plan, res):
    rows = _table(plan, res)
    return {"rows": rows, "walked": sum(not x["fell"] for x in rows), "terrains": len(rows),
            "paper": "30 s over +-5 cm rough ground (Fig. 5D)"}


SEA_BANDWIDTHS_HZ = (40.0, 20.0, 10.0, 5.0, 2.5)


def _actuators_plan(name, size, gait):
    if gait.plant == "position":
        raise ValueError(f"actuators compares torque loops: {name} is position-controlled")
    rows, labels = [Row(forward_mps=WALK_MPS, actuator=(("torque_loop", "ideal"), ("delay_s", 0.0)))], [
        {"torque_loop": "ideal", "bandwidth_hz": None, "lag_s": 0.0}]
    for f in sorted(SEA_BANDWIDTHS_HZ, key=lambda f: f != 10.0):
        rows.append(Row(forward_mps=WALK_MPS, actuator=(("torque_loop", "sea"), ("delay_s", 0.010),
                                                        ("torque_bandwidth_hz", f))))
        labels.append({"torque_loop": "sea", "bandwidth_hz": f, "lag_s": 1.0 / (2.0 * math.pi * f)})
    return _small(Plan(rows, labels, 10.0, {}), size)


def _actuators_reduce(plan, res):
    rows = _table(plan, res)
    ideal = [x for x in rows if x["torque_loop"] == "ideal"]
    lags, ok = _by(plan, res, "lag_s", lambda lab: lab["torque_loop"] == "sea")
    return {"rows": rows, "ideal_walked": (not ideal[0]["fell"]) if ideal else None,
            "largest_sea_lag_s": largest_tolerated(lags, ok), "sea_transport_delay_s": 0.010,
            "paper": "ideal torques in simulation; about 50 ms of actuator lag on the real robot is too slow"}


EXPERIMENTS = {e.name: e for e in (
    Experiment("speeds", "forward speeds -0.2..0.4 m/s, 20 s each (Fig. 3)", _speeds_plan, _speeds_reduce),
    Experiment("steer", "forward speed and steering rate ramped over 3 s, 10 s each (Fig. 4)", _steer_plan,
               _steer_reduce),
    Experiment("push", "3 N s pushes in 8 directions at 4 phases, and the largest recovered (Fig. 5A)", _push_plan,
               _push_reduce),
    Experiment("model-error", "extra mass on the torso (1 cm back) and other bodies (Fig. 5B)", _mass_plan,
               _mass_reduce),
    Experiment("slope", "up and down slopes to 20 deg (Fig. 5B)", _slope_plan, _slope_reduce),
    Experiment("noise", "IMU orientation noise with 1 deg joint noise, and joint noise alone (Fig. 5C)",
               _noise_plan, _noise_reduce),
    Experiment("delay", "extra controller-to-robot delay to 20 ms (Fig. 5C)", _delay_plan, _delay_reduce),
    Experiment("terrain", "30 s over +-5 cm rough ground, 3 terrain seeds (Fig. 5D)", _terrain_plan,
               _terrain_reduce),
    Experiment("actuators", "ideal torques and the series-elastic loop at 40-2.5 Hz", _actuators_plan,
               _actuators_reduce),
)}
