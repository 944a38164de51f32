"""Footholds on a known terrain: heights under the footsteps and whole treads on stairs, up and down."""

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.straight_leg import foothold as fh
from mjx_coman.scenarios import terrain as T


def _walk(terrain, step_m, n, overhang, max_step=0.2, start=0.0):
    """Footholds of ``n`` nominal steps of ``step_m`` from a stance centre at ``start``: (n,) centres."""
    x = start + step_m * np.arange(1, n + 1)
    xy, z = fh.footholds(terrain, jnp.asarray([start, 0.05]), np.stack([x, 0.05 * np.ones_like(x)], 1),
                         margin_m=0.01, overhang_m=overhang, max_step_m=max_step)
    return np.asarray(xy[:, 0]), np.asarray(z)


@pytest.mark.parametrize("terrain", ["stairs:6", "stairs:-6"])
@pytest.mark.parametrize("overhang", [0.0, 0.05])
@pytest.mark.parametrize("step_m", [0.03, 0.06, 0.11])
def test_no_planned_sole_straddles_an_edge_and_every_step_is_short_and_forward(terrain, overhang, step_m):
    xs, z = _walk(terrain, step_m, int(2.3 / step_m), overhang)  # within the 2 m landing
    up = T.parse_terrain(terrain).height_m > 0
    # what must share a tread: the heel may overhang an edge up (behind it), the toe an edge down (ahead of it)
    heel = xs - fh.SOLE_HALF_LENGTH_M + (overhang if up else -0.01)
    toe = xs + fh.SOLE_HALF_LENGTH_M + (0.01 if up else -overhang)
    zs = [np.asarray(T.terrain_height_m(terrain, p, 0.05)) for p in (heel + 1e-6, toe - 1e-6)]
    np.testing.assert_allclose(zs[0], zs[1])
    np.testing.assert_allclose(z, np.asarray(T.terrain_height_m(terrain, xs, 0.05)), atol=1e-7)
    steps = np.diff(np.concatenate([[0.0], xs]))
    crossing = 2 * fh.SOLE_HALF_LENGTH_M + 0.01 - overhang  # the shortest step across an edge from just before it
    assert np.all(steps >= -1e-9) and np.all(steps <= max(0.2, crossing + fh.APPROACH_M) + 1e-6)
    assert xs[-1] > fh.stair_edges(terrain)[-1][0]  # past the last edge: never stuck before one
    tops = np.unique(np.round(z, 6))
    assert tops.size == T.STAIR_STEPS + 1  # a foothold on every tread


def test_far_from_an_edge_the_footsteps_keep_their_nominal_places():
    xs, _ = _walk("stairs:6", 0.05, 3, 0.05, start=-0.3)
    np.testing.assert_allclose(xs, [-0.25, -0.2, -0.15], atol=1e-7)


def test_a_step_past_max_step_goes_back_before_the_edge():
    e = fh.stair_edges("stairs:6")[0][0]
    start = e - 0.2  # the sole on the near side, 9 cm before its place at the edge; forward would be 0.25 m
    xs, _ = _walk("stairs:6", 0.1, 1, 0.05, start=start)
    assert xs[0] == pytest.approx(e - fh.SOLE_HALF_LENGTH_M - 0.01)
    xs, _ = _walk("stairs:6", 0.1, 1, 0.05, max_step=0.3, start=start)
    assert xs[0] == pytest.approx(e + fh.SOLE_HALF_LENGTH_M - 0.05)


def test_flat_and_rough_keep_the_footsteps_and_read_the_heights():
    xy = jnp.asarray([[0.1, 0.0], [1.37, -0.62]])
    same, z = fh.footholds("flat", jnp.zeros(2), xy)
    np.testing.assert_array_equal(same, xy) and np.testing.assert_array_equal(z, 0.0)
    _, z = fh.footholds("rough:5", jnp.zeros(2), xy)
    assert float(z[1]) == pytest.approx(float(T.terrain_height_m("rough:5", 1.37, -0.62)))


def test_a_stance_foot_that_fell_short_of_the_edge_still_steps_across():
    e = fh.stair_edges("stairs:6")[0][0]
    start = e - fh.SOLE_HALF_LENGTH_M - 0.01 - 0.03  # landed 3 cm short of its place before the edge
    xs, _ = _walk("stairs:6", 0.06, 1, 0.0, max_step=0.2, start=start)
    assert xs[0] == pytest.approx(e + fh.SOLE_HALF_LENGTH_M)  # a 0.24 m step rather than a 3 cm one, for ever
