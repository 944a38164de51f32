"""Joint-acceleration bounds from the joints' position limits (seed 004 eq. 5: ``vdot_min <= vdot <= vdot_max``).

A joint at ``q`` moving at ``qd`` under a constant acceleration ``qdd`` for a horizon ``h`` reaches
``q + qd h + qdd h^2 / 2``; keeping that inside ``[q_min, q_max]`` gives

    2 (q_min - q - qd h) / h^2  <=  qdd  <=  2 (q_max - q - qd h) / h^2,

clipped to ``+-max_acc`` (a joint far from its limits is not bounded by them) with the lower bound never
above the upper one (a joint already past a limit, or too fast to stop, is driven back as hard as allowed).
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np


@functools.cache
def joint_range_rad() -> np.ndarray:
    """(2, nu) the actuated joints' position limits from the robot's MJCF (``jnt_range``), rad (read-only)."""
    from mjx_coman import load_model

    m = load_model()
    hinge = [j for j in range(m.njnt) if m.jnt_type[j] != 0]  # every joint but the free root
    rng = np.array(m.jnt_range[hinge].T)
    rng.setflags(write=False)
    return rng


def joint_acc_bounds(q, qd, q_min, q_max, horizon_s, max_acc):
    """``(lo, hi)``: the accelerations that keep each joint inside its limits over ``horizon_s`` (module
    docstring), each within ``[-max_acc, max_acc]``; arrays broadcast together."""
    reach = q + qd * horizon_s
    k = 2.0 / (horizon_s * horizon_s)
    hi = jnp.clip(k * (q_max - reach), -max_acc, max_acc)
    lo = jnp.clip(k * (q_min - reach), -max_acc, max_acc)
    return jnp.minimum(lo, hi), hi
