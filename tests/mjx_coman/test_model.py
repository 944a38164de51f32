"""The generated MJCF against the CAD tables and the brief's dimensions."""

import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjx_coman
from mjx_coman import mjcf
from mjx_coman.actuators import JOINT_NAMES, SEA_MASK


@pytest.fixture(scope="module")
def model():
    return mjx_coman.load_model()


@pytest.fixture(scope="module")
def data(model):
    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    return d


def test_regenerating_gives_the_committed_files(tmp_path):
    coman, scene = mjcf.write_assets(tmp_path)
    assert coman.read_text() == (mjcf.ASSETS_DIR / "coman.xml").read_text()
    assert scene.read_text() == (mjcf.ASSETS_DIR / "scene.xml").read_text()


def test_loads_in_mujoco_and_mjx(model):
    assert (model.nq, model.nv, model.nu) == (30, 29, 23)
    mx = mjx.put_model(model)
    assert mx.nv == 29


def test_joint_and_actuator_order_matches_qpos(model):
    names = tuple(model.joint(i).name for i in range(1, model.njnt))
    assert names == JOINT_NAMES
    assert [int(model.actuator_trnid[i, 0]) for i in range(model.nu)] == list(range(1, 24))


def test_masses_match_the_table(model):
    links = mjcf.read_links()
    assert model.body_mass.sum() == pytest.approx(28.8934, abs=1e-3)
    for name, link in links.items():
        assert model.body(name).mass[0] == pytest.approx(link["mass"], rel=1e-7)


def test_inertias_are_physical(model):
    for b in range(1, model.nbody):
        i = np.sort(model.body_inertia[b])
        assert i[0] > 0 and i[0] + i[1] >= i[2] * (1 - 1e-9)


def test_fix_inertia_repairs_a_bad_tensor():
    bad = np.diag([1.0, 1.0, 3.0])  # violates the triangle inequality
    fixed, changed = mjcf.fix_inertia(bad)
    w = np.linalg.eigvalsh(fixed)
    assert changed and w[0] + w[1] >= w[2] - 1e-12 and w[2] == pytest.approx(3.0)
    good = np.diag([1.0, 2.0, 2.5])
    assert not mjcf.fix_inertia(good)[1]


@pytest.mark.parametrize("side,sign", [("r", -1), ("l", 1)])
def test_foot_geometry(data, side, sign):
    ankle = data.site(f"{side}_ankle").xpos
    sole = data.site(f"{side}_sole").xpos
    hip_z = data.body("Waist").xpos[2]
    assert hip_z - sole[2] == pytest.approx(0.5168, abs=1e-4)
    assert ankle[2] - sole[2] == pytest.approx(0.09, abs=1e-9)
    assert ankle[2] - data.site(f"{side}_ft").xpos[2] == pytest.approx(0.065, abs=1e-9)
    assert sole[1] == pytest.approx(sign * 0.0726, abs=1e-9)
    toe = data.site(f"{side}_foot_upper_left").xpos
    heel = data.site(f"{side}_foot_lower_right").xpos
    assert toe - heel == pytest.approx([0.20, 0.10, 0.0], abs=1e-9)
    assert toe[0] - ankle[0] == pytest.approx(0.13, abs=1e-9)


def test_waist_roll_axis_is_tilted_20_degrees(model):
    axis = model.joint("WaistLat").axis
    assert np.degrees(np.arctan2(axis[2], axis[0])) == pytest.approx(20.0, abs=0.01)


def test_only_feet_collide_through_pairs(model):
    assert model.npair == 8
    assert np.all(model.geom_contype == 0) and np.all(model.geom_conaffinity == 0)
    floor = model.geom("floor").id
    assert set(model.pair_geom1) == {floor}


def test_sea_joints_have_small_armature_rigid_joints_the_rotor(model):
    arm = model.dof_armature[6:]
    assert np.allclose(arm[SEA_MASK], mjcf.LINK_ARMATURE_KGM2)
    assert np.allclose(arm[~SEA_MASK], mjcf.ROTOR_INERTIA_NMS2_PER_RAD)
