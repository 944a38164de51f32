"""Seed 001 section III references: eq. 8 lift, blend, Slerp, swing foot, base turn, eq. 3 CoM acceleration."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman.controllers.footstep_mpc import trajectory as tr

T = 0.5  # swing duration, s
ZCL = 0.06  # clearance, m


@pytest.fixture(scope="module", autouse=True)
def _x64():
    with jax.enable_x64(True):
        yield


def fd(f, t, h=1e-6):
    """Central difference of ``f`` at ``t`` (pytrees of arrays)."""
    return jax.tree_util.tree_map(lambda a, b: (np.asarray(a) - np.asarray(b)) / (2 * h), f(t + h), f(t - h))


def axis_angle_quat(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def quat_angle(a, b):
    """Rotation angle between two orientations (sign-invariant, accurate near zero)."""
    a, b = np.asarray(a), np.asarray(b)
    b = b if np.dot(a, b) >= 0 else -b
    return 2 * np.arctan2(np.linalg.norm(a - b), np.linalg.norm(a + b))


def quat_to_mat(q):
    w, x, y, z = np.asarray(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_mul_np(a, b):
    aw, av, bw, bv = a[0], np.asarray(a[1:]), b[0], np.asarray(b[1:])
    return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])


def same_rotation(a, b, tol_rad=1e-12):
    return quat_angle(a, b) < tol_rad


# --- swing height (eq. 8) --------------------------------------------------------------------------------


def eq8_as_printed(t, dt, zcl):
    w = np.pi / dt
    return zcl / (1 / (2 * w) - 1 / (6 * w)) * (np.sin(w * t) / (2 * w) - np.sin(3 * w * t) / (6 * w))


@pytest.mark.parametrize("t", [-0.1, 0.0, T, T + 0.2])
def test_swing_height_zero_at_and_beyond_the_ends(t):
    np.testing.assert_allclose(tr.swing_height(t, T, ZCL), 0.0, atol=1e-14)


def test_swing_height_apex_is_the_clearance():
    z, zd, _ = tr.swing_height(T / 2, T, ZCL)
    np.testing.assert_allclose([z, zd], [ZCL, 0.0], atol=1e-15)
    zs = tr.swing_height(jnp.linspace(0, T, 201), T, ZCL)[0]
    assert float(zs.max()) == pytest.approx(ZCL, abs=1e-15) and float(zs.min()) >= 0.0


def test_printed_eq8_peaks_at_twice_the_clearance():
    assert eq8_as_printed(T / 2, T, ZCL) == pytest.approx(2 * ZCL)
    ts = np.linspace(0.01, T - 0.01, 37)
    np.testing.assert_allclose(eq8_as_printed(ts, T, ZCL), 2 * np.asarray(tr.swing_height(ts, T, ZCL)[0]),
                               rtol=1e-12)


@pytest.mark.parametrize("t", [0.03, 0.17, 0.25, 0.41])
def test_swing_height_derivatives_match_finite_differences(t):
    z, zd, zdd = tr.swing_height(t, T, ZCL)
    np.testing.assert_allclose(fd(lambda s: tr.swing_height(s, T, ZCL)[0], t), zd, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(fd(lambda s: tr.swing_height(s, T, ZCL)[1], t), zdd, rtol=1e-6, atol=1e-8)
    assert float(jax.grad(lambda s: tr.swing_height(s, T, ZCL)[0])(t)) == pytest.approx(float(zd), rel=1e-12)


# --- blend -----------------------------------------------------------------------------------------------


def test_blend_end_conditions_and_clipping():
    np.testing.assert_allclose(tr.blend(0.0, T), [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(tr.blend(T, T), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(tr.blend(-0.3, T), [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(tr.blend(T + 0.3, T), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(tr.blend(T / 2, T)[0], 0.5, atol=1e-15)


def test_blend_monotone_and_derivatives():
    ts = jnp.linspace(0, T, 101)
    s, sd, _ = tr.blend(ts, T)
    assert np.all(np.diff(np.asarray(s)) > 0) and np.all(np.asarray(sd) >= 0)
    for t in (0.05, 0.2, 0.33):
        _, sd, sdd = tr.blend(t, T)
        np.testing.assert_allclose(fd(lambda x: tr.blend(x, T)[0], t), sd, rtol=1e-7)
        np.testing.assert_allclose(fd(lambda x: tr.blend(x, T)[1], t), sdd, rtol=1e-6)


# --- quaternions -----------------------------------------------------------------------------------------

Q0 = axis_angle_quat([0.3, -0.2, 1.0], 0.7)
Q1 = axis_angle_quat([-0.5, 0.8, 0.1], 1.9)


def test_slerp_endpoints_and_unit_norm():
    assert same_rotation(tr.quat_slerp(Q0, Q1, 0.0), Q0)
    np.testing.assert_allclose(tr.quat_slerp(Q0, Q1, 0.0), Q0, atol=1e-14)
    assert same_rotation(tr.quat_slerp(Q0, Q1, 1.0), Q1)
    qs = jax.jit(jax.vmap(lambda s: tr.quat_slerp(Q0, Q1, s)))(jnp.linspace(0, 1, 11))
    np.testing.assert_allclose(jnp.linalg.norm(qs, axis=-1), 1.0, atol=1e-14)


def test_slerp_constant_angular_speed_on_the_shortest_arc():
    total = quat_angle(Q0, Q1)
    assert 0 < total < np.pi
    qs = jax.jit(jax.vmap(lambda s: tr.quat_slerp(Q0, Q1, s)))(jnp.linspace(0, 1, 9))
    steps = [quat_angle(qs[i], qs[i + 1]) for i in range(8)]
    np.testing.assert_allclose(steps, total / 8, rtol=1e-9)
    np.testing.assert_allclose(quat_angle(Q0, qs[3]), 3 * total / 8, rtol=1e-9)


def test_slerp_sign_of_the_target_does_not_matter():
    for s in (0.0, 0.3, 0.8, 1.0):
        np.testing.assert_allclose(tr.quat_slerp(Q0, -Q1, s), tr.quat_slerp(Q0, Q1, s), atol=1e-14)
    # an antipodal representation still takes the short way: the midpoint is half the short angle away
    mid = tr.quat_slerp(Q0, -Q1, 0.5)
    assert quat_angle(Q0, mid) == pytest.approx(quat_angle(Q0, Q1) / 2, rel=1e-9)


def test_slerp_safe_at_identical_quaternions():
    q = tr.quat_slerp(Q0, Q0, 0.4)
    np.testing.assert_allclose(q, Q0, atol=1e-15)
    g_s = jax.jit(jax.grad(lambda s: tr.quat_slerp(Q0, Q0, s).sum()))(0.4)
    g_q = jax.jit(jax.grad(lambda q1: tr.quat_slerp(Q0, q1, 0.4)[1]))(Q0)
    assert np.isfinite(g_s) and np.all(np.isfinite(g_q))
    # the derivative at q1 == q0 is the continuous one: d q(s) / d q1 along a small rotation = s times it
    q1 = tr.rotate_yaw(Q0, 1e-4)  # world z rotation of Q0 by a tiny angle
    np.testing.assert_allclose(tr.quat_delta(Q0, tr.quat_slerp(Q0, q1, 0.4)), 0.4 * tr.quat_delta(Q0, q1),
                               atol=1e-15)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(tr.quat_exp))(jnp.zeros(3)),
                               np.vstack([np.zeros(3), 0.5 * np.eye(3)]))
    np.testing.assert_allclose(jax.jit(jax.jacfwd(tr.quat_log))(jnp.asarray([1.0, 0, 0, 0])),
                               np.hstack([np.zeros((3, 1)), 2 * np.eye(3)]))


def test_log_exp_round_trip():
    for q in (Q0, Q1, -Q1, axis_angle_quat([1, 2, 3], 1e-7)):
        assert same_rotation(tr.quat_exp(tr.quat_log(q)), q)
    np.testing.assert_allclose(tr.quat_log(axis_angle_quat([0, 0, 1], 0.3)), [0, 0, 0.3], atol=1e-15)


def test_yaw_helpers():
    for y in (-2.5, -0.3, 0.0, 1.2, 3.0):
        assert float(tr.quat_yaw(tr.yaw_quat(y))) == pytest.approx(y, abs=1e-14)
    r = quat_to_mat(tr.rotate_yaw(Q0, 0.4))
    np.testing.assert_allclose(r, quat_to_mat(tr.yaw_quat(0.4)) @ quat_to_mat(Q0), atol=1e-14)
    assert float(tr.quat_yaw(tr.rotate_yaw(tr.yaw_quat(0.5), 0.3))) == pytest.approx(0.8, abs=1e-14)


# --- swing foot ------------------------------------------------------------------------------------------

START = np.array([0.1, -0.08, 0.02])
TARGET_XY = np.array([0.32, -0.12])
GROUND = 0.0
# lift-off orientation: rolled/pitched by 0.08 rad, then yaw 0.1 about world z
TILTED = quat_mul_np(np.array([np.cos(0.05), 0, 0, np.sin(0.05)]), axis_angle_quat([1.0, 0.5, 0.0], 0.08))
FLAT = np.array([np.cos(0.05), 0, 0, np.sin(0.05)])  # yaw 0.1


def foot(t, quat=TILTED, yaw=0.4):
    return tr.swing_foot_reference(t, T, START, TARGET_XY, GROUND, ZCL, quat, yaw)


def test_swing_foot_starts_at_the_start_pose():
    ref = foot(0.0)
    np.testing.assert_allclose(ref.pos, START, atol=1e-15)
    np.testing.assert_allclose(ref.quat, TILTED, atol=1e-15)
    for v in (ref.vel, ref.acc, ref.ang_vel, ref.ang_acc):
        np.testing.assert_allclose(v, 0.0, atol=1e-15)


def test_swing_foot_ends_flat_on_the_target():
    ref = foot(T)
    np.testing.assert_allclose(ref.pos, [0.32, -0.12, GROUND], atol=1e-12)
    assert same_rotation(ref.quat, tr.yaw_quat(0.4))  # yaw 0.4, roll = pitch = 0
    assert float(tr.quat_yaw(ref.quat)) == pytest.approx(0.4, abs=1e-12)
    for v in (ref.vel, ref.acc, ref.ang_vel, ref.ang_acc):
        np.testing.assert_allclose(v, 0.0, atol=1e-12)
    np.testing.assert_allclose(foot(T + 0.1).pos, ref.pos, atol=1e-15)


def test_swing_foot_apex_above_the_ground_line():
    level = tr.swing_foot_reference(T / 2, T, jnp.asarray([0.0, 0.0, 0.05]), jnp.zeros(2), 0.05, ZCL,
                                    tr.yaw_quat(0.0), 0.0)
    assert float(level.pos[2]) == pytest.approx(0.05 + ZCL, abs=1e-15)


@pytest.mark.parametrize("quat", [FLAT, TILTED], ids=["flat", "tilted"])
@pytest.mark.parametrize("t", [0.07, 0.25, 0.38])
def test_swing_foot_derivatives_match_finite_differences(quat, t):
    ref = foot(t, quat)  # yaw 0.1 -> 0.4: a 0.3 rad turn
    np.testing.assert_allclose(fd(lambda s: foot(s, quat).pos, t), ref.vel, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fd(lambda s: foot(s, quat).vel, t), ref.acc, rtol=1e-6, atol=1e-8)
    h = 1e-6
    w_fd = tr.quat_delta(foot(t - h, quat).quat, foot(t + h, quat).quat) / (2 * h)
    np.testing.assert_allclose(w_fd, ref.ang_vel, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fd(lambda s: foot(s, quat).ang_vel, t), ref.ang_acc, rtol=1e-6, atol=1e-8)
    if quat is not TILTED:
        np.testing.assert_allclose(ref.ang_vel[:2], 0.0, atol=1e-15)  # a pure yaw turn
        assert float(tr.quat_yaw(ref.quat)) == pytest.approx(0.1 + 0.3 * float(tr.blend(t, T)[0]), abs=1e-12)


def test_swing_foot_vmaps_jits_and_follows_dtype():
    ts = jnp.linspace(0.0, T, 5)
    refs = jax.jit(jax.vmap(foot))(ts)
    assert refs.pos.shape == (5, 3) and refs.quat.shape == (5, 4)
    f32 = tr.swing_foot_reference(jnp.float32(0.2), jnp.float32(T), jnp.asarray(START, jnp.float32),
                                  jnp.asarray(TARGET_XY, jnp.float32), jnp.float32(0.0), jnp.float32(ZCL),
                                  jnp.asarray(TILTED, jnp.float32), jnp.float32(0.4))
    assert all(x.dtype == jnp.float32 for x in f32)
    g = jax.jit(jax.grad(lambda yaw: foot(0.2, yaw=yaw).ang_vel[2]))(0.4)
    assert np.isfinite(g) and g != 0.0


# --- stepping over an edge --------------------------------------------------------------------------------

LIFT = 0.4  # fraction of the swing rising (and, at the end, dropping)


def over(t, start=(0.0, 0.0, 0.0), target=(0.24, 0.02), ground=0.05, quat=TILTED):
    return tr.step_over_reference(t, T, jnp.asarray(start), jnp.asarray(target), ground, ZCL, quat, 0.4, LIFT)


@pytest.mark.parametrize("ground", [0.05, -0.05], ids=["up", "down"])
def test_step_over_starts_and_ends_at_rest_on_the_two_treads(ground):
    a, b = over(0.0, ground=ground), over(T, ground=ground)
    np.testing.assert_allclose(a.pos, 0.0, atol=1e-15)
    np.testing.assert_allclose(b.pos, [0.24, 0.02, ground], atol=1e-12)
    assert same_rotation(a.quat, TILTED) and same_rotation(b.quat, tr.yaw_quat(0.4))
    for v in (a.vel, a.acc, b.vel, b.acc, a.ang_vel, b.ang_vel):
        np.testing.assert_allclose(v, 0.0, atol=1e-12)


@pytest.mark.parametrize("ground", [0.05, -0.05], ids=["up", "down"])
def test_step_over_is_above_both_treads_while_it_moves_across(ground):
    """Up: the foot is half way up before it moves forward; past the middle of the swing it is at the top
    (both tread heights + the clearance) until it is over the far tread. Down: mirrored in time."""
    ts = np.linspace(0.0, T, 401)
    refs = jax.vmap(lambda t: over(t, ground=ground))(jnp.asarray(ts))
    x, z = np.asarray(refs.pos[:, 0]), np.asarray(refs.pos[:, 2])
    top = max(0.0, ground) + ZCL
    assert z.max() == pytest.approx(top, abs=1e-12)
    moving = ts <= LIFT * T / 2  # before the horizontal motion starts
    np.testing.assert_allclose(x[moving], 0.0, atol=1e-15)
    crossing = (ts >= LIFT * T) & (ts <= (1 - LIFT) * T)
    np.testing.assert_allclose(z[crossing], top, atol=1e-12)
    assert x[ts >= (1 - LIFT / 2) * T].min() == pytest.approx(0.24, abs=1e-12)  # over the far tread as it drops
    rising = ts <= LIFT * T
    assert np.all(np.diff(z[rising]) >= -1e-15)


@pytest.mark.parametrize("t", [0.05, 0.12, 0.25, 0.41])
def test_step_over_derivatives_match_finite_differences(t):
    ref = over(t)
    np.testing.assert_allclose(fd(lambda s: over(s).pos, t), ref.vel, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fd(lambda s: over(s).vel, t), ref.acc, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(fd(lambda s: over(s).ang_vel, t), ref.ang_acc, rtol=1e-6, atol=1e-8)


# --- base ------------------------------------------------------------------------------------------------


def test_base_reference_turns_by_the_joystick_rate():
    yaw0, turn = 0.2, 0.6
    q_end, w_end, a_end = tr.base_reference(T, T, yaw0, turn)
    assert float(tr.quat_yaw(q_end)) == pytest.approx(yaw0 + turn * T, abs=1e-14)
    np.testing.assert_allclose(q_end[1:3], 0.0, atol=1e-15)  # upright
    np.testing.assert_allclose([w_end, a_end], 0.0, atol=1e-12)
    t = 0.2
    q, w, a = tr.base_reference(t, T, yaw0, turn)
    assert same_rotation(q, tr.quat_slerp(tr.yaw_quat(yaw0), tr.yaw_quat(yaw0 + turn * T), tr.blend(t, T)[0]))
    h = 1e-6
    np.testing.assert_allclose(tr.quat_delta(tr.base_reference(t - h, T, yaw0, turn)[0],
                                             tr.base_reference(t + h, T, yaw0, turn)[0]) / (2 * h), w, rtol=1e-7)
    np.testing.assert_allclose(fd(lambda s: tr.base_reference(s, T, yaw0, turn)[1], t), a, rtol=1e-6, atol=1e-12)


# --- CoM (eq. 3) -----------------------------------------------------------------------------------------


def test_com_acceleration_eq3_and_height_pd():
    com, vel = jnp.asarray([0.05, -0.02, 0.48]), jnp.asarray([0.3, 0.0, 0.1])
    acc = tr.com_reference_acc(com, vel, jnp.asarray([0.0, 0.0]), 0.5, 100.0, 20.0)
    assert float(acc[0]) > 0 and float(acc[1]) < 0  # the CoM falls away from the stance foot
    np.testing.assert_allclose(acc[:2], 9.81 / 0.5 * np.array([0.05, -0.02]), rtol=1e-14)
    assert float(acc[2]) == pytest.approx(100.0 * 0.02 - 20.0 * 0.1)
    # on a raised stance foot the pendulum height is given apart from the absolute height target
    acc2 = tr.com_reference_acc(com, vel, jnp.asarray([0.0, 0.0]), 0.5, 100.0, 20.0, lipm_height_m=0.4)
    np.testing.assert_allclose(acc2[:2], 9.81 / 0.4 * np.array([0.05, -0.02]), rtol=1e-14)
    assert float(acc2[2]) == pytest.approx(float(acc[2]))
