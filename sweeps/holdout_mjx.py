"""Held-out validation of estimation constants on COMAN in MJX, through the sweep machinery.

The seed's constants and the tuned ones (``tuned.json`` of ``coman-sweep
tune``, either plant) meet the same held-out pushes on the ``mjx`` sweep model
(:mod:`sweeps.model_mjx`: COMAN in MuJoCo MJX under the walking controller,
with its 12-bit encoders, nominal IMU/F-T noise and constant per-joint encoder
offsets, the systematic errors the dead-zones are for). Each (constants,
direction) pair is one ordinary sweep run by :func:`sweeps.runner.run_sweep`
into its own folder, so it is chunked, sharded over the devices and resumed
after a kill like any ``coman-sweep map``; a folder holding another sweep is
refused. Per set: recovery rate, steps to recover (``WalkResult.steps_to_recover``:
phase changes until the filtered pelvis error stays within the walk's
tolerance) and the largest recovered impulse per phase
(:func:`sweeps.holdout.compare`), and basin maps (:func:`sweeps.holdout.plot_holdout`).

The MJX controller takes the four sagittal dead-zone thresholds, ``zeta`` and
a whole-sample velocity window (the tuned window is rounded).
"""

from __future__ import annotations

import json
from pathlib import Path

from sweeps.grid import SweepConfig

SETS = ("seed", "tuned")
DEFAULT_GRID = dict(directions=("forward", "backward"), phases=(0.0, 0.25, 0.5, 0.75),
                    impulses_ns=(0.0, 2.0, 4.0, 6.0, 8.0), n_steps=8, push_step=2, sensor_noise_scale=1.0,
                    encoder_offset_std_rad=0.002, chunk=64)


def sweep_fields(constants: dict) -> dict:
    """``SweepConfig`` fields (``deadzone``, ``zeta``, ``velocity_window``) of a constants dict.

    Args:
        constants: as ``constants_before`` / ``constants_after`` of ``tuned.json``
            (:meth:`sweeps.objective.Constants.as_dict` names; the DLQR weight scales may be absent).

    Raises:
        ValueError: a missing or bad constant, naming it (:func:`sweeps.objective.make_constants`).
    """
    from sweeps.objective import CONSTANT_NAMES, make_constants

    try:
        c = make_constants([constants[n] for n in CONSTANT_NAMES[:4]], constants["zeta"], constants["window_samples"])
    except KeyError as e:
        raise ValueError(f"constants lack {e.args[0]!r}") from None
    return dict(deadzone=tuple(float(v) for v in c.deadzone), zeta=float(c.zeta),
                velocity_window=int(round(float(c.window_samples))))


def load_constants(path: Path, which: str = "after") -> dict:
    """``SweepConfig`` fields from a ``tuned.json`` (its ``constants_<which>``) or a flat constants JSON.

    Raises:
        ValueError: an unreadable file or bad constants, naming the file.
    """
    if which not in ("before", "after"):
        raise ValueError(f"which must be 'before' or 'after', got {which!r}")
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read constants from {path}: {e}") from None
    if not isinstance(d, dict):
        raise ValueError(f"{path} holds no constants object")
    d = d.get(f"constants_{which}", d)
    try:
        return sweep_fields(d)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def holdout_configs(fields: dict, *, seed: int = 1, controller: str = "time-projection", **grid) -> list[SweepConfig]:
    """One MJX sweep per direction with the constants ``fields`` (``grid`` overrides :data:`DEFAULT_GRID`)."""
    g = dict(DEFAULT_GRID, **grid, **fields)
    dirs = g.pop("directions")
    g["phases"], g["impulses_ns"] = tuple(g["phases"]), tuple(g["impulses_ns"])
    return [SweepConfig(model="mjx", controller=controller, direction=d, seed=seed, **g).validate() for d in dirs]


def run_mjx_holdout(record: dict, out: Path, *, progress: bool = True, resume: bool = True, force: bool = False,
                    **grid) -> dict:
    """The held-out MJX sweeps of the seed and the tuned constants of ``record``; write the outputs.

    Writes to ``out``: ``holdout-mjx/<set>/<direction>/`` (each an ordinary
    sweep folder: chunks, results, basin map, summary), ``holdout_mjx.json``
    (the comparison, the grid and the constants), ``holdout_mjx.npz`` and
    ``holdout_mjx.png`` (maps: one row per set, one column per direction).

    Args:
        record: a ``coman-sweep tune`` record (``constants_before`` / ``constants_after``, ``config``).
        out: the tuning output folder.
        progress: progress bars on stderr.
        resume: keep finished chunks of the same sweeps (a re-run redoes nothing finished).
        force: overwrite folders that hold other sweeps.
        **grid: overrides of :data:`DEFAULT_GRID` (and ``seed``, default the tuning seed + 1).

    Returns:
        ``{"table": sweeps.holdout.compare(...), "runs": {set: [SweepRun, ...]}}``.
    """
    from sweeps import holdout, report
    from sweeps.runner import run_sweep, save_text_atomic

    out = Path(out)
    cfg = record["config"]
    grid.setdefault("seed", int(cfg["seed"]) + 1)
    grid.setdefault("controller", cfg["controller"])
    sets = {name: sweep_fields(record[f"constants_{which}"]) for name, which in zip(SETS, ("before", "after"))}
    runs = {}
    for name, fields in sets.items():
        runs[name] = []
        for c in holdout_configs(fields, **grid):
            folder = out / "holdout-mjx" / name / c.direction
            run = run_sweep(c, folder, resume=resume, force=force, progress=progress,
                            desc=f"held-out mjx {name}/{c.direction}")
            report.write_outputs(folder, run)
            runs[name].append(run)
    table = holdout.compare(runs)
    for name, t in table.items():
        t["constants"] = sets[name]
        t["wall_s"] = float(sum(r.timing["wall_s"] for r in runs[name]))
    save_text_atomic(out / "holdout_mjx.json", json.dumps(dict(table, grid={**DEFAULT_GRID, **grid}), indent=1))
    holdout.save_runs(out / "holdout_mjx.npz", runs)
    holdout.plot_holdout(out / "holdout_mjx.png", runs)
    return dict(table=table, runs=runs)


def format_table(table: dict) -> str:
    """One line per constant set: recovery rate, mean steps to recover, the weakest phase."""
    lines = []
    for name in SETS:
        t = table[name]
        steps = "-" if t["mean_steps_to_recover"] is None else f"{t['mean_steps_to_recover']:.2f}"
        weakest = []
        for d in t["per_direction"]:
            best = [r["max_recovered_impulse_ns"] for r in d["per_phase"]]
            weakest.append(f"{d['direction']} {min(v or 0.0 for v in best):g}")
        lines.append(f"  held-out MJX grid, {name} constants: {t['recovery_rate']:.1%} of {t['rollouts']} recovered; "
                     f"{t['settled_within_tol']} pushed walks settled, after {steps} steps on average; "
                     f"largest impulse recovered at the weakest phase (N s): {', '.join(weakest)}")
    return "\n".join(lines)

