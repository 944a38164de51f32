"""Basin maps: recovered / fell / failed solve / NaN over push phase x impulse, one panel per direction and
scenario of each sweep, saved atomically (basin.png, compare.png)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from jaxlp.files import save_bytes_atomic
from sweeps.grid import SweepConfig
from sweeps.rows import blocks, pooled, recovered, scenario_rows
from sweeps.runner import SweepRun

MAX_COLUMNS = 4  # basin maps per row of a figure


def _grid(config: SweepConfig, values: np.ndarray) -> np.ndarray:
    """(n,) phase-major values as (impulses, phases) for plotting."""
    return np.asarray(values).reshape(len(config.phases), len(config.impulses_ns)).T


MAP_COLOURS = ("#7fc97f", "#f0027f", "#999999", "#fdb462")
MAP_LABELS = ("recovered", "fell", "numerically bad (NaN)", "controller's solve failed")


def map_states(results: dict) -> np.ndarray:
    """Per rollout the index into :data:`MAP_COLOURS`: 0 recovered, 1 fell, 2 NaN, 3 ended by a failed solve."""
    failed = np.asarray(results.get("reason", np.zeros(np.shape(results["fell"]), str))) == "solve_failed"
    return np.where(results["nan"], 2, np.where(recovered(results), 0, np.where(failed, 3, 1)))


def plot_basin(ax, config: SweepConfig, results: dict, title: str | None = None) -> None:
    """Recovered / fell / failed solve / NaN map over push phase x impulse, with steps-to-recover contours."""
    from matplotlib.colors import ListedColormap

    ph = np.asarray(config.phases)
    imp = np.asarray(config.impulses_ns)
    state = map_states(results)
    cmap = ListedColormap(MAP_COLOURS)
    dph = 1.0 / len(ph) if len(ph) > 1 else 1.0
    x_edges = np.append(ph, ph[-1] + (ph[-1] - ph[-2] if len(ph) > 1 else dph))
    y_edges = _edges(imp)
    ax.pcolormesh(x_edges, y_edges, _grid(config, state), cmap=cmap, vmin=-0.5, vmax=len(MAP_COLOURS) - 0.5,
                  shading="flat")
    steps = _grid(config, np.where(recovered(results) & (results["steps_to_recover"] >= 0),
                                   results["steps_to_recover"], np.nan)).astype(float)
    if len(ph) > 1 and len(imp) > 1 and np.isfinite(steps).sum() > 3:
        levels = np.arange(np.nanmin(steps), np.nanmax(steps) + 1)
        if levels.size > 1:
            cs = ax.contour(ph + 0.5 * np.diff(x_edges), imp, steps, levels=levels, colors="k", linewidths=0.8)
            ax.clabel(cs, fmt=lambda v: f"{v:.0f} st", fontsize=7)
    ax.set_xlabel(f"push start, fraction of step {config.push_step} (step {config.step_time_s:g} s)")
    ax.set_ylabel(f"impulse, N s  ({config.push_duration_s:g} s push: force = impulse / {config.push_duration_s:g} s)")
    ax.set_xlim(x_edges[0], x_edges[-1])
    sec = ax.secondary_yaxis("right", functions=(lambda j: j / config.push_duration_s,
                                                 lambda f: f * config.push_duration_s))
    sec.set_ylabel("force, N")
    ax.set_title(title or f"{config.model} / {config.controller}: {config.direction} pushes")


def _edges(v: np.ndarray) -> np.ndarray:
    if len(v) == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5])
    mid = 0.5 * (v[1:] + v[:-1])
    return np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])


def _legend(fig) -> None:
    from matplotlib.patches import Patch

    fig.legend(handles=[Patch(color=c, label=label) for c, label in zip(MAP_COLOURS, MAP_LABELS)],
               loc="lower center", ncol=len(MAP_COLOURS), frameon=False)


def save_basin_png(path: Path, runs: list[SweepRun], row_per_run: bool = False) -> None:
    """Basin maps of runs (one per direction and scenario of each; several repeats pooled: :func:`pooled`) to
    ``path`` (Agg backend): up to :data:`MAX_COLUMNS` a row, or with ``row_per_run`` one row per run (the
    comparison: rows controllers, columns directions and scenarios). One colour scale for all."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = []
    for run in runs:
        panels = []
        for cfg, res in blocks(run.config, run.results):
            cfg, res = cfg.for_repeat(), pooled(cfg, res)
            where = f"{cfg.direction} pushes" if run.config.directions else ""
            if not cfg.scenario:
                panels.append((cfg, res, f"{cfg.model} / {cfg.controller}: {where}" if where else None))
                continue
            for s, values in enumerate(cfg.scenarios()):
                label = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items())
                panels.append((cfg, scenario_rows(cfg, res, s),
                               f"{cfg.controller}: {label}" + (f", {where}" if where else "")))
        rows.append(panels)
    if max(len(r) for r in rows) == 1:  # one map per run: side by side
        row_per_run = False
    if not row_per_run:
        flat = [p for panels in rows for p in panels]
        ncol = min(len(flat), MAX_COLUMNS)
        rows = [flat[i:i + ncol] for i in range(0, len(flat), ncol)]
    ncol, nrow = max(len(r) for r in rows), len(rows)
    w, h = (5.8, 4.8) if not row_per_run else (4.2, 3.6)
    fig, axes = plt.subplots(nrow, ncol, figsize=(w * ncol, h * nrow), squeeze=False, sharey=True)
    for r, panels in enumerate(rows):
        for c in range(ncol):
            if c < len(panels):
                plot_basin(axes[r, c], *panels[c])
            else:
                axes[r, c].set_visible(False)
    fig.tight_layout(rect=(0, 0.07 / nrow, 1, 1))
    _legend(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    save_bytes_atomic(path, buf.getvalue())
