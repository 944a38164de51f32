"""Intervals and paired tests for recovery rates (plain NumPy; no SciPy).

* :func:`wilson_interval`: the Wilson score interval of a binomial proportion.
* :func:`mcnemar_exact`: McNemar's exact test of paired successes: under the null hypothesis the discordant
  pairs split as Binomial(b + c, 1/2); two-sided p = min(1, 2 P[X <= min(b, c)]).
* :func:`bootstrap_interval`: the percentile bootstrap interval of a mean.
"""

from __future__ import annotations

import math

import numpy as np

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile
BOOTSTRAP_DRAWS = 2000


def wilson_interval(successes: int, n: int, z: float = Z95) -> list[float] | None:
    """95 % Wilson score interval of ``successes / n`` (``None`` for ``n = 0``)."""
    if n == 0:
        return None
    p = successes / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return [max(0.0, mid - half), min(1.0, mid + half)]


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """Two-sided p-value of McNemar's exact test from the discordant pairs (successes of A alone, of B alone)."""
    n = a_only + b_only
    if n == 0:
        return 1.0
    k = min(a_only, b_only)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def paired(a_ok, b_ok, names=("a", "b"), alpha: float = 0.05) -> dict:
    """Paired comparison of two success arrays over the same trials: counts, rates with Wilson intervals,
    McNemar's exact p-value and a one-line verdict at level ``alpha``."""
    a, b = np.asarray(a_ok, bool), np.asarray(b_ok, bool)
    if a.shape != b.shape:
        raise ValueError(f"paired arrays differ in shape: {a.shape} and {b.shape}")
    na, nb = names
    a_only, b_only = int(np.sum(a & ~b)), int(np.sum(~a & b))
    p = mcnemar_exact(a_only, b_only)
    if p < alpha:
        verdict = f"{nb} {'better' if b_only > a_only else 'worse'} than {na} (McNemar p = {p:.3g} < {alpha:g})"
    else:
        verdict = f"no significant difference between {na} and {nb} (McNemar p = {p:.3g})"
    n = int(a.size)
    return {"pairs": n, "both": int(np.sum(a & b)), f"{na}_only": a_only, f"{nb}_only": b_only,
            "neither": int(np.sum(~a & ~b)),
            f"{na}_rate": float(a.mean()) if n else None, f"{na}_interval": wilson_interval(int(a.sum()), n),
            f"{nb}_rate": float(b.mean()) if n else None, f"{nb}_interval": wilson_interval(int(b.sum()), n),
            "mcnemar_p": p, "verdict": verdict}


def bootstrap_interval(values, draws: int = BOOTSTRAP_DRAWS, seed: int = 0) -> list[float] | None:
    """95 % percentile bootstrap interval of the mean of ``values`` (``None`` for fewer than two)."""
    v = np.asarray(values, float)
    if v.size < 2:
        return None
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, v.size, size=(draws, v.size))].mean(axis=1)
    return [float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))]
