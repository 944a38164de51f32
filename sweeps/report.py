"""Sweep outputs: results.npz, results.csv, basin.png and summary.json; the controller comparison.

The rows of one scenario, direction or repeat are :mod:`sweeps.rows`'; the maps are :mod:`sweeps.basin_plot`'s
(both re-exported here).

One meaning per word, in rows and summaries alike: ``nan`` a rollout that
went non-finite, ``fell`` a finite rollout that fell or whose controller's
solve failed (which ends a walk), recovered neither (``reason`` is
``"nan"``, ``"solve_failed"``, ``"fell"`` or ``""``; the summaries count
``fell`` and ``solve_failed`` apart). NaN rollouts are counted
(``nan``) and left out of every statistic: rates are over the finite
rollouts, maxima and medians over the recovered ones.

A sweep with scenario axes (``SweepConfig.scenario``) records each row's
scenario (``scenario_index`` and a column per axis); its summary's
top-level statistics pool every scenario, and ``per_scenario`` gives each
one's own (per phase, the limit-cycle comparison against its own unpushed
walks); basin.png draws one map per scenario.

A sweep of several push directions (``SweepConfig.directions``) reports
each direction's rows as a sweep of its own (``per_direction``); its
top-level ``per_phase`` counts an impulse as recovered at a phase only where
every direction (and scenario) recovered it; basin.png draws one map per
direction and scenario.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from jaxlp.files import save_npz_atomic, save_text_atomic, strict_json
from sweeps.basin_plot import MAP_COLOURS, MAP_LABELS, map_states, plot_basin, save_basin_png  # noqa: F401
from sweeps.grid import SCENARIO_AXES, TEXT_AXES, SweepConfig, direction_rad
from sweeps.rows import (blocks, direction_rows, outcome_counts, pooled, recovered, repeat_rows,  # noqa: F401
                         scenario_rows)
from sweeps.runner import SweepRun

CSV_COLUMNS = ("index", "phase", "impulse_ns", "force_n", "direction_rad", "fell", "steps_to_recover",
               "max_abs_footstep_adjustment_m", "fall_time_s", "reason")
_BASE = set(CSV_COLUMNS) | {"nan"}
_SCENARIO = ("scenario_index", *SCENARIO_AXES)


def scenario_columns(results: dict) -> list[str]:
    """The per-row scenario columns of the results (none without scenario axes)."""
    return [k for k in _SCENARIO if k in results]


def extra_columns(results: dict) -> list[str]:
    """The model's further per-rollout outputs (``RolloutOutputs.extra``), sorted."""
    return sorted(k for k in results if k not in _BASE and k not in _SCENARIO)


def _max_or_none(values: np.ndarray):
    vals = np.asarray(values, float)
    vals = vals[np.isfinite(vals)]
    return float(np.max(vals)) if vals.size else None


def recovery_rate(results: dict, where=True) -> float | None:
    """Share of the finite rollouts (of those ``where`` selects) that recovered (``None`` if none is finite)."""
    finite = ~np.asarray(results["nan"], bool) & where
    return float(np.mean(recovered(results)[finite])) if finite.any() else None


def percent(rate: float | None) -> str:
    """A rate for people: ``"62.5%"``, or ``"n/a"`` for ``None`` (no finite rollout)."""
    return "n/a" if rate is None else f"{rate:.1%}"


def per_phase(config: SweepConfig, results: dict) -> list[dict]:
    """Per push timing: the largest impulse recovered (N s and N), the largest up to which every impulse of
    the grid was recovered (``recovered_up_to_ns``; ``None`` if the smallest fell), the recovery rate."""
    ok = recovered(results)
    rows = []
    for ph in config.phases:
        sel = np.isclose(results["phase"], ph)
        best = _max_or_none(np.where(ok[sel], results["impulse_ns"][sel], np.nan))
        imp, inv = np.unique(results["impulse_ns"][sel], return_inverse=True)
        ok_u = np.ones(imp.size, bool)
        np.logical_and.at(ok_u, inv.ravel(), ok[sel])  # recovered in every repeat
        n_ok = int(np.cumprod(ok_u).sum())  # recovered from the smallest impulse up
        up_to = float(imp[n_ok - 1]) if n_ok else None
        rows.append(dict(
            phase=float(ph), max_recovered_impulse_ns=best, recovered_up_to_ns=up_to,
            max_recovered_force_n=None if best is None else best / config.push_duration_s,
            recovery_rate=recovery_rate(results, sel),
            nan_rollouts=int(np.sum(results["nan"][sel])),
        ))
    return rows


def _cycle_stats(res: dict, ok: np.ndarray) -> dict:
    """How far the recovered pushed walks' final limit cycles lie from the unpushed walks' (mjx)."""
    if "cycle_forward_mps" not in res:
        return {}
    cyc = np.stack([res["cycle_forward_mps"], res["cycle_lateral_mps"]], axis=1).astype(float)
    pushed = res["impulse_ns"] > 0
    ref_rows = ok & ~pushed & np.all(np.isfinite(cyc), axis=1)
    if not ref_rows.any():
        return dict(unpushed_cycle_mps=None, max_cycle_difference_mps=None)
    ref = cyc[ref_rows].mean(axis=0)
    rec = ok & pushed & (res["steps_to_recover"] >= 0)
    diff = np.linalg.norm(cyc[rec] - ref, axis=1)
    return dict(unpushed_cycle_mps=ref.tolist(), max_cycle_difference_mps=float(diff.max()) if diff.size else None)


def _scenario_summary(cfg: SweepConfig, res: dict) -> list[dict]:
    out = []
    for s, values in enumerate(cfg.scenarios()):
        sub = scenario_rows(cfg, res, s)
        ok = recovered(sub)
        cyc = _cycle_stats(sub, ok)
        out.append(dict(scenario_index=s, scenario=values, recovery_rate=recovery_rate(sub),
                        **outcome_counts(sub),
                        **cyc, per_phase=per_phase(cfg, sub)))
    return out


def _direction_summary(cfg: SweepConfig, res: dict) -> dict:
    """One direction's statistics (``cfg`` a single-direction config, ``res`` its rows)."""
    ok = recovered(res)
    s2r = _steps_to_recover(res, ok)
    return dict(direction=cfg.direction, direction_deg=float(np.degrees(direction_rad(cfg.direction))),
                recovery_rate=recovery_rate(res), **outcome_counts(res),
                median_steps_to_recover=float(np.median(s2r)) if s2r.size else None,
                per_phase=phase_rows(cfg, res),
                **({} if not cfg.scenario else dict(per_scenario=_scenario_summary(cfg, res))))


def _steps_to_recover(res: dict, ok: np.ndarray) -> np.ndarray:
    """Steps to recover of the recovered pushed rollouts that settled."""
    s2r = np.asarray(res["steps_to_recover"])[ok & (np.asarray(res["impulse_ns"]) > 0)]
    return s2r[s2r >= 0]


def summarize(run: SweepRun) -> dict:
    """The summary.json content of a sweep."""
    cfg, res = run.config, run.results
    ok = recovered(res)
    scen = _scenario_summary(cfg, res) if cfg.scenario and not cfg.directions else None
    cycle = _cycle_stats(res, ok)
    if scen is not None and cycle:  # each scenario against its own unpushed walks
        diffs = [r["max_cycle_difference_mps"] for r in scen if r.get("max_cycle_difference_mps") is not None]
        cycle = dict(unpushed_cycle_mps=None, max_cycle_difference_mps=max(diffs) if diffs else None)
    per_phase_rows = phase_rows(cfg, res)
    t = run.timing
    s2r = _steps_to_recover(res, ok)
    several = len(cfg.direction_list) > 1
    return dict(
        model=cfg.model, engine=cfg.engine, controller=cfg.controller,
        controller_overrides=cfg.to_dict()["controller_overrides"],
        direction=", ".join(cfg.direction_list), directions=list(cfg.direction_list),
        push_duration_s=cfg.push_duration_s, push_step=cfg.push_step,
        rollouts=int(cfg.n_rollouts), recovery_rate=recovery_rate(res),
        **outcome_counts(res),
        median_steps_to_recover=float(np.median(s2r)) if s2r.size else None,
        max_abs_footstep_adjustment_m=_max_or_none(res["max_abs_footstep_adjustment_m"][ok]),
        **cycle,
        per_phase=per_phase_rows,
        **({} if scen is None else dict(per_scenario=scen)),
        **({} if not several else dict(per_direction=[_direction_summary(c, r) for c, r in blocks(cfg, res)])),
        wall_s=t["wall_s"], first_chunk_s=t["first_chunk_s"], run_s=t["run_s"],
        rollouts_per_s=t["rollouts_per_s"], env_steps_per_s=t["env_steps_per_s"],
        rate_includes_compile=t["rate_includes_compile"], env_steps_per_rollout=t["ticks_per_rollout"],
        env_step_s=t.get("env_step_s"),
        rollouts_run=t["rollouts_run"], rollouts_resumed=t["rollouts_resumed"],
        chunks_run=t["chunks_run"], chunks_resumed=t["chunks_resumed"], chunk=t["chunk"],
        device_count=t["device_count"], process_count=t["process_count"], backend=t["backend"],
        devices=t["devices"],
        seed=cfg.seed, config_hash=cfg.hash(), config=cfg.to_dict(),
    )


def phase_rows(cfg: SweepConfig, res: dict) -> list[dict]:
    """:func:`per_phase`, over every direction and scenario of the sweep: an impulse counts as recovered at a
    phase only where every direction and every scenario recovered it."""
    if not cfg.scenario and not cfg.directions:
        return per_phase(cfg, res)  # repeats: an impulse is recovered up to only if every repeat recovered it
    subs = [scenario_rows(c, r, s) for c, r in blocks(cfg, res) for s in range(cfg.n_scenarios)]
    ok = np.all([recovered(sub) for sub in subs], axis=0)
    nan = np.any([sub["nan"] for sub in subs], axis=0)
    first = dict(subs[0], fell=~ok & ~nan, nan=nan)
    return per_phase(cfg.for_direction(0), first)


def results_csv(config: SweepConfig, results: dict) -> str:
    """One CSV row per rollout (the model's extra outputs as further columns)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    extra = extra_columns(results)
    scen = scenario_columns(results)
    w.writerow((*CSV_COLUMNS, *scen, *extra))
    force = np.asarray(results["impulse_ns"]) / config.push_duration_s
    for i in range(len(results["index"])):
        w.writerow([
            int(results["index"][i]), f"{results['phase'][i]:.6g}", f"{results['impulse_ns'][i]:.6g}",
            f"{force[i]:.6g}", f"{results['direction_rad'][i]:.6g}", int(results["fell"][i]),
            int(results["steps_to_recover"][i]), f"{results['max_abs_footstep_adjustment_m'][i]:.6g}",
            f"{results['fall_time_s'][i]:.6g}", results["reason"][i],
            *(results[k][i] if k in TEXT_AXES else f"{float(results[k][i]):.6g}" for k in scen),
            *(f"{float(results[k][i]):.6g}" for k in extra),
        ])
    return buf.getvalue()


def write_outputs(out_dir: Path, run: SweepRun) -> dict:
    """results.npz, results.csv, basin.png and summary.json of one sweep; return the summary."""
    out_dir = Path(out_dir)
    save_npz_atomic(out_dir / "results.npz", {k: np.asarray(v) for k, v in run.results.items()})
    save_text_atomic(out_dir / "results.csv", results_csv(run.config, run.results))
    save_basin_png(out_dir / "basin.png", [run])
    summary = summarize(run)
    save_text_atomic(out_dir / "summary.json", strict_json(summary))
    return summary


def compare_table(runs: list[SweepRun]) -> dict:
    """Per phase, each controller's largest recovered impulse (in every direction and scenario); per direction,
    the largest it recovered; overall recovery rates."""
    cfg = runs[0].config
    rows = []
    per = {r.config.controller: phase_rows(r.config, r.results) for r in runs}
    for k, ph in enumerate(cfg.phases):
        rows.append(dict(phase=float(ph), **{f"{c}_max_recovered_impulse_ns": per[c][k]["max_recovered_impulse_ns"]
                                            for c in per}))
    out = dict(
        controllers=list(per), direction=", ".join(cfg.direction_list), push_duration_s=cfg.push_duration_s,
        recovery_rate={r.config.controller: recovery_rate(r.results) for r in runs},
        per_phase=rows,
        wall_s={r.config.controller: r.timing["wall_s"] for r in runs},
    )
    if cfg.directions:
        out["max_recovered_impulse_ns_per_direction"] = {
            r.config.controller: {c.direction: _max_or_none(np.where(recovered(b), b["impulse_ns"], np.nan))
                                  for c, b in blocks(r.config, r.results)} for r in runs}
    if cfg.scenario:
        out["scenarios"] = cfg.scenarios()
        out["recovery_rate_per_scenario"] = {
            r.config.controller: [recovery_rate(scenario_rows(r.config, r.results, s))
                                  for s in range(r.config.n_scenarios)] for r in runs}
    return out


def format_compare_table(table: dict) -> str:
    """A fixed-width text table: phase, then each controller's largest recovered impulse (N s / N)."""
    ctrls = table["controllers"]
    dur = table["push_duration_s"]
    head = f"{'phase':>6} " + " ".join(f"{c:>22}" for c in ctrls)
    what = (f"impulse recovered in every direction ({table['direction']})" if ", " in table["direction"]
            else f"recovered {table['direction']} impulse")
    lines = [f"largest {what}, N s (force N) for {dur:g} s pushes", head]
    for row in table["per_phase"]:
        cells = []
        for c in ctrls:
            v = row[f"{c}_max_recovered_impulse_ns"]
            cells.append(f"{'none':>22}" if v is None else f"{v:>11.2f} ({v / dur:>7.1f})")
        lines.append(f"{row['phase']:>6.3f} " + " ".join(cells))
    lines.append("recovery rate " + ", ".join(f"{c} {percent(table['recovery_rate'][c])}" for c in ctrls))
    return "\n".join(lines)
