"""Tests of mjx_coman.kinematics: FK conventions, closed-form IK round trips, clamping."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import kinematics as kin

SIDES = ["left", "right"]
LEG_LENGTH_M = kin.THIGH_LENGTH_M + kin.SHANK_LENGTH_M
N_POSES = 300
POS_TOL_M = 1e-6
ROT_TOL_RAD = 1e-6
KNEE_MIN_SAMPLE_RAD = 0.1  # away from the straight-knee singularity
MJCF_PATH = Path(__file__).resolve().parents[2] / "mjx_coman" / "assets" / "coman.xml"


@pytest.fixture(scope="module", autouse=True)
def x64():
    """Run the whole module in float64."""
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def fns():
    """Jitted, vmapped FK and IK per side (compiled once per module)."""
    out = {}
    for side in SIDES:
        out[side] = dict(
            fk=jax.jit(jax.vmap(lambda q, side=side: kin.leg_fk(q, side))),
            ik=jax.jit(jax.vmap(lambda p, r, o, side=side: kin.leg_ik(p, r, side, o),
                                in_axes=(0, 0, None))),
        )
    return out


def _random_angles(side: str, n: int, seed: int) -> np.ndarray:
    lim = kin.leg_limits_rad(side)
    rng = np.random.default_rng(seed)
    q = rng.uniform(lim[0], lim[1], size=(n, 6))
    q[:, 3] = rng.uniform(KNEE_MIN_SAMPLE_RAD, lim[1, 3], size=n)
    return q


def _rot_angle_rad(r1, r2) -> np.ndarray:
    """Angle of the relative rotation ``r1^T r2`` (robust near zero)."""
    rel = np.einsum("...ji,...jk->...ik", np.asarray(r1), np.asarray(r2))
    skew = np.stack([rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0],
                     rel[..., 1, 0] - rel[..., 0, 1]], -1)
    trace = np.trace(rel, axis1=-2, axis2=-1)
    return np.arctan2(0.5 * np.linalg.norm(skew, axis=-1), 0.5 * (trace - 1.0))


@pytest.mark.parametrize("side", SIDES)
def test_zero_pose(side):
    pose = kin.leg_fk(jnp.zeros(6), side)
    s = 1.0 if side == "left" else -1.0
    np.testing.assert_allclose(pose.hip_m, [0.0, s * 0.0726, 0.0], atol=1e-12)
    np.testing.assert_allclose(pose.ankle_m, [0.0, s * 0.0726, -0.4268], atol=1e-12)
    np.testing.assert_allclose(pose.sole_m, [0.0, s * 0.0726, -0.5168], atol=1e-12)
    np.testing.assert_allclose(pose.foot_point_m, [0.03, s * 0.0726, -0.4268], atol=1e-12)
    np.testing.assert_allclose(pose.foot_rot, np.eye(3), atol=1e-12)
    # The README rounds the hip height above the sole to 0.517 m; the joint
    # offsets give 0.1024 + 0.1234 + 0.201 + 0.09 = 0.5168 m (0.2 mm less).
    assert abs(-float(pose.sole_m[2]) - 0.517) < 5e-4


@pytest.mark.parametrize("side", SIDES)
def test_sign_conventions(side):
    """Hip pitch < 0 swings the leg forward, knee > 0 flexes, ankle pitch > 0 toes down."""
    ref = kin.leg_fk(jnp.zeros(6), side)
    q = np.zeros(6)

    def moved(i, v):
        return kin.leg_fk(jnp.asarray(np.where(np.arange(6) == i, v, q)), side)

    assert moved(0, -0.3).ankle_m[0] > 0.1  # hip flexion: foot forward
    assert moved(1, 0.3).ankle_m[1] > ref.ankle_m[1] + 0.1  # hip roll > 0: foot to +y
    assert moved(2, 0.3).foot_rot[1, 0] > 0.2  # hip yaw > 0: toes to the left
    knee = moved(3, 0.5)
    assert knee.knee_m[0] == pytest.approx(0.0) and knee.ankle_m[0] < -0.05  # knee bends forward
    assert moved(4, 0.3).foot_rot[2, 1] > 0.2  # ankle roll > 0: +y edge up
    assert moved(5, 0.3).foot_point_m[2] < ref.foot_point_m[2] - 0.005  # toes down


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("point", ["ankle", "sole", "foot_point"])
def test_ik_fk_round_trip(fns, side, point):
    offsets = {"ankle": (0.0, 0.0, 0.0), "sole": kin.ANKLE_TO_SOLE_OFFSET_M,
               "foot_point": kin.FOOT_POINT_OFFSET_M}
    q = _random_angles(side, N_POSES, seed=1 if side == "left" else 2)
    pose = fns[side]["fk"](jnp.asarray(q))
    target = getattr(pose, point + "_m" if point != "foot_point" else "foot_point_m")
    q_ik = fns[side]["ik"](target, pose.foot_rot, jnp.asarray(offsets[point]))
    assert np.all(np.isfinite(q_ik))
    back = fns[side]["fk"](q_ik)
    for field in ("ankle_m", "sole_m", "foot_point_m"):
        np.testing.assert_allclose(getattr(back, field), getattr(pose, field), rtol=0, atol=POS_TOL_M)
    assert np.max(_rot_angle_rad(back.foot_rot, pose.foot_rot)) < ROT_TOL_RAD
    # Within the joint limits (knee >= 0, roll angles below 90 degrees) the solution is unique.
    np.testing.assert_allclose(q_ik, q, rtol=0, atol=1e-8)


@pytest.mark.parametrize("side", SIDES)
def test_unreachable_target_gives_stretched_leg(fns, side):
    rng = np.random.default_rng(3)
    n = 100
    q = _random_angles(side, n, seed=4)
    rot = fns[side]["fk"](jnp.asarray(q)).foot_rot
    hip = np.asarray(kin.leg_fk(jnp.zeros(6), side).hip_m)
    direction = rng.normal(size=(n, 3))
    direction[:, 2] = -np.abs(direction[:, 2]) - 0.5  # mostly downwards, any direction is valid
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    target = hip + 2.0 * LEG_LENGTH_M * direction
    q_ik = fns[side]["ik"](jnp.asarray(target), rot, jnp.zeros(3))
    assert np.all(np.isfinite(q_ik))
    np.testing.assert_allclose(q_ik[:, 3], 0.0, atol=1e-5)  # straight knee
    back = fns[side]["fk"](q_ik)
    expected = hip + LEG_LENGTH_M * direction  # on the straight-leg sphere, along the target
    np.testing.assert_allclose(back.ankle_m, expected, rtol=0, atol=POS_TOL_M)
    assert np.max(_rot_angle_rad(back.foot_rot, rot)) < ROT_TOL_RAD


@pytest.mark.parametrize("side", SIDES)
def test_too_close_and_degenerate_targets_are_finite(fns, side):
    hip = np.asarray(kin.leg_fk(jnp.zeros(6), side).hip_m)
    targets = np.stack([hip, hip + [0.0, 0.0, -0.05], hip + [0.0, 0.0, -LEG_LENGTH_M]])
    rots = np.broadcast_to(np.eye(3), (3, 3, 3))
    q_ik = fns[side]["ik"](jnp.asarray(targets), jnp.asarray(rots), jnp.zeros(3))
    assert np.all(np.isfinite(q_ik))
    lim = kin.leg_limits_rad(side)
    np.testing.assert_allclose(q_ik[:2, 3], lim[1, 3], atol=1e-9)  # most flexed knee
    # Too close: the ankle lands at the knee's minimum reach, along the target direction.
    back = fns[side]["fk"](q_ik[1:2])
    r_min = np.sqrt(kin.THIGH_LENGTH_M**2 + kin.SHANK_LENGTH_M**2
                    + 2 * kin.THIGH_LENGTH_M * kin.SHANK_LENGTH_M * np.cos(lim[1, 3]))
    np.testing.assert_allclose(back.ankle_m[0], hip + [0.0, 0.0, -r_min], atol=POS_TOL_M)


@pytest.mark.parametrize("side", SIDES)
def test_unreachable_orientation_is_finite(side):
    """Foot rolled 90 degrees under a bent leg: ankle roll beyond reach, clamped."""
    hip = kin.leg_fk(jnp.zeros(6), side).hip_m
    rot = kin.rot_x(jnp.asarray(np.pi / 2))
    target = hip + jnp.array([0.0, 0.0, -0.35])

    def loss(p, r):
        return jnp.sum(kin.leg_ik(p, r, side) ** 2)

    q = kin.leg_ik(target, rot, side)
    g_pos, g_rot = jax.grad(loss, argnums=(0, 1))(target, rot)
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(g_pos)) and np.all(np.isfinite(g_rot))
    assert abs(float(q[4])) == pytest.approx(np.pi / 2, abs=1e-3)


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("reach_factor", [1.0, 2.0])
def test_straight_knee_gradients_finite(side, reach_factor):
    hip = kin.leg_fk(jnp.zeros(6), side).hip_m
    rot = kin.rot_z(jnp.asarray(0.2)) @ kin.rot_x(jnp.asarray(0.1))
    target = hip + reach_factor * LEG_LENGTH_M * jnp.array([0.0, 0.0, -1.0])

    def loss(p, r):
        q = kin.leg_ik(p, r, side)
        return jnp.sum(q**2) + jnp.sum(jnp.sin(q))

    q = kin.leg_ik(target, rot, side)
    assert np.all(np.isfinite(q))
    assert float(q[3]) == pytest.approx(0.0, abs=1e-5)
    g_pos, g_rot = jax.grad(loss, argnums=(0, 1))(target, rot)
    assert np.all(np.isfinite(g_pos)) and np.all(np.isfinite(g_rot))
    back = kin.leg_fk(q, side)
    expected = np.asarray(hip) + np.array([0.0, 0.0, -LEG_LENGTH_M])  # nearest reachable point
    np.testing.assert_allclose(back.ankle_m, expected, atol=POS_TOL_M)
    np.testing.assert_allclose(back.foot_rot, rot, atol=ROT_TOL_RAD)


@pytest.mark.parametrize("side", SIDES)
def test_ik_gradient_matches_finite_differences(side):
    q0 = jnp.asarray(_random_angles(side, 1, seed=5)[0])
    pose = kin.leg_fk(q0, side)

    def f(p):
        return kin.leg_ik(p, pose.foot_rot, side)

    jac = jax.jacobian(f)(pose.ankle_m)
    h = 1e-6
    fd = np.stack([(f(pose.ankle_m + h * e) - f(pose.ankle_m - h * e)) / (2 * h) for e in jnp.eye(3)], 1)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6)


def test_float32_jit_round_trip():
    with jax.enable_x64(False):
        q = jnp.asarray(_random_angles("left", 64, seed=6), jnp.float32)
        fk = jax.jit(jax.vmap(lambda a: kin.leg_fk(a, "left")))
        pose = fk(q)
        q_ik = jax.jit(jax.vmap(lambda p, r: kin.leg_ik(p, r, "left")))(pose.ankle_m, pose.foot_rot)
        assert q_ik.dtype == jnp.float32
        np.testing.assert_allclose(fk(q_ik).ankle_m, pose.ankle_m, atol=2e-5)


def test_vmap_over_side_sign():
    q = jnp.asarray(np.stack([_random_angles("left", 1, 7)[0], _random_angles("right", 1, 8)[0]]))
    signs = jnp.array([1.0, -1.0])
    pose = jax.vmap(kin.leg_fk)(q, signs)
    q_ik = jax.vmap(kin.leg_ik)(pose.ankle_m, pose.foot_rot, signs)
    np.testing.assert_allclose(q_ik, q, atol=1e-9)
    np.testing.assert_allclose(pose.ankle_m[1], kin.leg_fk(q[1], "right").ankle_m, atol=1e-15)


def test_feet_in_frame():
    rng = np.random.default_rng(9)
    q_l = jnp.asarray(_random_angles("left", 1, 10)[0])
    q_r = jnp.asarray(_random_angles("right", 1, 11)[0])
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    rot = kin.quat_to_rot(jnp.asarray(quat))
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    world = kin.feet_in_frame(jnp.asarray(quat), q_l, q_r, yaw_free=False)
    world_m = kin.feet_in_frame(rot, q_l, q_r, yaw_free=False)
    np.testing.assert_allclose(world.foot_point_m, world_m.foot_point_m, atol=1e-12)
    left, right = kin.leg_fk(q_l, "left"), kin.leg_fk(q_r, "right")
    np.testing.assert_allclose(world.foot_point_m[0], rot @ left.foot_point_m, atol=1e-12)
    np.testing.assert_allclose(world.sole_m[1], rot @ right.sole_m, atol=1e-12)
    np.testing.assert_allclose(world.foot_rot[1], rot @ right.foot_rot, atol=1e-12)
    # The pelvis point is midway between the hip centres.
    np.testing.assert_allclose(world.hip_m[0] + world.hip_m[1], np.zeros(3), atol=1e-12)
    # Yaw-free: invariant to the pelvis heading, z stays the world vertical.
    yawed = kin.rot_z(jnp.asarray(1.1)) @ rot
    a = kin.feet_in_frame(rot, q_l, q_r, yaw_free=True)
    b = kin.feet_in_frame(yawed, q_l, q_r, yaw_free=True)
    np.testing.assert_allclose(a.foot_point_m, b.foot_point_m, atol=1e-12)
    np.testing.assert_allclose(a.foot_point_m[:, 2], world.foot_point_m[:, 2], atol=1e-12)
    assert abs(float(a.frame_rot[1, 0])) < 1e-12  # heading removed: pelvis x has no +y component
    # The IMU link is upside down on the pelvis.
    np.testing.assert_allclose(kin.imu_to_pelvis_rot(rot @ kin.rot_y(jnp.asarray(3.14159))), rot, atol=1e-12)


LEG_JOINTS = {"left": ["LHipSag", "LHipLat", "LHipYaw", "LKneeSag", "LAnkLat", "LAnkSag"],
              "right": ["RHipSag", "RHipLat", "RHipYaw", "RKneeSag", "RAnkLat", "RAnkSag"]}


@pytest.mark.skipif(not MJCF_PATH.exists(), reason=f"COMAN MJCF not written yet ({MJCF_PATH})")
@pytest.mark.parametrize("side", SIDES)
def test_fk_matches_mujoco(fns, side):
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjModel.from_xml_path(str(MJCF_PATH))
    data = mujoco.MjData(model)
    try:
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in LEG_JOINTS[side]]
    except Exception as err:  # pragma: no cover - depends on the other module's names
        pytest.skip(f"joint names differ from joints.csv: {err}")
    if min(jids) < 0:
        pytest.skip(f"MJCF lacks some of the joints {LEG_JOINTS[side]}")
    pelvis = model.body_parentid[model.jnt_bodyid[jids[0]]]
    foot = model.jnt_bodyid[jids[5]]
    sole_site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, side[0] + "_sole")
    imu_site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "imu")
    q = _random_angles(side, 50, seed=12)
    rng = np.random.default_rng(13)
    pose = fns[side]["fk"](jnp.asarray(q))
    for i in range(len(q)):
        data.qpos[:] = model.qpos0
        if model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE:  # arbitrary base pose
            quat = rng.normal(size=4)
            data.qpos[model.jnt_qposadr[0]:model.jnt_qposadr[0] + 7] = np.r_[rng.normal(size=3), quat / np.linalg.norm(quat)]
        for j, v in zip(jids, q[i]):
            data.qpos[model.jnt_qposadr[j]] = v
        mujoco.mj_kinematics(model, data)
        r_pelvis = data.xmat[pelvis].reshape(3, 3)
        ankle = r_pelvis.T @ (data.xanchor[jids[5]] - data.xpos[pelvis])
        hip = r_pelvis.T @ (data.xanchor[jids[1]] - data.xpos[pelvis])
        r_foot = r_pelvis.T @ data.xmat[foot].reshape(3, 3)
        np.testing.assert_allclose(ankle, pose.ankle_m[i], atol=1e-6)
        np.testing.assert_allclose(hip, pose.hip_m[i], atol=1e-6)
        assert _rot_angle_rad(r_foot, pose.foot_rot[i]) < 1e-6
        if sole_site >= 0:
            sole = r_pelvis.T @ (data.site_xpos[sole_site] - data.xpos[pelvis])
            np.testing.assert_allclose(sole, pose.sole_m[i], atol=1e-6)
        if imu_site >= 0:  # the IMU frame is upside down on the pelvis
            r_imu = data.site_xmat[imu_site].reshape(3, 3)
            assert _rot_angle_rad(kin.imu_to_pelvis_rot(jnp.asarray(r_imu)), r_pelvis) < 1e-6
