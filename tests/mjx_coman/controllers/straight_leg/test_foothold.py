"""Footholds on a known terrain: heights under the footsteps and whole treads on stairs."""

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.straight_leg import foothold as fh
from mjx_coman.scenarios import terrain as T


@pytest.mark.parametrize("overhang", [0.0, 0.05])
def test_no_planned_sole_straddles_a_riser_and_heights_are_the_treads(overhang):
    x = np.linspace(0.0, 2.5, 501)
    xy, z = fh.footholds("stairs:6", np.stack([x, 0.05 * np.ones_like(x)], 1), margin_m=0.01, heel_overhang_m=overhang)
    xs = np.asarray(xy[:, 0])
    heel, toe = xs - fh.SOLE_HALF_LENGTH_M + overhang, xs + fh.SOLE_HALF_LENGTH_M + 0.01  # what must share a tread
    zs = [np.asarray(T.terrain_height_m("stairs:6", p, 0.05)) for p in (heel + 1e-6, toe - 1e-6)]
    np.testing.assert_allclose(zs[0], zs[1])  # the toe (and a margin) clear of the riser, the heel on the tread
    np.testing.assert_allclose(z, np.asarray(T.terrain_height_m("stairs:6", xs, 0.05)), atol=1e-7)
    edges = np.array(fh.stair_edges_m("stairs:6"))
    gap = np.abs(x[:, None] - edges[None]).min(1)
    moved = np.abs(xs - x)
    assert moved.max() <= 0.22 + 1e-6 and np.all(moved[gap > 0.2] < 1e-6)


def test_a_short_step_toward_a_riser_crosses_it():
    """From a sole just behind the first riser, 6 cm steps reach the tread beyond (never stuck before it)."""
    e = fh.stair_edges_m("stairs:6")[0]
    x = float(fh.on_treads(e - 0.12, (e,), 0.01))
    for _ in range(3):
        x = float(fh.on_treads(x + 0.06, (e,), 0.01))
    assert x > e


def test_flat_and_rough_keep_the_footsteps_and_read_the_heights():
    xy = jnp.asarray([[0.1, 0.0], [1.37, -0.62]])
    same, z = fh.footholds("flat", xy)
    np.testing.assert_array_equal(same, xy) and np.testing.assert_array_equal(z, 0.0)
    _, z = fh.footholds("rough:5", xy)
    assert float(z[1]) == pytest.approx(float(T.terrain_height_m("rough:5", 1.37, -0.62)))
