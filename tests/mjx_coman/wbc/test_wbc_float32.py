"""The whole-body QP solved in float32 (the simulator's default precision) against proxsuite in float64.

No x64 here: the QPs are built and solved in float32 from MuJoCo-C standing states (double support,
single support, torque limits of 8 N m that bind, and an infeasible 1e-3 N m), and proxsuite solves
the same float32 data in float64.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import qpsolvers

import mjx_coman
from mjx_coman import wbc
from mjx_coman.env import standing_posture
from mjx_coman.wbc import reference as ref


def test_float32_solves_agree_with_float64_proxsuite():
    model = mjx_coman.load_model()
    states = ref.standing_plants(model, 4, seed=21)
    rows = [(s, (1.0, 1.0), 33.0) for s in states] + [(states[0], (1.0, 0.0), 33.0), (states[1], (0.0, 1.0), 33.0),
                                                       (states[2], (1.0, 1.0), 8.0), (states[3], (1.0, 1.0), 1e-3)]
    q_ref = standing_posture()[0]

    def com_des(plant, mask):
        stance = plant.contact_pos[np.asarray(mask) > 0.5].reshape(-1, 3)
        return np.array([*stance[:, :2].mean(0), plant.com[2]])

    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    plant = jax.tree_util.tree_map(f32, ref.stack_plants([s[2] for s, _, _ in rows]))
    args = (plant, f32([s[0] for s, _, _ in rows]), f32([s[1] for s, _, _ in rows]),
            f32([com_des(s[2], m) for s, m, _ in rows]), f32([m for _, m, _ in rows]), f32([lim for _, _, lim in rows]))

    def one(p, qpos, qvel, cd, mask, lim):
        tasks = ref.standing_tasks(p, qpos, qvel, q_ref, cd, mask)
        qp = wbc.build_qp(p, tasks, mask, -lim * jnp.ones(23, jnp.float32), lim * jnp.ones(23, jnp.float32))
        return qp, wbc.solve_qp(qp)

    qp, (x, info) = jax.tree_util.tree_map(np.asarray, jax.jit(jax.vmap(one))(*args))
    assert x.dtype == np.float32
    np.testing.assert_array_equal(info.ok, [True] * 7 + [False])
    assert np.isfinite(x).all()
    binding = 0
    for j in range(7):
        one_qp = jax.tree_util.tree_map(lambda a: a[j], qp)
        e = wbc.export_qp(one_qp)
        xr = qpsolvers.solve_qp(**e, solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
        binding += int(np.sum(e["h"] - e["G"] @ xr < 1e-7))
        assert np.max(np.abs(x[j] - xr)) < 2e-4, (j, np.max(np.abs(x[j] - xr)))
        tau, tau_r = one_qp.tau_map @ x[j] + one_qp.tau_offset, one_qp.tau_map @ xr + one_qp.tau_offset
        assert np.max(np.abs(tau - tau_r)) < 2e-3, (j, np.max(np.abs(tau - tau_r)))  # N m
    assert binding >= 10  # some rows bind (single support, 8 N m): not only easy problems
