"""Toe-off criteria of seed 004 (sec. IV-A, Fig. 6), pure JAX in the horizontal plane.

The toe-off support polygon is the convex hull of the leading foot's sole and the trailing foot's toe point:
the union of the sole (two triangles) and the four triangles from the toe point to each sole edge. Toe-off
starts when all hold:

1. the desired and the estimated ICP lie inside that polygon and within ``icp_distance_m`` of the leading
   foot's centre (the foothold);
2. the trailing foot's CoP lies within ``cop_distance_m`` of its toe point, or the foot is nearly unloaded
   (``trailing_light``: rolling it onto its toe changes little; beyond seed 004, whose QP put the trailing
   CoP at the heel through COMAN's transfers);
3. the desired CMP lies within ``cmp_distance_m`` of the polygon.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Criteria(NamedTuple):
    """Each of the four checks (bool arrays) and ``all`` of them."""

    icp_inside: jax.Array
    icp_near_foothold: jax.Array
    cop_near_toe: jax.Array
    cmp_near_polygon: jax.Array

    @property
    def all(self) -> jax.Array:
        return self.icp_inside & self.icp_near_foothold & self.cop_near_toe & self.cmp_near_polygon


def _segment_distance(p, a, b):
    ab = b - a
    u = jnp.clip(jnp.dot(p - a, ab) / jnp.maximum(jnp.dot(ab, ab), 1e-12), 0.0, 1.0)
    return jnp.linalg.norm(p - (a + u * ab))


def triangle_distance(p, tri) -> jax.Array:
    """Distance from ``p`` (2,) to the triangle ``tri`` (3, 2): 0 inside or on it."""
    cross = lambda u, v: u[0] * v[1] - u[1] * v[0]  # noqa: E731
    s = jnp.stack([cross(tri[(k + 1) % 3] - tri[k], p - tri[k]) for k in range(3)])
    inside = jnp.all(s >= 0) | jnp.all(s <= 0)
    edge = jnp.min(jnp.stack([_segment_distance(p, tri[k], tri[(k + 1) % 3]) for k in range(3)]))
    return jnp.where(inside, 0.0, edge)


def polygon_pieces(sole_corners, toe) -> jax.Array:
    """(6, 3, 2) triangles whose union is the hull of the sole ``sole_corners`` (4, 2), in order around it,
    and the point ``toe`` (2,)."""
    c = sole_corners
    sole = [jnp.stack([c[0], c[1], c[2]]), jnp.stack([c[0], c[2], c[3]])]
    fans = [jnp.stack([toe, c[k], c[(k + 1) % 4]]) for k in range(4)]
    return jnp.stack(sole + fans)


def polygon_distance(p, pieces) -> jax.Array:
    """Distance from ``p`` to the union of ``pieces`` (n, 3, 2)."""
    return jnp.min(jax.vmap(lambda t: triangle_distance(p, t))(pieces))


def criteria(icp_des, icp_est, cmp_des, trailing_cop, trailing_light, toe, leading_corners, leading_centre, *,
             icp_distance_m, cop_distance_m, cmp_distance_m) -> Criteria:
    """The four checks of the module docstring (all positions world x-y, (2,); corners (4, 2) in order;
    ``trailing_light`` a bool)."""
    pieces = polygon_pieces(leading_corners, toe)
    inside = lambda p: polygon_distance(p, pieces) <= 0.0  # noqa: E731
    near = lambda p: jnp.linalg.norm(p - leading_centre) <= icp_distance_m  # noqa: E731
    return Criteria(inside(icp_des) & inside(icp_est), near(icp_des) & near(icp_est),
                    (jnp.linalg.norm(trailing_cop - toe) <= cop_distance_m) | trailing_light,
                    polygon_distance(cmp_des, pieces) <= cmp_distance_m)
