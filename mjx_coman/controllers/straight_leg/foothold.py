"""Footholds on a known terrain: the planned footsteps' heights, and on stairs whole treads (seed 004, sec. V).

Seed 004 walked Atlas up and down stairs on a given footstep plan; here the controller is told the scenario's
terrain (its ``terrain`` setting, a terrain string as ``--terrain``) and plans on it: each footstep's height is
the terrain's under the foot's centre, and on ``stairs:CM`` a footstep whose sole (``SOLE_HALF_LENGTH_M``
either side of its centre) would straddle a stair edge moves along x off it (:func:`on_treads`), one footstep
after the other from the stance foot: onto the far tread where that step is at most ``max_step_m`` long or the
foot before is already at the edge, else back before it. On the far side of an edge up the heel may overhang
it by ``overhang_m``, before an edge down the toe may (the controller keeps 0: the feet touch at their corners,
and an overhanging heel landed off the edge); the other end of the sole keeps ``margin_m`` from the riser, so a
step across an edge is at least a sole and a margin long (0.21 m on 0.3 m treads). Stairs run along world x
(:mod:`mjx_coman.scenarios.terrain`); the walk is assumed to head along x there.
"""

from __future__ import annotations

import jax.numpy as jnp

from mjx_coman.mjcf import HEEL_BEHIND_M, TOE_AHEAD_M
from mjx_coman.scenarios import terrain as T

SOLE_HALF_LENGTH_M = 0.5 * (TOE_AHEAD_M + HEEL_BEHIND_M)
APPROACH_M = 0.05  # a stance foot this close to its place before an edge steps across it, whatever the length


def stair_edges(terrain: str) -> tuple[tuple[float, float], ...]:
    """``(x, rise)`` of each edge of a ``stairs`` terrain (empty for the others)."""
    t = T.parse_terrain(terrain)
    return T.stair_edges(t) if t.kind == "stairs" else ()


def on_treads(stance_x, centre_x, edges, margin_m: float, overhang_m: float = 0.0, max_step_m: float = 0.2):
    """``centre_x`` (n,), the footsteps after the stance foot at ``stance_x``, each moved off every edge of
    ``edges`` (static ``(x, rise)`` pairs) its sole would straddle: forward (the sole just past the edge) where the
    step from the footstep before is at most ``max_step_m`` or that footstep is within :data:`APPROACH_M` of its
    place before the edge (a landing falls short of its plan by a few cm: the walk must not stall there), else
    back (just before it); each footstep keeps its nominal step from the one before (module docstring)."""
    x = jnp.asarray(centre_x)
    prev = jnp.asarray(stance_x, x.dtype)
    nominal_prev = prev
    out = []
    for k in range(x.shape[0]):
        xk = prev + (x[k] - nominal_prev)
        for e, rise in edges:
            back = SOLE_HALF_LENGTH_M + (margin_m if rise > 0 else -overhang_m)  # centre before the edge
            ahead = SOLE_HALF_LENGTH_M + (-overhang_m if rise > 0 else margin_m)  # centre past it
            straddles = (xk > e - back) & (xk < e + ahead)
            forward = (e + ahead - prev <= max_step_m) | (e - back - prev <= APPROACH_M)
            xk = jnp.where(straddles, jnp.where(forward, e + ahead, e - back), xk)
        out.append(xk)
        nominal_prev, prev = x[k], xk
    return jnp.stack(out)


def footholds(terrain: str, stance_xy, centres_xy, margin_m: float = 0.01, overhang_m: float = 0.0,
              max_step_m: float = 0.2):
    """``(centres (n, 2), heights (n,))``: the footsteps ``centres_xy`` (n, 2) after the stance foot's centre
    ``stance_xy`` (2,) on the terrain (module docstring)."""
    xy = jnp.asarray(centres_xy)
    edges = stair_edges(terrain)
    if edges:
        xy = xy.at[:, 0].set(on_treads(jnp.asarray(stance_xy)[0], xy[:, 0], edges, margin_m, overhang_m, max_step_m))
    z = T.terrain_height_m(terrain, xy[:, 0], xy[:, 1])
    return xy, jnp.broadcast_to(jnp.asarray(z, xy.dtype), xy.shape[:1])
