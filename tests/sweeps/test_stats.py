"""sweeps.stats against closed forms and reference values."""

import math

import numpy as np
import pytest

from sweeps.stats import bootstrap_interval, mcnemar_exact, paired, wilson_interval


def test_wilson_interval_matches_its_closed_form_and_stays_in_0_1():
    lo, hi = wilson_interval(81, 263)  # Wilson (1927) example as tabulated in Newcombe (1998): 0.2553-0.3662
    assert lo == pytest.approx(0.2553, abs=1e-4) and hi == pytest.approx(0.3662, abs=1e-4)
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == pytest.approx(1.0)
    assert wilson_interval(0, 10)[1] == pytest.approx(3.8415 / 13.8415, abs=1e-4)  # z^2 / (n + z^2) at p = 0
    assert wilson_interval(0, 0) is None


def test_mcnemar_exact_is_the_two_sided_binomial_tail():
    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(5, 5) == 1.0
    assert mcnemar_exact(0, 6) == pytest.approx(2 / 64)
    assert mcnemar_exact(2, 10) == pytest.approx(2 * sum(math.comb(12, i) for i in range(3)) / 4096)
    assert mcnemar_exact(10, 2) == mcnemar_exact(2, 10)
    rng = np.random.default_rng(0)  # under the null, p < 0.05 in at most about 5 % of draws (exact: fewer)
    draws = rng.binomial(30, 0.5, 4000)
    assert np.mean([mcnemar_exact(int(k), 30 - int(k)) < 0.05 for k in draws]) <= 0.05


def test_paired_counts_and_verdict():
    a = np.array([1, 1, 0, 0] + [0] * 12, bool)
    b = np.array([1, 0, 1, 0] + [1] * 12, bool)
    r = paired(a, b, names=("seed", "tuned"))
    assert (r["pairs"], r["both"], r["seed_only"], r["tuned_only"], r["neither"]) == (16, 1, 1, 13, 1)
    assert r["tuned_rate"] == 14 / 16 and r["mcnemar_p"] == pytest.approx(mcnemar_exact(1, 13))
    assert r["verdict"].startswith("tuned better than seed")
    assert paired(a, a, names=("seed", "tuned"))["verdict"].startswith("no significant difference")
    with pytest.raises(ValueError, match="shape"):
        paired(a, b[:3])


def test_bootstrap_interval_brackets_the_mean_and_shrinks_with_more_samples():
    rng = np.random.default_rng(1)
    small, large = rng.normal(5.0, 1.0, 4), rng.normal(5.0, 1.0, 64)
    lo, hi = bootstrap_interval(small)
    assert lo <= small.mean() <= hi
    lo2, hi2 = bootstrap_interval(large)
    assert lo2 <= large.mean() <= hi2 and hi2 - lo2 < hi - lo
    assert bootstrap_interval([3.0]) is None and bootstrap_interval([2.0, 2.0]) == [2.0, 2.0]
