"""Toe-off criteria (seed 004, Fig. 6): the hull of a sole and a toe point against a brute-force hull test."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.straight_leg import toe_off as to

SOLE = np.array([[0.33, 0.13], [0.33, 0.03], [0.13, 0.03], [0.13, 0.13]])  # leading foot, in order around it
TOE = np.array([0.13, -0.08])  # trailing toe point, behind and to the right
CENTRE = SOLE.mean(0)


def _in_hull(p, pts):
    """Inside the convex hull of ``pts`` iff no separating direction (checked over 3600 directions)."""
    ang = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    return bool(np.all(d @ p <= (pts @ d.T).max(0) + 1e-9))


def test_the_pieces_cover_exactly_the_hull_of_sole_and_toe():
    pieces = to.polygon_pieces(jnp.asarray(SOLE), jnp.asarray(TOE))
    dist = jax.jit(jax.vmap(lambda p: to.polygon_distance(p, pieces)))
    rng = np.random.default_rng(0)
    pts = rng.uniform([0.0, -0.15], [0.45, 0.2], size=(400, 2))
    d = np.asarray(dist(jnp.asarray(pts)))
    hull = np.array([_in_hull(p, np.vstack([SOLE, TOE])) for p in pts])
    near_edge = np.abs(d) < 1e-6
    assert np.all((d == 0) == hull | near_edge) and hull.sum() > 50 and (~hull).sum() > 50
    # outside: the distance to the hull's boundary (a point due right of the sole's right edge)
    assert float(to.polygon_distance(jnp.array([0.40, 0.08]), pieces)) == pytest.approx(0.07, abs=1e-6)


def _check(icp_des=None, icp_est=None, cmp_des=None, cop=None, light=False):
    mid = 0.5 * (TOE + CENTRE)
    pick = lambda v, default: jnp.asarray(default if v is None else v)  # noqa: E731
    return to.criteria(pick(icp_des, mid), pick(icp_est, mid), pick(cmp_des, mid), pick(cop, TOE),
                       jnp.asarray(light), jnp.asarray(TOE), jnp.asarray(SOLE), jnp.asarray(CENTRE),
                       icp_distance_m=0.15, cop_distance_m=0.03, cmp_distance_m=0.02)


def test_each_criterion_can_veto_toe_off():
    assert bool(_check().all)
    c = _check(icp_est=np.array([0.05, 0.0]))  # behind the toe: outside the polygon
    assert not bool(c.icp_inside) and not bool(c.all)
    c = _check(icp_des=np.array([0.14, -0.06]))  # inside near the toe, 0.19 m from the foothold
    assert bool(c.icp_inside) and not bool(c.icp_near_foothold) and not bool(c.all)
    c = _check(cop=TOE - np.array([0.05, 0.0]))  # the trailing CoP still under the heel
    assert not bool(c.cop_near_toe) and not bool(c.all)
    assert bool(_check(cop=TOE - np.array([0.05, 0.0]), light=True).all)  # unless the foot is nearly unloaded
    c = _check(cmp_des=np.array([0.40, 0.08]))  # 7 cm past the sole
    assert not bool(c.cmp_near_polygon) and not bool(c.all)
    assert bool(_check(cmp_des=np.array([0.34, 0.08])).cmp_near_polygon)  # 1 cm past: near enough
