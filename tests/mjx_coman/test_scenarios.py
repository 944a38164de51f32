"""Scenarios (mjx_coman.scenarios): each has its physical effect, checked against physics.

* payload: the same point mass welded to the torso as a body of its own in MuJoCo C (MjSpec) gives the same
  mass matrix, total mass, CoM and invweights as the parallel-axis fields, and MJX the same CoM;
* terrain: heights against MuJoCo's own ray casts, and spheres resting on the height field and on a stair in
  MJX against MuJoCo C (and against the analytic height, offset by the plane's penetration);
* delay: a command reaches the motor boards k ticks later;
* one compiled batch of 1 s walks of the default controller under several scenarios: momentum balance with
  rotated gravity (the ground reaction impulse plus gravity's equals the momentum change), the IMU measuring
  relative to gravity, the judge's tilt, and the noise levels over every tick.
"""

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjx_coman import controllers, load_model, model_path, mjcf, rollout as ro, scenarios as sc, sensors
from mjx_coman import ground_truth as gt
from mjx_coman.actuators import MAX_DELAY_TICKS, delay_command, init_actuator_state, NU
from mjx_coman.env import standing_posture
from mjx_coman.kinematics import quat_to_rot
from mjx_coman.scenarios import terrain as T

TORSO = "DWYTorso"
GROUND = np.array([1, 0, 0, 0, 0, 0], np.uint8)  # geom group 0: floor and terrain (the robot's are 1 and 3)


def _pose(m, d, tilt=True):
    q, root = standing_posture()
    d.qpos[:7], d.qpos[7:] = root, q
    if tilt:  # any orientation: the mass matrix's rotational part sees the whole inertia
        d.qpos[3:7] = np.array([0.9, 0.1, 0.2, 0.3]) / np.linalg.norm([0.9, 0.1, 0.2, 0.3])
    mujoco.mj_forward(m, d)


def _welded_payload(body, kg, offset):
    """The payload as a point-mass body welded to ``body`` (MjSpec), independent of add_point_mass."""
    m0 = load_model()
    b = m0.body(body).id
    spec = mujoco.MjSpec.from_file(str(model_path()))
    spec.body(body).add_body(name="payload", pos=m0.body_ipos[b] + np.asarray(offset), ipos=[0, 0, 0], mass=kg,
                             inertia=[1e-12] * 3, explicitinertial=True)
    return spec.compile()


@pytest.mark.parametrize("body,kg,offset", [(TORSO, 1.0, (-0.01, 0.0, 0.0)), (TORSO, 2.5, (0.05, -0.03, 0.1)),
                                            ("LThighUpLeg", 0.7, (0.0, 0.04, -0.02))])
def test_payload_is_a_welded_point_mass_in_mujoco_c(body, kg, offset):
    ma = sc.apply_payload(load_model(), body, kg, offset)
    mb = _welded_payload(body, kg, offset)
    da, db = mujoco.MjData(ma), mujoco.MjData(mb)
    _pose(ma, da)
    _pose(mb, db)
    full_a, full_b = np.zeros((ma.nv, ma.nv)), np.zeros((mb.nv, mb.nv))
    mujoco.mj_fullM(ma, da, full_a)
    mujoco.mj_fullM(mb, db, full_b)
    np.testing.assert_allclose(full_a, full_b, atol=1e-9)  # parallel-axis inertia = the welded body's
    np.testing.assert_allclose(da.qfrc_bias, db.qfrc_bias, atol=1e-9)  # gravity and Coriolis alike
    np.testing.assert_allclose(da.subtree_com[0], db.subtree_com[0], atol=1e-12)
    assert ma.body_subtreemass[0] == pytest.approx(load_model().body_subtreemass[0] + kg)
    names = [ma.body(i).name for i in range(ma.nbody)]
    ids = [mb.body(n).id for n in names]
    np.testing.assert_allclose(ma.body_subtreemass, mb.body_subtreemass[ids], rtol=1e-12)
    np.testing.assert_allclose(ma.dof_invweight0, mb.dof_invweight0, rtol=1e-8)
    others = [i for i, n in enumerate(names) if n != body]  # the loaded body's own CoM moved in ma, not in mb
    np.testing.assert_allclose(ma.body_invweight0[others], mb.body_invweight0[[ids[i] for i in others]], rtol=1e-8)


@pytest.fixture(scope="module")
def mjx_com():
    return jax.jit(lambda model, qpos: mjx.com_pos(model, mjx.kinematics(model, mjx.make_data(model).replace(
        qpos=qpos))).subtree_com[0])


def test_payload_reaches_mjx_as_in_mujoco_c(mjx_com):
    """The env's batched payload fields: MJX's CoM and masses equal MuJoCo C's with the welded body."""
    base = ro.walking_env_params()
    kgs, offs = (0.0, 1.0, 3.0), ((0.0, 0.0, 0.0), (-0.01, 0.0, 0.0), (0.1, 0.05, -0.05))
    params, axes = sc.batched_env_params(base, [sc.Scenario(payload_kg=k, payload_com_m=o) for k, o in zip(kgs, offs)])
    q, root = standing_posture()
    qpos = jnp.asarray(np.concatenate([root, q]), params.model.body_mass.dtype)
    coms = []
    for i in range(3):
        p = sc.select(params, axes, i)
        coms.append(np.asarray(mjx_com(p.model, qpos)))
        ref = _welded_payload(TORSO, kgs[i], offs[i]) if kgs[i] else load_model()
        d = mujoco.MjData(ref)
        _pose(ref, d, tilt=False)
        np.testing.assert_allclose(coms[-1], d.subtree_com[0], atol=2e-6)
        assert float(p.model.body_subtreemass[0]) == pytest.approx(ref.body_subtreemass[0], rel=1e-6)
    assert np.linalg.norm(coms[2] - coms[0]) > 5e-3  # a real shift (3 kg 11 cm off the torso CoM)


def test_heights_are_mujocos_own_ray_casts():
    rng = np.random.default_rng(0)
    for terrain in ("rough:5", "rough:2:7", "stairs:5", "stairs:12", "stairs:-7"):
        t = sc.parse_terrain(terrain)
        m = sc.scene_model(terrain)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        pts = np.column_stack([rng.uniform(-1.5, 4.5, 300), rng.uniform(-0.9, 0.9, 300)])
        ray = []
        for x, y in pts:
            gid = np.zeros(1, np.int32)
            dist = mujoco.mj_ray(m, d, np.array([x, y, 1.0]), np.array([0.0, 0.0, -1.0]), GROUND, 1, -1, gid)
            ray.append(1.0 - dist)
        h = np.asarray(T.terrain_height_m(terrain, jnp.asarray(pts[:, 0]), jnp.asarray(pts[:, 1])))
        tol = 2e-4 if t.kind == "rough" else 1e-6  # MuJoCo triangulates the height field's cells
        np.testing.assert_allclose(h, ray, atol=tol)
        if t.kind == "rough":
            assert np.max(np.abs(ray)) <= t.height_m and np.max(np.abs(ray)) > 0.7 * t.height_m
            xs, ys, field = T.rough_heights_m(t)
            start = (np.abs(xs)[None, :] <= 0.3) & (np.abs(ys)[:, None] <= 0.25)
            assert np.all(field[start] == 0.0)  # the robot starts on flat ground
        elif t.height_m > 0:
            assert max(ray) == pytest.approx(T.STAIR_STEPS * t.height_m)
        else:  # down: the start platform at 0, the floor a staircase lower
            assert max(ray) == pytest.approx(0.0, abs=1e-9) and min(ray) == pytest.approx(T.STAIR_STEPS * t.height_m)


def _support_xml(points):
    """A sphere (the foot's; on slide joints, so that it cannot roll) on each terrain and one on a plane."""
    rough, stairs = T.scene_parts(sc.parse_terrain("rough:5")), T.scene_parts(sc.parse_terrain("stairs:8"))
    r = mjcf.CONTACT_SPHERE_RADIUS_M
    bodies = []
    for name, (x, y, z) in points.items():
        slides = "".join(f'<joint type="slide" axis="{a}"/>' for a in ("1 0 0", "0 1 0", "0 0 1"))
        bodies.append(f'<body name="{name}" pos="{x} {y} {z}">{slides}<geom name="{name}" type="sphere" '
                      f'size="{r}" mass="0.2" contype="0" conaffinity="0"/></body>')
    pairs = ['<pair geom1="rough" geom2="on_rough"/>', '<pair geom1="plane" geom2="on_plane"/>']
    pairs += [f'<pair geom1="{g}" geom2="on_stair"/>' for g in stairs["contact_geoms"]]
    return f"""<mujoco>
  <option timestep="0.001" integrator="Euler" solver="Newton" iterations="4" ls_iterations="8" cone="pyramidal">
    <flag eulerdamp="disable"/></option>
  <asset>{rough["assets"][0]}</asset>
  <worldbody>
    {rough["terrain_geoms"][0]}
    <geom name="plane" type="plane" size="0 0 0.05" pos="0 -10 0" contype="0" conaffinity="0"/>
    <body name="stairs" pos="0 10 0">{"".join(stairs["terrain_geoms"])}</body>
    {"".join(bodies)}
  </worldbody>
  <contact>{"".join(pairs)}</contact>
</mujoco>"""


def test_foot_spheres_rest_on_the_terrain_at_its_height_in_mjx_as_in_c():
    xy_rough, xy_stair = (1.37, -0.62), (T.STAIR_START_X_M + 2.5 * T.STAIR_TREAD_M, 0.1)
    h_rough = float(T.terrain_height_m("rough:5", *xy_rough))
    h_stair = 3 * 0.08
    pts = {"on_rough": (*xy_rough, h_rough + 0.011), "on_stair": (xy_stair[0], 10 + xy_stair[1], h_stair + 0.011),
           "on_plane": (0.0, -10.0, 0.011)}
    m = mujoco.MjModel.from_xml_string(_support_xml(pts))
    field = T.rough_heights_m(sc.parse_terrain("rough:5"))[2]
    m.hfield_data[:] = ((field + 0.05) / 0.1).ravel()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    n = 300
    for _ in range(n):
        mujoco.mj_step(m, d)
    mx = mjx.put_model(m)
    dx = jax.jit(lambda dd: jax.lax.scan(lambda c, _: (mjx.step(mx, c), None), dd, None, length=n)[0])(
        mjx.make_data(mx).replace(qpos=jnp.asarray(m.qpos0, jnp.float32)))
    ids = [m.body(name).id for name in pts]
    zc = d.xpos[ids, 2]
    zx = np.asarray(dx.xpos)[ids, 2]
    np.testing.assert_allclose(zx, zc, atol=5e-5)  # MJX supports them where MuJoCo C does
    on_plane = zc[2]  # radius minus the soft contact's penetration under the same weight
    assert 0.009 < on_plane < 0.0101
    xr, yr = d.xpos[ids[0], :2]
    gx = (T.terrain_height_m("rough:5", xr + 1e-3, yr) - T.terrain_height_m("rough:5", xr - 1e-3, yr)) / 2e-3
    gy = (T.terrain_height_m("rough:5", xr, yr + 1e-3) - T.terrain_height_m("rough:5", xr, yr - 1e-3)) / 2e-3
    cos = 1.0 / np.sqrt(1.0 + float(gx) ** 2 + float(gy) ** 2)  # the surface normal's tilt
    assert zc[0] == pytest.approx(float(T.terrain_height_m("rough:5", xr, yr)) + on_plane / cos, abs=3e-4)
    assert zc[1] == pytest.approx(h_stair + on_plane, abs=2e-5)
    # The force on each sphere, decoded as the sensors do (the stair pair has the sphere as geom1): its weight.
    force, _ = sensors.contact_wrenches_world(dx)
    for k, name in enumerate(pts):
        w = np.asarray(sensors.contact_signs(dx, (m.geom(name).id,)))
        np.testing.assert_allclose((w[:, None] * np.asarray(force)).sum(0), [0.0, 0.0, 0.2 * 9.81], atol=0.02,
                                   err_msg=name)


def test_delay_reaches_the_motor_boards_k_ticks_later():
    base = ro.walking_env_params()
    env = sc.scenario_env_params(base, sc.Scenario(delay_ms=10))
    k = int(env.actuator.delay_ticks)
    assert k == int(base.actuator.delay_ticks) + 5 == 15
    state = init_actuator_state(jnp.zeros(NU), jnp.zeros(NU), jnp.zeros(NU))
    out = []
    for tick in range(30):
        state, delayed = delay_command(env.actuator, state, jnp.full(NU, float(tick >= 3)))[:2]
        out.append(float(delayed[0]))
    assert out.index(1.0) == 3 + k


@pytest.mark.parametrize("kw,word", [
    (dict(payload_kg=-1.0), "payload_kg"), (dict(payload_kg=float("nan")), "payload_kg"),
    (dict(payload_body="Head"), "Head"), (dict(payload_com_m=(0.0, 0.1)), "payload_com_m"),
    (dict(payload_com_m=(0.0, 0.0, 2.0)), "payload_com_m"), (dict(slope_deg=45.0), "slope_deg"),
    (dict(terrain="ice"), "ice"), (dict(terrain="rough:0"), "rough:0"), (dict(terrain="stairs:30"), "stairs:30"),
    (dict(terrain="stairs:0"), "stairs:0"), (dict(terrain="stairs:-25"), "stairs:-25"),
    (dict(terrain="rough:2:x"), "x"), (dict(imu_noise_deg=-3.0), "imu_noise_deg"),
    (dict(joint_noise_deg=float("inf")), "joint_noise_deg"), (dict(delay_ms=-1.0), "delay_ms"),
    (dict(delay_ms=50.0), "delay_ms"), (dict(slope_deg="5"), "slope_deg"), (dict(actuator="hydraulic"), "hydraulic"),
])
def test_bad_scenarios_raise_naming_the_value(kw, word):
    with pytest.raises(ValueError, match=word):
        sc.scenario_env_params(ro.walking_env_params(), sc.Scenario(**kw))


def test_the_actuator_axis_picks_each_rows_torque_loop():
    from mjx_coman.actuators import TORQUE_IDEAL, TORQUE_SEA

    base = ro.plant_env_params("torque-ideal")
    params, axes = sc.batched_env_params(base, [sc.Scenario(), sc.Scenario(actuator="sea"),
                                                sc.Scenario(actuator="ideal", delay_ms=10.0)])
    assert axes.actuator.torque_loop == 0
    assert np.asarray(params.actuator.torque_loop).tolist() == [int(base.actuator.torque_loop), TORQUE_SEA, TORQUE_IDEAL]
    assert int(sc.select(params, axes, 1).actuator.torque_loop) == TORQUE_SEA


def test_one_batch_shares_one_terrain():
    with pytest.raises(ValueError, match="terrain differs"):
        sc.batched_env_params(ro.walking_env_params(), [sc.Scenario(), sc.Scenario(terrain="stairs:5")])
    assert gt.judge_on(sc.Scenario(terrain="rough:2.0")).terrain == "rough:2"
    assert gt.judge_on("flat") == gt.Judge()


# --- one compiled batch of 1 s walks under several scenarios -------------------------------------------------

ROWS = [sc.Scenario(imu_noise_deg=0.0), sc.Scenario(payload_kg=1.0, payload_com_m=(-0.01, 0.0, 0.0)),
        sc.Scenario(slope_deg=5.0, imu_noise_deg=0.0), sc.Scenario(slope_deg=-5.0, imu_noise_deg=0.0),
        sc.Scenario(imu_noise_deg=3.0, joint_noise_deg=1.0), sc.Scenario(delay_ms=10.0)]


def _record(state):
    d = state.env.data
    force, _ = sensors.contact_wrenches_world(d)
    on_robot = sensors.foot_contact_weights(d).sum(0)
    return dict(com=gt.com_m(d), grf=(on_robot[:, None] * force).sum(0), imu=state.env.readings.imu_quat,
                true=sensors.pelvis_quat_gravity(d), pelvis=d.xquat[sensors.model_ids()["pelvis_body"]],
                link=state.env.readings.link_angle_rad, q=d.qpos[7:], tilt=gt.tilt_rad(d))


@pytest.fixture(scope="module")
def walks():
    ctrl, cfg = controllers.load("time-projection", {})
    params, axes = sc.batched_env_params(ro.walking_env_params(), ROWS)
    n = len(ROWS)
    fn = ro.batched_walk(ctrl, ro.WalkSpec(seconds=1.0), ro.SaveAt(_record, every=1), env_axes=axes)
    pushes = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,) + x.shape), ro.no_push())
    r = fn(cfg, params, pushes, jax.random.split(jax.random.PRNGKey(0), n), controllers.joystick(0.0))
    return params, jax.tree_util.tree_map(np.asarray, r)


def test_scenario_walks_stay_up_for_a_second(walks):
    params, r = walks
    assert not r.fell.any() and not r.nan.any()
    assert params.model.body_quat.shape[1] == load_model().nbody + 1  # the slopes brought the gravity frame


def test_ground_reaction_balances_rotated_gravity(walks):
    """Newton on the whole robot: sum F dt + M g T = M (v_T - v_0), and the steady part of F points along -g."""
    params, r = walks
    dt = 0.002
    mass = np.asarray(params.model.body_subtreemass[:, 0], float)
    g = np.asarray(params.model.opt.gravity, float)
    for i, s in enumerate(ROWS):
        com, grf = r.saved["com"][i].astype(float), r.saved["grf"][i].astype(float)
        t = len(com) * dt
        dp = mass[i] * (com[-1] - com[-2]) / dt  # it starts at rest
        np.testing.assert_allclose(grf.sum(0) * dt + mass[i] * g[i] * t, dp, atol=0.01 * mass[i] * 9.81 * t)
        steady = grf.mean(0) - dp / t
        up = -g[i] / np.linalg.norm(g[i])
        assert np.degrees(np.arccos(np.clip(steady @ up / np.linalg.norm(steady), -1, 1))) < 0.3
        assert np.degrees(np.arccos(-g[i][2] / np.linalg.norm(g[i]))) == pytest.approx(abs(s.slope_deg), abs=1e-4)
    assert mass[1] == pytest.approx(mass[0] + 1.0, rel=1e-6)


def test_imu_measures_relative_to_gravity(walks):
    """On a slope the IMU sees the robot tilted: gravity in the pelvis frame from the reading equals the
    model's gravity rotated into the pelvis frame; the judge's tilt is measured from gravity too."""
    params, r = walks
    g = np.asarray(params.model.opt.gravity, float)
    for i, s in enumerate(ROWS):
        if s.imu_noise_deg != 0.0:
            continue
        for k in (0, 200, 499):
            r_read = np.asarray(quat_to_rot(jnp.asarray(r.saved["imu"][i, k])))
            r_world = np.asarray(quat_to_rot(jnp.asarray(r.saved["pelvis"][i, k])))
            g_hat = g[i] / np.linalg.norm(g[i])
            np.testing.assert_allclose(r_read.T @ [0, 0, -1], r_world.T @ g_hat, atol=2e-4)
            assert r.saved["tilt"][i, k] == pytest.approx(np.arccos(np.clip(-(r_world[:, 2] @ g_hat), -1, 1)), abs=2e-3)
        pitch = np.asarray(sensors.quat_to_rpy(jnp.asarray(r.saved["imu"][i, 0])))[1]
        world_pitch = np.asarray(sensors.quat_to_rpy(jnp.asarray(r.saved["pelvis"][i, 0])))[1]
        assert np.degrees(pitch - world_pitch) == pytest.approx(-s.slope_deg, abs=0.05)  # standing back on the slope
        assert np.degrees(r.saved["tilt"][i, 0]) == pytest.approx(abs(s.slope_deg), abs=0.3)


def _rotvec(q):
    w, v = q[..., :1], q[..., 1:]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return 2 * np.arctan2(n, w) * v / np.maximum(n, 1e-12)


def test_noise_levels_over_every_tick(walks):
    _, r = walks
    i = ROWS.index(sc.Scenario(imu_noise_deg=3.0, joint_noise_deg=1.0))
    joint = np.degrees(r.saved["link"][i] - r.saved["q"][i])
    assert joint.std() == pytest.approx(1.0, rel=0.05) and abs(joint.mean()) < 0.05
    quiet = np.degrees(r.saved["link"][0] - r.saved["q"][0])
    assert quiet.std() < 0.03  # the 12-bit quantum alone (0.088 deg / sqrt 12)
    true, read = r.saved["true"][i], r.saved["imu"][i]
    conj = true * np.array([1, -1, -1, -1])
    err = np.degrees(_rotvec(np.asarray(jax.vmap(sensors.quat_mul)(jnp.asarray(conj), jnp.asarray(read)))))
    np.testing.assert_allclose(err.std(0), 3.0, rtol=0.12)
