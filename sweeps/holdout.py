"""Held-out validation of tuned constants: the seed's and the tuned overrides on the same held-out sweeps.

A tuning record (``tuned.json`` of ``coman-sweep tune``, either plant) holds
the controller overrides before and after tuning. Each (set, direction) pair
is one ordinary sweep of :func:`sweeps.runner.run_sweep` into its own folder
(``OUT/holdout/<set>/<direction>/``; several at once in worker processes on a
CPU, :mod:`sweeps.parallel`), so it is chunked, sharded, resumed after a kill
and refused over another sweep like any ``coman-sweep map``.
The grid is the model's default (:attr:`sweeps.models.Model.holdout_grid`:
fresh noise seed, sensors like the training ones), overridable. Constants
tuned on one model reach the other through the settings they share
(:func:`transfer_overrides`: the 3LP's real-valued ``window_samples`` becomes
the MJX controller's whole-sample ``window``). Per set: recovery rate, steps
to recover and the largest recovered impulse per phase; basin maps.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sweeps import report
from sweeps.grid import SweepConfig

SETS = ("seed", "tuned")


def transfer_overrides(overrides: dict, settings) -> dict:
    """The overrides a controller with ``settings`` can take: shared names, ``window_samples`` -> ``window``."""
    names = {s.name: s for s in settings}
    out = {}
    for k, v in overrides.items():
        if k == "window_samples" and k not in names and "window" in names:
            out["window"] = int(round(float(v)))
        elif k in names:
            out[k] = tuple(v) if isinstance(v, list) else v
    return out


def load_overrides(path: Path, which: str = "after") -> dict:
    """Controller overrides from a ``tuned.json`` (its ``overrides_<which>``) or a flat JSON of settings.

    Raises:
        ValueError: an unreadable file or no overrides, naming the file.
    """
    if which not in ("before", "after"):
        raise ValueError(f"which must be 'before' or 'after', got {which!r}")
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read constants from {path}: {e}") from None
    if not isinstance(d, dict):
        raise ValueError(f"{path} holds no settings object")
    d = d.get(f"overrides_{which}", d if "config" not in d else None)
    if not isinstance(d, dict) or not d:
        raise ValueError(f"{path} holds no controller overrides (overrides_{which})")
    return d


def holdout_configs(record: dict, model: str, overrides: dict, **grid) -> list[SweepConfig]:
    """One sweep per held-out direction with these overrides (``grid`` overrides the model's default grid).

    Raises:
        GridError: a bad grid field or override.
    """
    from sweeps.models import check, get_model

    m = get_model(model)
    g = dict(m.holdout_grid(record), **grid)
    g.setdefault("seed", int(record["config"]["seed"]) + 1)
    g.setdefault("controller", record["controller"])
    dirs = g.pop("directions")
    g["phases"], g["impulses_ns"] = tuple(g["phases"]), tuple(g["impulses_ns"])
    ov = transfer_overrides(overrides, m.settings(g["controller"]))
    return [check(SweepConfig(model=model, direction=d, **g).with_overrides(ov)) for d in dirs]


def summary(run) -> dict:
    """Recovery rate, steps to recover and the largest recovered impulse per phase of one held-out sweep."""
    res, cfg = run.results, run.config
    ok = report.recovered(res)
    pushed = res["impulse_ns"] > 0
    steps = res["steps_to_recover"][ok & pushed]
    settled = steps[steps >= 0]
    late = res.get("late_error")
    return dict(
        direction=cfg.direction, rollouts=int(cfg.n_rollouts), recovery_rate=report.recovery_rate(res),
        pushed_recovery_rate=report.recovery_rate(res, pushed),
        nan=int(np.sum(res["nan"])), solve_failed=report.outcome_counts(res)["solve_failed"],
        undisturbed_fell=int(np.sum(~ok & ~pushed)),
        mean_steps_to_recover=float(np.mean(settled)) if settled.size else None,
        recovered_but_unsettled=int(np.sum(steps < 0)),
        late_error_median=float(np.median(late[ok])) if late is not None and ok.any() else None,
        per_phase=[dict(phase=r["phase"], max_recovered_impulse_ns=r["max_recovered_impulse_ns"],
                        recovery_rate=r["recovery_rate"]) for r in report.per_phase(cfg, res)],
        wall_s=run.timing.get("wall_s"),
    )


def compare(runs: dict) -> dict:
    """Per set (``"seed"``, ``"tuned"``): per direction summaries and the pooled rates; ``paired``: the two
    sets' walks pushed alike with the same noise (:func:`sweeps.stats.paired`: Wilson intervals, McNemar's
    exact test; a walk gone non-finite did not recover)."""
    from sweeps import stats

    out = {}
    for name, lst in runs.items():
        ok = np.concatenate([report.recovered(r.results) for r in lst])
        nan = np.concatenate([np.asarray(r.results["nan"], bool) for r in lst])
        steps = np.concatenate([r.results["steps_to_recover"][report.recovered(r.results)
                                                              & (r.results["impulse_ns"] > 0)] for r in lst])
        settled = steps[steps >= 0]
        late = np.concatenate([r.results["late_error"][report.recovered(r.results)] for r in lst
                               if "late_error" in r.results] or [np.zeros(0)])
        out[name] = dict(recovery_rate=report.recovery_rate(dict(fell=~ok & ~nan, nan=nan)), rollouts=int(ok.size),
                         nan=int(nan.sum()),
                         solve_failed=sum(report.outcome_counts(r.results)["solve_failed"] for r in lst),
                         mean_steps_to_recover=float(np.mean(settled)) if settled.size else None,
                         settled=int(settled.size), model=lst[0].config.model,
                         recover_tol=lst[0].config.recover_tol if lst[0].config.model == "3lp" else None,
                         late_error_median=float(np.median(late)) if late.size else None,
                         overrides=lst[0].config.to_dict()["controller_overrides"],
                         per_direction=[summary(r) for r in lst])
    if set(SETS) <= set(runs):
        a, b = (np.concatenate([report.recovered(r.results) for r in runs[n]]) for n in SETS)
        out["paired"] = stats.paired(a, b, names=SETS)
    return out


def plot_holdout(path, runs: dict) -> None:
    """Basin maps: one row per set, one column per direction, written atomically as PNG."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxlp.files import save_bytes_atomic

    names = list(runs)
    ncol = max(len(v) for v in runs.values())
    fig, axes = plt.subplots(len(names), ncol, figsize=(5.2 * ncol, 4.2 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        for j, run in enumerate(runs[name]):
            rate = float(np.mean(report.recovered(run.results)))
            report.plot_basin(axes[i, j], run.config, run.results,
                              title=f"{name} constants: {run.config.direction} pushes, {rate:.0%} recovered")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    save_bytes_atomic(path, buf.getvalue())


def save_runs(path, runs: dict) -> None:
    """Per-rollout results of held-out sweeps as one ``.npz`` (atomically), configurations included."""
    from jaxlp.files import save_npz_atomic

    arrays = {}
    for name, lst in runs.items():
        for r in lst:
            tag = f"{name}/{r.config.direction}"
            arrays.update({f"{tag}/{k}": np.asarray(v) for k, v in r.results.items() if k != "reason"})
            arrays[f"{tag}/config"] = np.asarray(json.dumps(r.config.to_dict()))
    save_npz_atomic(path, arrays)


def load_runs(path) -> dict:
    """The inverse of :func:`save_runs` (timing left empty)."""
    from sweeps.runner import SweepRun, failure_reason

    runs: dict[str, list] = {}
    with np.load(path) as z:
        tags = list(dict.fromkeys(k.rsplit("/", 1)[0] for k in z.files))
        for tag in tags:
            cfg = SweepConfig.from_dict(json.loads(str(z[f"{tag}/config"])))
            res = {k.rsplit("/", 1)[1]: z[k] for k in z.files if k.rsplit("/", 1)[0] == tag and not k.endswith("/config")}
            res["reason"] = failure_reason(res["fell"], res["nan"], res.get("solve_failed"))
            runs.setdefault(tag.split("/")[0], []).append(SweepRun(cfg, res, {}))
    return runs


def run_holdout(record: dict, out: Path, *, model: str | None = None, progress: bool = True, resume: bool = True,
                force: bool = False, workers: int | None = None, **grid) -> dict:
    """The held-out sweeps of the seed's and the tuned overrides of ``record``; write the outputs.

    Writes to ``out``: ``holdout/<set>/<direction>/`` (each an ordinary sweep folder), ``holdout.json``
    (the comparison, the grid and the overrides), ``holdout.npz`` and ``holdout.png``.

    Args:
        record: a ``coman-sweep tune`` record.
        out: the tuning output folder.
        model: the model of the sweeps (default: the record's plant).
        progress: progress bars on stderr.
        resume: keep finished chunks of the same sweeps (a re-run redoes nothing finished).
        force: overwrite folders that hold other sweeps.
        workers: sweeps at once, one process each (default :func:`sweeps.parallel.default_workers`).
        **grid: overrides of the model's held-out grid (``SweepConfig`` fields and ``directions``).

    Returns:
        ``{"table": compare(...), "runs": {set: [SweepRun, ...]}}``.

    Raises:
        GridError: a bad grid or override. SweepConflict: a folder holding another sweep, without ``force``.
    """
    from jaxlp.files import save_text_atomic, strict_json
    from sweeps.parallel import SweepJob, default_workers, run_sweeps

    out = Path(out)
    model = model or record["plant"]
    sets = {name: record[f"overrides_{which}"] for name, which in zip(SETS, ("before", "after"))}
    configs = {name: holdout_configs(record, model, ov, **grid) for name, ov in sets.items()}
    tags = [(name, c) for name, cfgs in configs.items() for c in cfgs]
    jobs = [SweepJob(c, out / "holdout" / name / c.direction, f"held-out {model} {name}/{c.direction}")
            for name, c in tags]
    done = run_sweeps(jobs, workers=workers or default_workers(len(jobs)), resume=resume, force=force,
                      progress=progress, on_done=lambda i, run: report.write_outputs(jobs[i].out_dir, run))
    runs = {name: [] for name in configs}
    for (name, _), run in zip(tags, done):
        runs[name].append(run)
    table = compare(runs)
    for name in SETS:
        table[name]["wall_s"] = float(sum(r.timing["wall_s"] for r in runs[name]))
    save_text_atomic(out / "holdout.json", strict_json(dict(table, model=model, grid=dict(grid))))
    save_runs(out / "holdout.npz", runs)
    plot_holdout(out / "holdout.png", runs)
    return dict(table=table, runs=runs)


def format_table(table: dict) -> str:
    """One line per set: recovery rate, mean steps to recover, the weakest phase per direction."""
    lines = []
    for name in SETS:
        t = table[name]
        steps = "-" if t["mean_steps_to_recover"] is None else f"{t['mean_steps_to_recover']:.2f}"
        weakest = []
        for d in t["per_direction"]:
            best = [r["max_recovered_impulse_ns"] for r in d["per_phase"]]
            weakest.append(f"{d['direction']} {min(v or 0.0 for v in best):g}")
        finite = t["rollouts"] - t["nan"]
        count = f"{t['rollouts']}" if not t["nan"] else f"{finite} finite ({t['nan']} of {t['rollouts']} non-finite)"
        failed = f", {t['solve_failed']} ended by a failed solve" if t.get("solve_failed") else ""
        lines.append(f"  held-out {t['model']} grid, {name} constants: {report.percent(t['recovery_rate'])} of {count} "
                     f"recovered{failed}; {t['settled']} pushed walks settled, after {steps} steps on average; "
                     f"largest impulse recovered at the weakest phase (N s): {', '.join(weakest)}")
    if "paired" in table:
        p = table["paired"]
        iv = lambda n: "[{:.1%}, {:.1%}]".format(*p[f"{n}_interval"])  # noqa: E731
        lines.append(f"  paired over {p['pairs']} walks: seed {p['seed_rate']:.1%} {iv('seed')}, tuned "
                     f"{p['tuned_rate']:.1%} {iv('tuned')} (95 % Wilson); recovered by seed only {p['seed_only']}, "
                     f"by tuned only {p['tuned_only']}"
                     f"{' (a non-finite walk counts as not recovered)' if any(table[n]['nan'] for n in SETS) else ''}"
                     f": {p['verdict']}")
    return "\n".join(lines)


__all__ = ["SETS", "compare", "format_table", "holdout_configs", "load_overrides", "load_runs",
           "plot_holdout", "run_holdout", "save_runs", "summary", "transfer_overrides"]
