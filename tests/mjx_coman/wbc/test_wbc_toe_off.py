"""Toe-off in the whole-body QP (seed 004, sec. IV; :mod:`mjx_coman.wbc.contacts`), float64, against MuJoCo's
terms and proxsuite: the right foot of double-support standing states rolls onto its toe while a soft task
asks its sole to pitch heel-up. One vmapped, jitted solve covers every case (flat and toe-off rows)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import qpsolvers

import mjx_coman
from mjx_coman import wbc
from mjx_coman.env import standing_posture
from mjx_coman.wbc import contacts
from mjx_coman.wbc import reference as ref
from mjx_coman.wbc.plant import N_BASE

N_STATES = 3
MU = 0.7
TAU_LIMIT_NM = 33.0
SLACK_W = 1e4
PITCH_ACC = 4.0  # rad/s^2 asked of the right sole, heel up
HEEL = (2, 3)


@pytest.fixture(scope="module", autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


def _one(plant, qpos, qvel, toe):
    mask = jnp.ones(2, qvel.dtype)
    com_des = jnp.concatenate([jnp.mean(plant.contact_pos[:, :, :2], axis=(0, 1)), plant.com[2:]])
    tasks = ref.standing_tasks(plant, qpos, qvel, jnp.asarray(standing_posture()[0]), com_des, mask)
    # the right sole's pitch acceleration about its own y axis, heel up (negative about y is toe down)
    pitch_row = plant.sole_rot[0][:, 1] @ plant.sole_jac[0, 3:]
    pitch_bias = plant.sole_rot[0][:, 1] @ plant.sole_bias_acc[0, 3:]
    tasks.append(wbc.motion_task(pitch_row[None], pitch_bias[None], -PITCH_ACC, 10.0))
    lim = jnp.full(23, TAU_LIMIT_NM)
    qp = wbc.build_qp(plant, tasks, mask, -lim, lim, friction_coeff=MU, contact_slack_weight=SLACK_W,
                      toe_off=jnp.stack([toe, jnp.zeros_like(toe)]))
    x, info = wbc.solve_qp(qp, max_iter=60)
    return qp, wbc.solution(qp, x, info, wbc.fallback_torque(plant, -lim, lim))


@pytest.fixture(scope="module")
def solved():
    """``(plants, qp, sol, toe)``: each state flat (toe 0) and on the right toe (toe 1), one compile."""
    states = ref.standing_plants(mjx_coman.load_model(), N_STATES, seed=5)
    rows = [(s, t) for s in states for t in (0.0, 1.0)]
    plants = ref.stack_plants([s[2] for s, _ in rows])
    qpos = np.stack([s[0] for s, _ in rows])
    qvel = np.stack([s[1] for s, _ in rows])
    toe = np.array([t for _, t in rows])
    qp, sol = jax.jit(jax.vmap(_one))(plants, qpos, qvel, toe)
    return [s[2] for s, _ in rows], jax.tree_util.tree_map(np.asarray, qp), jax.tree_util.tree_map(np.asarray, sol), toe


def _take(tree, j):
    return jax.tree_util.tree_map(lambda a: a[j], tree)


def _pitch_acc(p, qdd):
    return p.sole_rot[0][:, 1] @ (p.sole_jac[0, 3:] @ qdd + p.sole_bias_acc[0, 3:])


def test_toe_off_frees_the_pitch_holds_the_toe_point_and_loads_only_it(solved):
    plants, _, sol, toe = solved
    for j, p in enumerate(plants):
        s = _take(sol, j)
        assert bool(s.info.ok), (j, s.info)
        # MuJoCo's dynamics with the returned forces: exact, slack or not
        gen = np.concatenate([np.zeros(N_BASE), s.tau]) + p.contact_jac.reshape(24, -1).T @ s.forces.reshape(24)
        assert np.max(np.abs(p.mass @ s.qdd + p.bias - p.passive - gen)) < 1e-6
        corner_acc = np.einsum("fcin,n->fci", p.contact_jac, s.qdd) + p.contact_bias_acc
        toe_acc = corner_acc[0, list(contacts.TOE_CORNERS)].mean(0)
        ang = p.sole_rot[0].T @ (p.sole_jac[0, 3:] @ s.qdd + p.sole_bias_acc[0, 3:])
        if toe[j]:
            assert np.all(s.forces[0, HEEL, :] == 0.0)  # the heel's forces are cut
            np.testing.assert_array_equal(*s.forces[0, list(contacts.TOE_CORNERS)])  # one force at the toe point
            assert s.forces[0, list(contacts.TOE_CORNERS), 2].sum() > 20.0  # the toe carries load
            assert abs(_pitch_acc(p, s.qdd) + PITCH_ACC) < 0.5, _pitch_acc(p, s.qdd)  # the pitch follows its task
            assert np.max(np.abs(toe_acc)) < 0.02 and abs(ang[0]) < 0.02 and abs(ang[2]) < 0.02, (toe_acc, ang)
        else:  # flat: the same task cannot pitch the foot, and every corner stays put
            assert abs(_pitch_acc(p, s.qdd)) < 0.02
            assert np.max(np.abs(corner_acc[0])) < 0.02
        assert np.max(np.abs(corner_acc[1])) < 0.02  # the left foot stays flat


def test_toe_off_agrees_with_proxsuite_and_keeps_the_friction_cones(solved):
    plants, qp, sol, toe = solved
    for j in np.flatnonzero(toe):
        one = _take(qp, j)
        x = qpsolvers.solve_qp(**wbc.export_qp(one), solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
        assert x is not None
        assert np.max(np.abs(sol.tau[j] - (one.tau_map @ x + one.tau_offset))) < 1e-5
        assert np.max(np.abs(sol.forces[j].reshape(-1) - one.force_map @ x)) < 1e-5
        local = sol.forces[j, 0] @ plants[j].sole_rot[0]
        assert np.all(local[:, 2] >= -1e-6)
        assert np.all(np.linalg.norm(local[:, :2], axis=1) <= MU * local[:, 2] + 1e-6)


def test_toe_off_without_stance_slack_is_refused():
    p = ref.standing_plants(mjx_coman.load_model(), 1, seed=5)[0][2]
    lim = np.full(23, 33.0)
    with pytest.raises(ValueError, match="toe_off needs contact_slack_weight"):
        wbc.build_qp(p, [wbc.qdd_regularization(1.0, 29)], (1, 1), -lim, lim, toe_off=np.array([1.0, 0.0]))


def test_a_lifted_foots_toe_off_is_ignored():
    """A toe-off flag on a lifted foot would cut its heel forces under its zero-wrench rows, leaving them without
    rank (the KKT matrix singular: qpax's first factorization non-finite, seen in batched bent-knee walks): the
    QP is the one without the flag, and it solves."""
    p = ref.standing_plants(mjx_coman.load_model(), 1, seed=5)[0][2]
    lim = np.full(23, TAU_LIMIT_NM)
    mask = np.array([0.0, 1.0])  # right foot lifted
    tasks = [wbc.qdd_regularization(1.0, 29), wbc.force_regularization(1e-4)]
    build = jax.jit(lambda toe: wbc.build_qp(p, tasks, mask, -lim, lim, toe_off=toe, friction_coeff=MU,
                                             contact_slack_weight=SLACK_W))  # one compile, not op by op
    flagged, plain = build(np.array([1.0, 0.0])), build(np.array([0.0, 0.0]))
    for a, b in zip(flagged, plain):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.linalg.matrix_rank(np.asarray(flagged.A)) == flagged.A.shape[0]
    assert bool(jax.jit(lambda qp: wbc.solve_qp(qp, max_iter=40)[1].ok)(flagged))
