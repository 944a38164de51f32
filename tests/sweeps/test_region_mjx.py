"""sweeps.region_mjx: the safeguarded Newton search and the grid bisection on margins with known roots
(the MJX margin itself runs in the slow test below and in `coman-sweep region --model mjx`)."""

import numpy as np
import pytest

from sweeps import region_mjx

ROOTS = np.array([3.3, 5.7, 0.8, 11.2])
GRID = np.linspace(0.0, 12.0, 25)


def smooth(j):
    """A decreasing, curved margin with its root at ROOTS; the verdict is its sign."""
    m = (ROOTS - j) * (1.0 + 0.2 * np.sin(j))
    dm = -(1.0 + 0.2 * np.sin(j)) + (ROOTS - j) * 0.2 * np.cos(j)
    return j > ROOTS, m, dm


def test_newton_brackets_each_root_within_tol_in_fewer_rollouts_than_bisection():
    tol = 0.25
    calls = []
    newton = region_mjx.newton_search(lambda j: (calls.append(j.copy()), smooth(j))[1], np.zeros(4), np.full(4, 12.0), tol)
    assert np.all(newton.impulse_ns <= ROOTS) and np.all(ROOTS - newton.impulse_ns < tol)
    bisect = region_mjx.grid_bisection(lambda j: smooth(j)[0], GRID, 4)
    np.testing.assert_allclose(bisect.impulse_ns, np.floor(ROOTS / 0.5) * 0.5)  # the last recovered grid impulse
    assert np.all(np.abs(newton.impulse_ns - bisect.impulse_ns) <= 0.5)
    assert newton.rollouts < bisect.rollouts and newton.iterations == len(calls)


def test_a_margin_with_the_wrong_slope_falls_back_to_bisection_and_still_converges():
    def wrong(j):  # the verdict is right but the slope points the wrong way: every Newton step is refused
        fell, m, dm = smooth(j)
        return fell, m, -dm

    found = region_mjx.newton_search(wrong, np.zeros(4), np.full(4, 12.0), 0.1)
    assert np.all(ROOTS - found.impulse_ns < 0.1) and np.all(found.impulse_ns <= ROOTS)
    assert found.iterations <= int(np.ceil(np.log2(12.0 / 0.1))) + 1  # plain bisection of the bracket


@pytest.mark.slow
def test_mjx_newton_agrees_with_bisection_on_a_small_grid(tmp_path):
    """Time projection, forward pushes at two phases of walking step 1, 4-step walks (the jvp walk compiles
    in minutes)."""
    spec = region_mjx.Spec(controller="time-projection", n_steps=4)
    out = region_mjx.run(spec, (0.25, 0.75), np.linspace(0.0, 12.0, 13), ("forward",), tol_ns=0.5)
    assert out["same_within_grid"] == out["lanes"] == 2
    assert out["newton_rollouts"] <= out["bisection_rollouts"] + 2
