"""A sweep's rows: those of one scenario, push direction or repeat, the repeats pooled, and what recovered.

Rows are phase-major within a grid, a repeat's directions in blocks of ``config.n_per_direction`` rows, and
scenarios interleaved (``s::n_scenarios``); ``fell``, ``nan`` and ``reason`` mean what :mod:`sweeps.report` says.
"""

from __future__ import annotations

import numpy as np

from sweeps.grid import SweepConfig
from sweeps.runner import failure_reason


def scenario_rows(config: SweepConfig, results: dict, s: int) -> dict:
    """The results of scenario ``s`` alone (rows ``s::n_scenarios``: that scenario's grid, phase-major)."""
    k = config.n_scenarios
    return {name: np.asarray(v)[s::k] for name, v in results.items()}


def direction_rows(config: SweepConfig, results: dict, d: int) -> dict:
    """The results of push direction ``d`` alone (its block of ``config.n_per_direction`` rows in each repeat),
    in the row order of ``config.for_direction(d)``."""
    b, r = config.n_per_direction, config.n_per_repeat
    rows = (np.arange(config.repeats)[:, None] * r + d * b + np.arange(b)).ravel()
    return {name: np.asarray(v)[rows] for name, v in results.items()}


def repeat_rows(config: SweepConfig, results: dict, r: int) -> dict:
    """The results of repeat ``r`` of the grid (rows of ``config.for_repeat()``)."""
    n = config.n_per_repeat
    return {name: np.asarray(v)[r * n:(r + 1) * n] for name, v in results.items()}


def pooled(config: SweepConfig, results: dict) -> dict:
    """One repeat's rows where a push counts as recovered only if it recovered in every repeat (for maps); its
    ``reason`` is ``"nan"`` if any repeat went non-finite, else ``"solve_failed"`` if any ended by a failed
    solve, else ``"fell"`` if any fell."""
    if config.repeats == 1:
        return results
    subs = [repeat_rows(config, results, r) for r in range(config.repeats)]
    ok = np.all([recovered(sub) for sub in subs], axis=0)
    nan = np.any([sub["nan"] for sub in subs], axis=0)
    failed = np.any([np.asarray(sub["reason"]) == "solve_failed" for sub in subs], axis=0)
    steps = np.max([sub["steps_to_recover"] for sub in subs], axis=0)
    fell = ~ok & ~nan
    return dict(subs[0], fell=fell, nan=nan, steps_to_recover=np.where(ok, steps, -1),
                reason=failure_reason(fell, nan, failed))


def blocks(config: SweepConfig, results: dict) -> list[tuple[SweepConfig, dict]]:
    """``(single-direction config, its rows)`` per push direction (one pair without several directions)."""
    if not config.directions:
        return [(config, results)]
    return [(config.for_direction(d), direction_rows(config, results, d)) for d in range(len(config.directions))]


def outcome_counts(res: dict) -> dict:
    """``{fell, solve_failed, nan}``: rollouts per failure ``reason`` (falls without the failed solves)."""
    return {k: int(np.sum(res["reason"] == r)) for k, r in (("fell", "fell"), ("solve_failed", "solve_failed"),
                                                            ("nan", "nan"))}


def recovered(results: dict) -> np.ndarray:
    """Rollouts that neither fell nor went numerically bad."""
    return ~np.asarray(results["fell"], bool) & ~np.asarray(results["nan"], bool)
