"""The whole-body QP on random standing states of COMAN, float64, against MuJoCo's dynamics and proxsuite.

Plants come from MuJoCo's C functions (:mod:`mjx_coman.wbc.reference`); the checks use those arrays, not
the QP's own rows: ``M qdd + h - passive = [0; tau] + J_c^T f`` for the returned qdd, tau and forces,
stance corners not accelerating, friction cones, unilateral forces and torque limits. One vmapped,
jitted solve per variant (full body, fixed upper body) covers every case; the gradient check reuses the
same batch for its central differences.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import qpsolvers

import mjx_coman
from mjx_coman import wbc
from mjx_coman.env import standing_posture
from mjx_coman.wbc import reference as ref
from mjx_coman.wbc.plant import N_BASE, LEG_JOINTS

N_DOUBLE = 5
MU = 0.7
TAU_LIMIT_NM = 33.0
GRAD_W, GRAD_H = 10.0, 1e-3
UPPER_KP, UPPER_KD = 100.0, 20.0
SLACK_W = 1e4
SLACK_MAX_ITER = 60
SLACK_TOL, TAU_TOL_NM = 10.0 / SLACK_W, 100.0 / SLACK_W  # measured 1.3e-4 m/s^2, 2.3e-4 N m


@pytest.fixture(scope="module", autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def cases():
    """Rows: 5 double-support states; 2 of them on the left foot only; one with 1e-3 N m torque limits
    (infeasible); state 0 with the CoM weight at GRAD_W +- GRAD_H (central differences)."""
    model = mjx_coman.load_model()
    states = ref.standing_plants(model, N_DOUBLE, seed=3)
    rows = []
    for i, (qpos, qvel, plant) in enumerate(states):
        rows.append(dict(i=i, mask=(1.0, 1.0), lim=TAU_LIMIT_NM, w=GRAD_W, kind="double"))
    rows += [dict(i=i, mask=(0.0, 1.0), lim=TAU_LIMIT_NM, w=GRAD_W, kind="single") for i in (1, 2)]
    rows.append(dict(i=3, mask=(1.0, 1.0), lim=1e-3, w=GRAD_W, kind="infeasible"))
    rows += [dict(i=0, mask=(1.0, 1.0), lim=TAU_LIMIT_NM, w=GRAD_W + s, kind="fd") for s in (GRAD_H, -GRAD_H)]
    for r in rows:
        qpos, qvel, plant = states[r["i"]]
        r.update(qpos=qpos, qvel=qvel, plant=plant, com_des=_com_target(plant, r["mask"]))
    return rows


def _com_target(plant, mask):
    """Above the centre of the stance corners, at the current height."""
    stance = plant.contact_pos[np.asarray(mask) > 0.5].reshape(-1, 3)
    return np.array([*stance[:, :2].mean(0), plant.com[2]])


def _inputs(rows):
    stack = lambda k: np.stack([r[k] for r in rows])  # noqa: E731
    return (ref.stack_plants([r["plant"] for r in rows]), stack("qpos"), stack("qvel"), stack("com_des"),
            np.stack([np.asarray(r["mask"]) for r in rows]), np.array([r["lim"] for r in rows]),
            np.array([r["w"] for r in rows]))


Q_REF = standing_posture()[0]


def _one(plant, qpos, qvel, com_des, mask, lim, w, fixed: bool, slack_weight=None, max_iter=None):
    tasks = ref.standing_tasks(plant, qpos, qvel, Q_REF, com_des, mask, com_weight=w)
    kw = {}
    if fixed:
        kw = dict(fixed_upper_body=True,
                  upper_acc=wbc.joint_pd(Q_REF[LEG_JOINTS:], qpos[7 + LEG_JOINTS:], qvel[N_BASE + LEG_JOINTS:],
                                         UPPER_KP, UPPER_KD))
    tau_lim = jnp.full(23, 1.0) * lim
    qp = wbc.build_qp(plant, tasks, mask, -tau_lim, tau_lim, friction_coeff=MU, contact_slack_weight=slack_weight, **kw)
    x, info = wbc.solve_qp(qp, max_iter=max_iter)
    return qp, wbc.solution(qp, x, info, wbc.fallback_torque(plant, -tau_lim, tau_lim))


@pytest.fixture(scope="module")
def solved(cases):
    """``{False: (qp, sol), True: (qp, sol)}`` (full body, fixed upper body) as NumPy, one compile each."""
    out = {}
    for fixed in (False, True):
        f = jax.jit(jax.vmap(lambda *a, fixed=fixed: _one(*a, fixed=fixed)))
        out[fixed] = jax.tree_util.tree_map(np.asarray, f(*_inputs(cases)))
    return out


@pytest.fixture(scope="module")
def relaxed(cases):
    """(qp, sol) with the stance rows relaxed at weight SLACK_W, full body, one compile; the infeasible
    case's relaxed solve takes ~40 interior-point iterations, more than the float64 default."""
    f = jax.jit(jax.vmap(lambda *a: _one(*a, fixed=False, slack_weight=SLACK_W, max_iter=SLACK_MAX_ITER)))
    return jax.tree_util.tree_map(np.asarray, f(*_inputs(cases)))


def _rows_of(cases, *kinds):
    return [j for j, r in enumerate(cases) if r["kind"] in kinds]


def _take(tree, j):
    return jax.tree_util.tree_map(lambda a: a[j], tree)


@pytest.mark.parametrize("fixed", [False, True])
def test_solutions_satisfy_mujoco_dynamics_and_contacts(cases, solved, fixed):
    _, sol = solved[fixed]
    for j in _rows_of(cases, "double", "single"):
        p, s, mask = cases[j]["plant"], _take(sol, j), np.asarray(cases[j]["mask"])
        assert bool(s.info.ok), (j, s.info)
        jc = p.contact_jac.reshape(24, -1)
        gen_force = np.concatenate([np.zeros(N_BASE), s.tau]) + jc.T @ s.forces.reshape(24)
        resid = p.mass @ s.qdd + p.bias - p.passive - gen_force
        assert np.max(np.abs(resid)) < 1e-6, (j, np.max(np.abs(resid)))
        corner_acc = np.einsum("fcin,n->fci", p.contact_jac, s.qdd) + p.contact_bias_acc
        assert np.max(np.abs(corner_acc[mask > 0.5])) < 1e-6, (j, corner_acc)


@pytest.mark.parametrize("fixed", [False, True])
def test_solutions_respect_friction_unilaterality_and_torque_limits(cases, solved, fixed):
    _, sol = solved[fixed]
    tol_n, tol_nm = 1e-6, 1e-6
    for j in _rows_of(cases, "double", "single"):
        p, s = cases[j]["plant"], _take(sol, j)
        assert np.all(np.abs(s.tau) <= TAU_LIMIT_NM + tol_nm)
        for foot in range(2):
            r = p.sole_rot[foot]
            local = s.forces[foot] @ r  # (4, 3) in sole axes
            if cases[j]["mask"][foot] < 0.5:
                assert np.max(np.abs(s.forces[foot])) < 1e-8, (j, s.forces[foot])  # lifted: no force
                continue
            assert np.all(local[:, 2] >= -tol_n), local
            # inscribed 4-face pyramid: |f_t1|, |f_t2| <= mu / sqrt 2 f_n, hence inside the cone mu f_n
            assert np.all(np.abs(local[:, :2]) <= MU / np.sqrt(2) * local[:, 2:] + tol_n), local
            assert np.all(np.linalg.norm(local[:, :2], axis=1) <= MU * local[:, 2] + tol_n)
        # the stance feet carry the weight (plus what accelerates the CoM)
        weight = p.mass[0, 0] * 9.81
        assert abs(s.forces[..., 2].sum() - weight) < 0.2 * weight


def test_single_support_puts_all_load_on_the_stance_foot(cases, solved):
    _, sol = solved[False]
    for j in _rows_of(cases, "single"):
        s = _take(sol, j)
        assert np.max(np.abs(s.forces[0])) < 1e-8
        assert s.forces[1, :, 2].sum() > 0.8 * cases[j]["plant"].mass[0, 0] * 9.81


@pytest.mark.parametrize("fixed", [False, True])
def test_agrees_with_proxsuite(cases, solved, fixed):
    qp, sol = solved[fixed]
    for j in _rows_of(cases, "double", "single"):
        one = _take(qp, j)
        ref_x = qpsolvers.solve_qp(**wbc.export_qp(one), solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
        assert ref_x is not None
        x_tau = one.tau_map @ ref_x + one.tau_offset
        assert np.max(np.abs(sol.tau[j] - x_tau)) < 1e-5, (j, np.max(np.abs(sol.tau[j] - x_tau)))
        assert np.max(np.abs(sol.qdd[j] - (one.qdd_map @ ref_x + one.qdd_offset))) < 1e-5
        assert np.max(np.abs(sol.forces[j].reshape(-1) - one.force_map @ ref_x)) < 1e-5


def test_fixed_upper_body_follows_the_pd_law_and_shrinks_the_qp(cases, solved):
    qp_full, _ = solved[False]
    qp_fixed, sol = solved[True]
    for j in _rows_of(cases, "double", "single"):
        qpos, qvel = cases[j]["qpos"], cases[j]["qvel"]
        pd = UPPER_KP * (Q_REF[LEG_JOINTS:] - qpos[7 + LEG_JOINTS:]) - UPPER_KD * qvel[N_BASE + LEG_JOINTS:]
        np.testing.assert_allclose(sol.qdd[j, N_BASE + LEG_JOINTS:], pd, rtol=0, atol=1e-12)
    assert qp_fixed.Q.shape[-1] == qp_full.Q.shape[-1] - 11 == wbc.problem_size(29, True)["variables"]
    assert qp_full.G.shape[-2] == wbc.problem_size(29, False)["inequalities"]


@pytest.mark.parametrize("fixed", [False, True])
def test_infeasible_torque_limits_are_flagged_with_finite_fallback(cases, solved, fixed):
    _, sol = solved[fixed]
    (j,) = _rows_of(cases, "infeasible")
    s, p = _take(sol, j), cases[j]["plant"]
    assert not bool(s.info.ok)
    assert np.isfinite(s.tau).all() and np.isfinite(s.qdd).all() and np.isfinite(s.forces).all()
    np.testing.assert_allclose(s.tau, np.clip((p.bias - p.passive)[N_BASE:], -1e-3, 1e-3), atol=1e-15)
    assert np.all(s.qdd == 0) and np.all(s.forces == 0)
    ok_rows = _rows_of(cases, "double", "single", "fd")
    assert np.all(sol.info.ok[ok_rows]) and np.all(sol.info.kkt_residual[ok_rows] < 1e-8)


def test_gradient_through_the_qp_matches_central_differences(cases, solved):
    """d/dw of a scalar of (tau, qdd, forces), w the CoM task weight, forward and reverse mode."""
    (j0,) = [j for j, r in enumerate(cases) if r["kind"] == "double" and r["i"] == 0]
    jp, jm = _rows_of(cases, "fd")
    _, sol = solved[False]

    def scalar(s):
        return s.tau[..., 3] + 0.1 * s.qdd[..., 2] + 1e-4 * jnp.sum(s.forces[..., 2] ** 2, axis=(-1, -2))

    cd = (scalar(_take(sol, jp)) - scalar(_take(sol, jm))) / (2 * GRAD_H)
    args = [_take(a, j0) for a in _inputs(cases)[:-1]]
    f = lambda w: scalar(_one(*args, w, fixed=False)[1])  # noqa: E731
    grad, tangent = jax.jit(lambda w: (jax.grad(f)(w), jax.jvp(f, (w,), (jnp.ones_like(w),))[1]))(GRAD_W)
    assert abs(float(cd)) > 1e-3  # the weight matters
    assert abs(float(grad) - float(cd)) < 1e-5 * abs(float(cd)), (grad, cd)
    assert abs(float(tangent) - float(grad)) < 1e-10 * abs(float(cd))


def test_bad_inputs_raise_naming_the_value(cases):
    p = cases[0]["plant"]
    tasks = [wbc.qdd_regularization(1.0, 29)]
    lim = np.full(23, 33.0)
    with pytest.raises(ValueError, match="contact_jac"):
        wbc.build_qp(p._replace(contact_jac=p.contact_jac[:, :3]), tasks, (1, 1), -lim, lim)
    with pytest.raises(ValueError, match="tasks is empty"):
        wbc.build_qp(p, [], (1, 1), -lim, lim)
    with pytest.raises(ValueError, match="upper_acc"):
        wbc.build_qp(p, tasks, (1, 1), -lim, lim, fixed_upper_body=True)
    with pytest.raises(ValueError, match="n_faces"):
        wbc.build_qp(p, tasks, (1, 1), -lim, lim, n_faces=3)
    with pytest.raises(ValueError, match="selection"):
        wbc.momentum_rate_task(p.cmm, p.cmm_bias, np.zeros(6), 1.0, selection=(0, 6))


def _linalg_operand_ranks(jaxpr):
    """Ranks of the matrix operands of every Cholesky and triangular solve in a jaxpr, nested ones too."""
    out = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name in ("cholesky", "triangular_solve"):
            out.append(eqn.invars[0].aval.ndim)
        for p in eqn.params.values():
            for j in (p if isinstance(p, (tuple, list)) else [p]):
                inner = getattr(j, "jaxpr", j)
                if hasattr(inner, "eqns"):
                    out += _linalg_operand_ranks(inner)
    return out


def test_batched_solves_issue_no_batched_lapack_calls_on_cpu(cases):
    """jaxlib 0.10.2's batched CPU LAPACK kernels can deadlock the 2-thread pool (mjx_coman.wbc.batching
    .per_problem): under vmap, in forward and reverse mode, every factorization and solve stays unbatched."""
    assert jax.default_backend() == "cpu"
    args = _inputs(cases)
    forward = jax.make_jaxpr(jax.vmap(lambda *r: _one(*r, fixed=False)[1].tau))(*args)

    def loss(w):
        return jnp.sum(jax.vmap(lambda *r: _one(*r, w, fixed=False)[1].tau)(*args[:-1]))

    reverse = jax.make_jaxpr(jax.grad(loss))(GRAD_W)
    for jaxpr in (forward, reverse):
        ranks = _linalg_operand_ranks(jaxpr.jaxpr)
        assert len(ranks) >= 4 and max(ranks) == 2, ranks


def test_relaxed_stance_rows_solve_the_infeasible_case_within_torque_limits(cases, relaxed):
    """The hard QP with 1e-3 N m limits is infeasible; the relaxed one is not (seed 001's stance rows soft)."""
    qp, sol = relaxed
    (j,) = _rows_of(cases, "infeasible")
    s = _take(sol, j)
    assert bool(s.info.ok), s.info
    assert np.isfinite(s.tau).all() and np.isfinite(s.qdd).all() and np.isfinite(s.forces).all()
    assert np.all(np.abs(s.tau) <= 1e-3 + 1e-9)
    one = _take(qp, j)
    assert one.Q.shape[-1] == wbc.problem_size(29, False, contact_slack=True)["variables"]
    # the feet must accelerate: the slack is what the torques could not hold
    p, mask = cases[j]["plant"], np.asarray(cases[j]["mask"])
    corner_acc = np.einsum("fcin,n->fci", p.contact_jac, s.qdd) + p.contact_bias_acc
    assert np.max(np.abs(corner_acc[mask > 0.5])) > 1e-2


def test_relaxed_qp_agrees_with_proxsuite_and_its_kkt_conditions(cases, relaxed):
    qp, sol = relaxed
    for j in range(len(cases)):
        one = _take(qp, j)
        ref_x = qpsolvers.solve_qp(**wbc.export_qp(one), solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
        assert ref_x is not None, j
        x_tau = one.tau_map @ ref_x + one.tau_offset
        assert np.max(np.abs(sol.tau[j] - x_tau)) < 1e-5, (j, np.max(np.abs(sol.tau[j] - x_tau)))
        assert np.max(np.abs(sol.forces[j].reshape(-1) - one.force_map @ ref_x)) < 1e-5
    assert np.all(sol.info.ok) and np.all(sol.info.kkt_residual < 1e-8), sol.info.kkt_residual


def test_relaxed_qp_matches_the_hard_one_where_that_is_feasible(cases, solved, relaxed):
    """Where the stance rows can hold, the slack is O(1 / w) and the torques follow the hard solution."""
    _, hard = solved[False]
    qp, sol = relaxed
    for j in _rows_of(cases, "double", "single"):
        p, s, mask = cases[j]["plant"], _take(sol, j), np.asarray(cases[j]["mask"])
        corner_acc = np.einsum("fcin,n->fci", p.contact_jac, s.qdd) + p.contact_bias_acc
        assert np.max(np.abs(corner_acc[mask > 0.5])) < SLACK_TOL, (j, np.max(np.abs(corner_acc[mask > 0.5])))
        assert np.max(np.abs(s.tau - hard.tau[j])) < TAU_TOL_NM, (j, np.max(np.abs(s.tau - hard.tau[j])))
