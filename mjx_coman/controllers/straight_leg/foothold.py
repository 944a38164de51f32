"""Footholds on a known terrain: the planned footsteps' heights, and on stairs whole treads (seed 004, sec. V).

Seed 004 walked Atlas up and down stairs on a given footstep plan; here the controller is told the scenario's
terrain (its ``terrain`` setting, a terrain string as ``--terrain``) and plans on it: each footstep's height is
the terrain's under the foot's centre, and on ``stairs:CM`` a footstep whose sole (``SOLE_HALF_LENGTH_M``
either side of its centre) would straddle a stair edge moves along x off it (:func:`on_treads`): between
treads a whole sole and a margin (0.3 m treads under a 0.2 m sole) took 0.22 m steps, too long for COMAN,
so the heel may overhang the edge below by ``heel_overhang_m``. Stairs run along world x
(:mod:`mjx_coman.scenarios.terrain`); the walk is assumed to head along x there.
"""

from __future__ import annotations

import jax.numpy as jnp

from mjx_coman.mjcf import HEEL_BEHIND_M, TOE_AHEAD_M
from mjx_coman.scenarios import terrain as T

SOLE_HALF_LENGTH_M = 0.5 * (TOE_AHEAD_M + HEEL_BEHIND_M)


def stair_edges_m(terrain: str) -> tuple[float, ...]:
    """x of each riser of a ``stairs`` terrain (empty for the others)."""
    t = T.parse_terrain(terrain)
    if t.kind != "stairs":
        return ()
    return tuple(a for a, _, _ in T.stair_boxes(t))


def on_treads(centre_x, edges: tuple[float, ...], margin_m: float, heel_overhang_m: float = 0.0):
    """``centre_x`` (any shape) moved off every edge its sole would straddle (static ``edges``): back to the
    sole's half-length plus ``margin_m`` (``back``) before the edge (the toe clear of the riser), or forward
    onto the upper tread with the heel ``heel_overhang_m`` past the edge (``ahead``); forward from ``back / 2``
    before the edge, so that a short step is not moved back for ever."""
    back = SOLE_HALF_LENGTH_M + margin_m
    ahead = SOLE_HALF_LENGTH_M - heel_overhang_m
    x = jnp.asarray(centre_x)
    for e in edges:
        straddles = (x > e - back) & (x < e + ahead)
        x = jnp.where(straddles, jnp.where(x >= e - 0.5 * back, e + ahead, e - back), x)
    return x


def footholds(terrain: str, centres_xy, margin_m: float = 0.01, heel_overhang_m: float = 0.0):
    """``(centres (n, 2), heights (n,))``: the footsteps ``centres_xy`` (n, 2) on the terrain (module docstring)."""
    xy = jnp.asarray(centres_xy)
    edges = stair_edges_m(terrain)
    if edges:
        xy = xy.at[:, 0].set(on_treads(xy[:, 0], edges, margin_m, heel_overhang_m))
    z = T.terrain_height_m(terrain, xy[:, 0], xy[:, 1])
    return xy, jnp.broadcast_to(jnp.asarray(z, xy.dtype), xy.shape[:1])
