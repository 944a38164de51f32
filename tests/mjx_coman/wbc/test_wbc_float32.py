"""The whole-body QP solved in float32 (the simulator's default precision) against proxsuite in float64.

No x64 here: the QPs are built and solved in float32 from MuJoCo-C standing states (double support,
single support, torque limits of 8 N m that bind, and an infeasible 1e-3 N m), and proxsuite solves
the same float32 data in float64.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
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
        # N m: stopped at float32's KKT measure of 1e-5 the torques are within 8.2e-3 N m (0.03 % of the 33 N m
        # stall torque; 2e-3 with a stop at 1e-6, which costs twice the iterations on walking ticks)
        assert np.max(np.abs(tau - tau_r)) < 1e-2, (j, np.max(np.abs(tau - tau_r)))
    assert binding >= 10  # some rows bind (single support, 8 N m): not only easy problems


def test_a_retry_at_fewer_iterations_rescues_a_late_float32_breakdown():
    """A straight-leg QP recorded after a push (float32; stance rows relaxed at 1e4): qpax's interior point
    broke down past 12 iterations on the machine that recorded it. With ``retry_iter=12`` the solve is ok either
    way: the full solve where it succeeds, else the 12-iteration one, which agrees with proxsuite in float64."""
    data = np.load(Path(__file__).parent / "data" / "late_breakdown_qp.npz")
    qp = wbc.QP(**{k: jnp.asarray(data[k]) for k in wbc.QP._fields})
    # one compilation for the three solves (eager, each small op would compile on its own)
    (full_x, full), (short_x, short), (x, info) = jax.jit(lambda qp: (
        wbc.solve_qp(qp, max_iter=20), wbc.solve_qp(qp, max_iter=12), wbc.solve_qp(qp, max_iter=20, retry_iter=12)))(qp)
    assert bool(short.ok) and bool(info.ok)
    np.testing.assert_array_equal(np.asarray(x), np.asarray(full_x if bool(full.ok) else short_x))
    xr = qpsolvers.solve_qp(**wbc.export_qp(qp), solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
    tau, tau_ref = np.asarray(qp.tau_map @ x + qp.tau_offset), np.asarray(qp.tau_map) @ xr + np.asarray(qp.tau_offset)
    assert np.max(np.abs(tau - tau_ref)) < 0.05  # N m (measured 1.2e-3), of a 33 N m stall torque


def test_retry_iter_must_be_below_the_cap():
    data = np.load(Path(__file__).parent / "data" / "late_breakdown_qp.npz")
    qp = wbc.QP(**{k: jnp.asarray(data[k]) for k in wbc.QP._fields})
    for bad in (0, 20, 25, 1.5, True):
        with pytest.raises(ValueError, match="retry_iter"):
            wbc.solve_qp(qp, max_iter=20, retry_iter=bad)
