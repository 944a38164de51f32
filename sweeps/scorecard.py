"""The side-by-side scorecard of a comparison (``coman-sweep compare``): per controller and scenario, ground truth.

One row per controller and scenario (every value of the batched scenario axes, and each terrain's run):

* per push direction, the largest recovered impulse, N s: the largest impulse recovered at any phase, 0 if
  none; with ``repeats`` K > 1 its mean over the K runs of the grid (each with its own draw of sensor noise
  and robot) and a 95 % percentile bootstrap interval over those runs (``None`` for one run);
* the share of pushes recovered, of all of them: a walk that went non-finite did not recover (it is counted
  in ``nan`` too; the sweep's own summaries leave such walks out of their rates), and the median steps to
  recover of those that settled; ``fell`` counts falls, ``solve_failed`` walks ended by the controller's
  failed solve;
* mean forward speed of the recovered walks; mean absolute knee torque and median cost of transport while
  walking before the push; the peak absolute knee torque (models that record effort, as ``mjx``);
* env-steps per second of the controller's sweep (with ``rate_includes_compile``).

Per controller, ``tolerated``: for each scenario axis of several values (and the terrain), one axis at a time
with the others nominal, the values whose scenario recovered at least :data:`TOLERATED_SHARE` of its pushes,
and the largest magnitude up to which every value did (``max_tolerated``; terrain by its height in cm, actuator 0 ideal, 1 series-elastic).
"""

from __future__ import annotations

import numpy as np

from sweeps.grid import SweepConfig, direction_rad
from sweeps.report import direction_rows, outcome_counts, recovered, scenario_rows
from sweeps.stats import bootstrap_interval
from sweeps.runner import SweepRun

TOLERATED_SHARE = 0.5
EFFORT = ("mean_abs_knee_torque_nm", "cost_of_transport", "peak_abs_knee_torque_nm")


def largest_recovered_ns(res: dict) -> float:
    """The largest impulse recovered at any phase (0 if none)."""
    ok = recovered(res)
    return float(np.max(np.asarray(res["impulse_ns"], float)[ok])) if ok.any() else 0.0


def _stat(fn, values):
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return float(fn(v)) if v.size else None


def _rows(cfg: SweepConfig, res: dict, d: int, s: int) -> dict:
    """Direction ``d``, scenario ``s`` (every repeat, repeat-major)."""
    return scenario_rows(cfg, direction_rows(cfg, res, d), s)


def scenario_row(run: SweepRun, s: int) -> dict:
    """The scorecard row of scenario ``s`` of one controller's sweep."""
    cfg, res = run.config, run.results
    n_dir = len(cfg.direction_list)
    per_dir = []
    for d, name in enumerate(cfg.direction_list):
        sub = _rows(cfg, res, d, s)
        n = len(sub["index"]) // cfg.repeats
        each = [largest_recovered_ns({k: v[r * n:(r + 1) * n] for k, v in sub.items()}) for r in range(cfg.repeats)]
        per_dir.append(dict(direction=name, direction_deg=float(np.degrees(direction_rad(name))),
                            largest_recovered_impulse_ns=float(np.mean(each)),
                            interval_ns=bootstrap_interval(each)))
    both = [_rows(cfg, res, d, s) for d in range(n_dir)]
    res_s = {k: np.concatenate([b[k] for b in both]) for k in res}
    ok = recovered(res_s)
    pushed = np.asarray(res_s["impulse_ns"]) > 0
    steps = np.asarray(res_s["steps_to_recover"])[ok & pushed]
    row = dict(controller=cfg.controller, scenario=dict(cfg.scenarios()[s], terrain=cfg.terrain),
               rollouts=int(ok.size), repeats=cfg.repeats, per_direction=per_dir,
               recovery_rate=float(np.mean(ok)), **outcome_counts(res_s),
               median_steps_to_recover=_stat(np.median, steps[steps >= 0]),
               mean_speed_mps=_stat(np.mean, res_s["mean_speed_mps"][ok]) if "mean_speed_mps" in res_s else None)
    for k in EFFORT:
        if k in res_s:
            fn = np.max if k.startswith("peak") else np.median if k == "cost_of_transport" else np.mean
            row[k] = _stat(fn, res_s[k][~np.asarray(res_s["nan"], bool)])
    row.update(env_steps_per_s=run.timing["env_steps_per_s"], rate_includes_compile=run.timing["rate_includes_compile"])
    return row


def _magnitude(axis: str, value) -> float:
    if axis == "actuator":  # the series-elastic loop's lag is the harder one
        return {"ideal": 0.0, "sea": 1.0}[value]
    if axis == "terrain":
        parts = str(value).split(":")
        return 0.0 if parts[0] == "flat" else float(parts[1])
    return abs(float(value))


def tolerated(rows: list[dict]) -> dict:
    """Per scenario axis with several values among ``rows`` (one controller's), one axis at a time (every other
    axis at its nominal value, the smallest in magnitude): the values whose scenario recovered at least
    :data:`TOLERATED_SHARE` of its pushes, and the largest magnitude up to which every value did (``None`` if
    the smallest did not)."""
    out = {}
    axes = sorted({a for r in rows for a in r["scenario"]})
    order = {a: sorted({r["scenario"][a] for r in rows}, key=lambda v: (_magnitude(a, v), str(v))) for a in axes}
    for a in axes:
        values = order[a]
        if len(values) < 2:
            continue
        nominal = [r for r in rows if all(r["scenario"][b] == order[b][0] for b in axes if b != a)]
        good = [v for v in values if all(r["recovery_rate"] >= TOLERATED_SHARE
                                         for r in nominal if r["scenario"][a] == v)]
        best = None
        for v in values:  # by magnitude: stop at the first that fails
            if v not in good:
                break
            best = _magnitude(a, v)
        out[a] = dict(tolerated_values=good, max_tolerated=best)
    return out


def scorecard(runs: list[SweepRun]) -> dict:
    """The scorecard of a comparison's runs (every controller, every terrain)."""
    rows = [scenario_row(run, s) for run in runs for s in range(run.config.n_scenarios)]
    ctrls = list(dict.fromkeys(r["controller"] for r in rows))
    cfg = runs[0].config
    return dict(
        model=cfg.model, speed_mps=cfg.speed_mps, push_duration_s=cfg.push_duration_s, push_step=cfg.push_step,
        phases=list(cfg.phases), impulses_ns=list(cfg.impulses_ns), directions=list(cfg.direction_list),
        repeats=cfg.repeats, seed=cfg.seed, tolerated_share=TOLERATED_SHARE,
        controllers={c: dict(tolerated=tolerated([r for r in rows if r["controller"] == c])) for c in ctrls},
        rows=rows,
    )


def _num(v, fmt: str = "{:.2f}") -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else fmt.format(v)


def markdown(card: dict) -> str:
    """scorecard.md: one table row per controller and scenario, then the tolerated scenario values."""
    dirs = card["directions"]
    head = ["controller", "scenario", *(f"{d}" for d in dirs), "recovered", "fell", "solve failed", "NaN",
            "median steps",
            "speed m/s", "knee N m", "peak knee N m", "CoT", "env-steps/s"]
    lines = [f"Largest recovered impulse (N s) per push direction (degrees from forward, + left), "
             f"{card['push_duration_s']:g} s pushes at {card['speed_mps']:g} m/s"
             + (f"; mean of {card['repeats']} noise seeds [95 % bootstrap interval]" if card["repeats"] > 1 else ""),
             "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in card["rows"]:
        scen = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in r["scenario"].items())
        cells = []
        for p in r["per_direction"]:
            iv = p["interval_ns"]
            cells.append(f"{p['largest_recovered_impulse_ns']:.1f}" + (f" [{iv[0]:.1f}, {iv[1]:.1f}]" if iv else ""))
        rate = r["recovery_rate"]
        lines.append("| " + " | ".join([
            r["controller"], scen, *cells, f"{rate:.0%}", str(r["fell"]), str(r.get("solve_failed", 0)), str(r["nan"]),
            _num(r["median_steps_to_recover"], "{:g}"), _num(r["mean_speed_mps"], "{:.3f}"),
            _num(r.get("mean_abs_knee_torque_nm")), _num(r.get("peak_abs_knee_torque_nm"), "{:.1f}"),
            _num(r.get("cost_of_transport")), _num(r["env_steps_per_s"], "{:.0f}")]) + " |")
    tol = [(c, a, t) for c, v in card["controllers"].items() for a, t in v["tolerated"].items()]
    if tol:
        lines += ["", f"Tolerated (at least {card['tolerated_share']:.0%} of pushes recovered):", ""]
        lines += [f"- {c}, {a}: up to {_num(t['max_tolerated'], '{:g}')} "
                  f"(values passing: {', '.join(str(v) for v in t['tolerated_values']) or 'none'})" for c, a, t in tol]
    return "\n".join(lines) + "\n"
