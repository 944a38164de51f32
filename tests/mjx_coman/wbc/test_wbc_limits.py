"""Joint-acceleration bounds from the joint limits (seed 004 eq. 5), alone and as rows of the whole-body QP."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
import qpsolvers

import mjx_coman
from mjx_coman import wbc
from mjx_coman.actuators import JOINT_NAMES
from mjx_coman.env import standing_posture
from mjx_coman.kinematics import LEFT_LEG_LIMITS_RAD, RIGHT_LEG_LIMITS_RAD
from mjx_coman.wbc import reference as ref
from mjx_coman.wbc.plant import LEG_JOINTS, N_BASE


@pytest.fixture(scope="module", autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


def test_joint_range_is_the_mjcf_range_in_actuator_order():
    m = mjx_coman.load_model()
    rng = wbc.joint_range_rad()
    assert rng.shape == (2, len(JOINT_NAMES))
    for i, name in enumerate(JOINT_NAMES):
        np.testing.assert_array_equal(rng[:, i], m.jnt_range[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)])
    np.testing.assert_allclose(rng[:, :6], RIGHT_LEG_LIMITS_RAD)  # joints.csv, as the kinematics read it
    np.testing.assert_allclose(rng[:, 6:12], LEFT_LEG_LIMITS_RAD)


def test_a_joint_at_either_bound_reaches_its_limit_at_the_horizon_and_never_crosses_it():
    rng = np.random.default_rng(0)
    q_min, q_max, h = -0.17, 1.9, 0.05
    q = rng.uniform(q_min, q_max, 200)
    qd = rng.uniform(-3.0, 3.0, 200)
    lo, hi = (np.asarray(a) for a in wbc.joint_acc_bounds(q, qd, q_min, q_max, h, 1e9))  # unclipped
    end = lambda a, t: q + qd * t + 0.5 * a * t * t  # noqa: E731
    np.testing.assert_allclose(end(hi, h), q_max, atol=1e-12)
    np.testing.assert_allclose(end(lo, h), q_min, atol=1e-12)
    assert np.all(lo <= hi)
    # any acceleration within the bounds keeps the joint inside its limits at the horizon
    a = lo + rng.uniform(0, 1, 200) * (hi - lo)
    assert np.all((end(a, h) >= q_min - 1e-12) & (end(a, h) <= q_max + 1e-12))


def test_bounds_are_clipped_and_ordered_past_a_limit():
    lo, hi = wbc.joint_acc_bounds(jnp.asarray([0.5, -0.3, 0.5]), jnp.asarray([0.0, -2.0, 60.0]), -0.17, 1.9, 0.05,
                                  500.0)
    lo, hi = np.asarray(lo), np.asarray(hi)
    assert lo[0] == -500.0 and hi[0] == 500.0  # far from both limits: only the clip
    # past the lower limit and moving further: at least the acceleration that is back at the limit at the horizon
    assert hi[1] == 500.0 and lo[1] == pytest.approx(2 * (-0.17 - (-0.3 - 2.0 * 0.05)) / 0.05**2)
    assert lo[2] == hi[2] == -500.0  # too fast to stop before the upper limit: braked as hard as allowed


@pytest.fixture(scope="module")
def bounded():
    """Standing plants, both feet down, a CoM target 3 cm off; the legs' accelerations bounded by +-BOUND, with
    the upper body fixed and free (one compile each)."""
    model = mjx_coman.load_model()
    states = ref.standing_plants(model, 3, seed=5)
    q_ref = standing_posture()[0]
    out = []
    for fixed in (False, True):
        def one(plant, qpos, qvel, com_des, fixed=fixed):
            mask = jnp.ones(2)
            tasks = ref.standing_tasks(plant, qpos, qvel, q_ref, com_des, mask, com_weight=10.0)
            kw = {}
            if fixed:
                kw = dict(fixed_upper_body=True, upper_acc=wbc.joint_pd(q_ref[LEG_JOINTS:], qpos[7 + LEG_JOINTS:],
                                                                        qvel[N_BASE + LEG_JOINTS:], 100.0, 20.0))
            bounds = (jnp.full(23, -BOUND), jnp.full(23, BOUND))
            qp = wbc.build_qp(plant, tasks, mask, -jnp.full(23, 33.0), jnp.full(23, 33.0), qdd_bounds=bounds, **kw)
            x, info = wbc.solve_qp(qp)
            return qp, x, info

        plants = ref.stack_plants([p for _, _, p in states])
        qpos = np.stack([s[0] for s in states])
        qvel = np.stack([s[1] for s in states])
        com = np.stack([np.asarray(p.com) + np.array([0.03, 0.0, 0.0]) for _, _, p in states])
        res = jax.jit(jax.vmap(one))(plants, qpos, qvel, com)
        out.append((fixed, jax.tree_util.tree_map(np.asarray, res)))
    return out


BOUND = 0.5  # rad/s^2: binds (the CoM target 3 cm away at weight 10 asks for more)


def test_bounded_qp_holds_the_bounds_agrees_with_proxsuite_and_the_bounds_bind(bounded):
    for fixed, (qp, x, info) in bounded:
        n_act = (LEG_JOINTS if fixed else 23)
        size = wbc.problem_size(29, fixed, qdd_bounds=True)
        assert qp.G.shape[-2] == size["inequalities"] == wbc.problem_size(29, fixed)["inequalities"] + 2 * n_act
        assert np.all(info.ok) and np.all(info.kkt_residual < 1e-8), info.kkt_residual
        binding = 0
        for j in range(x.shape[0]):
            one = jax.tree_util.tree_map(lambda a, j=j: a[j], qp)
            qdd = one.qdd_map @ x[j] + one.qdd_offset
            act = qdd[N_BASE:N_BASE + n_act]
            assert np.all(np.abs(act) <= BOUND + 1e-7), np.abs(act).max()
            binding += int(np.sum(np.abs(act) > BOUND - 1e-6))
            ref_x = qpsolvers.solve_qp(**wbc.export_qp(one), solver="proxqp", eps_abs=1e-10, eps_rel=0.0)
            assert ref_x is not None
            np.testing.assert_allclose(one.tau_map @ x[j], one.tau_map @ ref_x, atol=1e-5)
        assert binding > 0  # the bounds are active: the test would see a solver that ignored them
