"""Tests of the time-projection open-loop blocks: seed 000, eq. 21-25 and the 3LP -> joint targets."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp.gait import nominal_state, periodic_gait
from jaxlp.presets import get_params
from mjx_coman import kinematics as kin
from mjx_coman.actuators import JOINT_INDEX, JOINT_NAMES, NU, default_kp_v_per_rad
from mjx_coman.env import standing_posture
from mjx_coman.controllers.time_projection import open_loop as ol

STEP_TIME_S = 0.4
STEP_WIDTH_M = 0.25
N_TIMES = 21
POS_TOL_M = 1e-5
SMALL_TOL = 1e-6
ANGLE_TOL_RAD = 1e-5
PHASES = [1.0, -1.0]
SPEEDS_MPS = [0.0, 0.2, -0.1]


@pytest.fixture(scope="module")
def setup():
    params = get_params("coman-mjcf")
    height = ol.crouched_pelvis_height_m(0.4)
    posture = jnp.asarray(standing_posture(0.4)[0], dtype=jnp.result_type(float))
    gaits = {v: periodic_gait(params, STEP_TIME_S, v, STEP_WIDTH_M) for v in SPEEDS_MPS}
    times = jnp.linspace(0.0, STEP_TIME_S, N_TIMES)
    return params, height, posture, gaits, times


@pytest.fixture(scope="module")
def fns(setup):
    """Jitted, vmapped over (time, phase sign) with the gait as an argument: compiled once per module."""
    params, height, posture, _, _ = setup

    def both(gait, t, d, bounce=False):
        c = ol.cartesian_targets(params, gait, t, d, height, lateral_bounce=bounce)
        return c, ol.joint_targets(c, d, posture)

    batched = jax.vmap(both, in_axes=(None, 0, 0))
    return dict(
        both=jax.jit(batched),
        bounce=jax.jit(jax.vmap(lambda g, t, d: both(g, t, d, True), in_axes=(None, 0, 0))),
        voltages=jax.jit(jax.vmap(ol.command_voltages, in_axes=(None, 0, 0, None, 0, None, None))),
    )


def _run(fns, setup, speed, d, key="both"):
    _, _, _, gaits, times = setup
    return fns[key](gaits[speed], times, jnp.full_like(times, d))


@pytest.mark.parametrize("d", PHASES)
def test_lift_and_roll_vanish_at_ends_and_peak_mid_phase(fns, setup, d):
    c, _ = _run(fns, setup, 0.2, d)
    roll, lift = np.asarray(c.roll_rad), np.asarray(c.lift_m)
    for i in (0, N_TIMES - 1):  # t = 0 and t = T
        assert abs(roll[i]) < SMALL_TOL and abs(lift[i]) < SMALL_TOL
        # feet both on the ground, pelvis at the crouched height above them
        assert abs(c.swing_m[i, 2] - c.stance_m[i, 2]) < SMALL_TOL
        assert abs(c.stance_m[i, 2] + setup[1]) < SMALL_TOL
    mid = N_TIMES // 2  # t = T / 2
    assert lift[mid] == pytest.approx(0.01, abs=SMALL_TOL)
    assert roll[mid] == pytest.approx(0.1 * d, abs=SMALL_TOL)
    assert np.all(lift >= -SMALL_TOL) and np.all(lift <= 0.01 + SMALL_TOL)
    assert np.all(d * roll >= -SMALL_TOL) and np.all(np.abs(roll) <= 0.1 + SMALL_TOL)
    # total swing-foot height above the stance foot: eq. 23 plus the swing hip's rise (Figure 8)
    rise = float(c.swing_m[mid, 2] - c.stance_m[mid, 2])
    assert rise == pytest.approx(0.01 + 2 * kin.HIP_HALF_WIDTH_M * np.sin(0.1), abs=SMALL_TOL)
    assert 0.023 < rise < 0.026  # the seed's "about 2.4 cm in total"


@pytest.mark.parametrize("d", PHASES)
def test_roll_raises_the_swing_hip(fns, setup, d):
    c, _ = _run(fns, setup, 0.2, d)
    mid = N_TIMES // 2
    swing_hip = kin.rot_x(c.roll_rad[mid]) @ jnp.array([0.0, d * kin.HIP_HALF_WIDTH_M, 0.0])
    assert float(swing_hip[2]) > 0.007  # swing-side hip above the pelvis point


@pytest.mark.parametrize("speed", SPEEDS_MPS)
@pytest.mark.parametrize("d", PHASES)
def test_joint_targets_reproduce_cartesian_targets(fns, setup, speed, d):
    c, q = _run(fns, setup, speed, d)
    q = np.asarray(q)
    assert q.shape == (N_TIMES, NU) and np.all(np.isfinite(q))
    legs = {s: [JOINT_INDEX[s[0].upper() + n] for n in ol.LEG_JOINTS] for s in ("left", "right")}
    fk = {s: jax.vmap(lambda a, s=s: kin.leg_fk(a, s))(jnp.asarray(q[:, legs[s]])) for s in legs}
    rot = jax.vmap(kin.rot_x)(c.roll_rad)
    left = jnp.einsum("nij,nj->ni", rot, fk["left"].foot_point_m)
    right = jnp.einsum("nij,nj->ni", rot, fk["right"].foot_point_m)
    swing, stance = (left, right) if d > 0 else (right, left)
    np.testing.assert_allclose(swing, c.swing_m, atol=POS_TOL_M)
    np.testing.assert_allclose(stance, c.stance_m, atol=POS_TOL_M)
    # flat feet in the heading frame
    for s in legs:
        feet_rot = jnp.einsum("nij,njk->nik", rot, fk[s].foot_rot)
        np.testing.assert_allclose(feet_rot, np.broadcast_to(np.eye(3), feet_rot.shape), atol=ANGLE_TOL_RAD)
    # within the joint limits, stance knee still bent (the IK does not clamp) at the seed's speeds
    for s, lim in (("left", kin.LEFT_LEG_LIMITS_RAD), ("right", kin.RIGHT_LEG_LIMITS_RAD)):
        assert np.all(q[:, legs[s]] >= lim[0]) and np.all(q[:, legs[s]] <= lim[1])
    assert q[:, [JOINT_INDEX["LKneeSag"], JOINT_INDEX["RKneeSag"]]].min() > 0.05
    # waist and arms stay at the standing posture
    others = [i for i, n in enumerate(JOINT_NAMES) if i not in legs["left"] + legs["right"]]
    np.testing.assert_array_equal(q[:, others], np.broadcast_to(np.asarray(setup[2])[others], (N_TIMES, len(others))))


def test_in_place_gait_is_symmetric_under_the_pelvis(fns, setup):
    (cl, ql), (cr, qr) = _run(fns, setup, 0.0, 1.0), _run(fns, setup, 0.0, -1.0)
    # sagittal: both feet right under the pelvis point all phase long
    for c in (cl, cr):
        assert np.abs(np.asarray(c.swing_m[:, 0])).max() < SMALL_TOL
        assert np.abs(np.asarray(c.stance_m[:, 0])).max() < SMALL_TOL
        # time-symmetric phase: targets at t and T - t agree
        np.testing.assert_allclose(c.swing_m, c.swing_m[::-1], atol=SMALL_TOL)
    # feet laterally symmetric about the pelvis at the phase ends
    np.testing.assert_allclose(cl.swing_m[0, 1], STEP_WIDTH_M / 2, atol=SMALL_TOL)
    np.testing.assert_allclose(cl.stance_m[0, 1], -STEP_WIDTH_M / 2, atol=SMALL_TOL)
    # right-swing phase is the mirror image of the left-swing phase
    mirror = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(cr.swing_m, cl.swing_m * mirror, atol=SMALL_TOL)
    np.testing.assert_allclose(cr.stance_m, cl.stance_m * mirror, atol=SMALL_TOL)
    np.testing.assert_allclose(cr.roll_rad, -cl.roll_rad, atol=SMALL_TOL)
    flip = np.array([1.0, -1.0, -1.0, 1.0, -1.0, 1.0])  # roll and yaw angles change sign
    left = [JOINT_INDEX["L" + n] for n in ol.LEG_JOINTS]
    right = [JOINT_INDEX["R" + n] for n in ol.LEG_JOINTS]
    np.testing.assert_allclose(np.asarray(qr)[:, right], np.asarray(ql)[:, left] * flip, atol=ANGLE_TOL_RAD)


@pytest.mark.parametrize("d", PHASES)
def test_lateral_bounce_flag(fns, setup, d):
    params, _, _, gaits, times = setup
    c, _ = _run(fns, setup, 0.2, d)
    cb, qb = _run(fns, setup, 0.2, d, key="bounce")
    # no sway: the pelvis stays midway between the feet lines, up to the roll about the stance hip
    roll_shift = d * kin.HIP_HALF_WIDTH_M * (1 - jnp.cos(c.roll_rad))
    np.testing.assert_allclose(c.pelvis_m[:, 1], d * STEP_WIDTH_M / 2 - roll_shift, atol=SMALL_TOL)
    p_3lp = jax.vmap(lambda t: nominal_state(params, gaits[0.2], t, d)[1, 1])(times)
    np.testing.assert_allclose(cb.pelvis_m[:, 1], p_3lp, atol=1e-3)  # 3LP sway (up to the roll's shift)
    assert float(jnp.ptp(cb.pelvis_m[:, 1])) > 0.02  # the 3LP bounce is a few cm
    np.testing.assert_allclose(cb.swing_m[:, 0], c.swing_m[:, 0], atol=SMALL_TOL)  # sagittal unchanged
    assert np.all(np.isfinite(np.asarray(qb)))


def test_hip_switch_gamma():
    T = STEP_TIME_S
    t1 = 0.2 * T
    assert float(ol.hip_switch_gamma(0.0, T, False)) == pytest.approx(1.0)
    assert float(ol.hip_switch_gamma(0.0, T, True)) == pytest.approx(0.0)
    assert float(ol.hip_switch_gamma(t1, T, False)) == pytest.approx(np.exp(-1.0), abs=SMALL_TOL)
    assert float(ol.hip_switch_gamma(t1, T, True)) == pytest.approx(1 - np.exp(-1.0), abs=SMALL_TOL)
    ts = jnp.linspace(0.0, T, 11)
    g_stance = jax.vmap(lambda t: ol.hip_switch_gamma(t, T, False))(ts)
    g_swing = jax.vmap(lambda t: ol.hip_switch_gamma(t, T, jnp.array(True)))(ts)
    np.testing.assert_allclose(g_stance + g_swing, 1.0, atol=SMALL_TOL)
    assert np.all(np.diff(np.asarray(g_stance)) <= 0) and float(g_stance[-1]) < 1e-9


@pytest.mark.parametrize("gamma", [0.0, 0.3, 1.0])
def test_hip_voltage(gamma):
    kd, des, act, pitch = 100.0, 0.2, 0.05, 0.03
    v = float(ol.hip_voltage(kd, des, act, pitch, gamma))
    assert v == pytest.approx(kd * (gamma * (des - act) + (1 - gamma) * pitch), rel=1e-6)
    if gamma == 0.0:  # stance hip: forward lean -> hip extension (positive voltage) uprights the torso
        assert v > 0
        assert float(ol.hip_voltage(kd, des, act, -0.1, 0.0)) < 0  # backward lean -> hip flexion


@pytest.mark.parametrize("mu", [0.02, 0.05])
def test_knee_compensation(mu):
    mg = 230.0
    left, right = ol.knee_compensation(0.0, mg, mg, mu, 2 * mu)
    assert float(left) == 0.0
    assert float(right) == pytest.approx(-2 * mu, rel=1e-6)
    left, right = ol.knee_compensation(-mg / 2, mg / 4, mg, mu, mu)  # |F| in eq. 21
    assert float(left) == pytest.approx(-mu / 2, rel=1e-6)
    assert float(right) == pytest.approx(-mu / 4, rel=1e-6)


def test_position_and_command_voltages(fns, setup):
    _, _, posture, _, times = setup
    kp = jnp.asarray(default_kp_v_per_rad(), posture.dtype)
    rng = np.random.default_rng(0)
    q_des = posture + jnp.asarray(rng.normal(0, 0.05, (N_TIMES, NU)), posture.dtype)
    q_act = jnp.broadcast_to(posture, q_des.shape)
    pitch = 0.02
    v = np.asarray(fns["voltages"](kp, q_des, q_act, pitch, times, STEP_TIME_S, 1.0))
    eq25 = np.asarray(ol.position_voltage(kp, q_des, q_act))
    hips = [JOINT_INDEX["LHipSag"], JOINT_INDEX["RHipSag"]]
    others = [i for i in range(NU) if i not in hips]
    np.testing.assert_allclose(v[:, others], eq25[:, others], rtol=1e-6)
    assert default_kp_v_per_rad()[JOINT_INDEX["LAnkLat"]] == 10.0
    # t = 0 of a left-swing phase: the left (swing) hip holds the torso, the right (stance) tracks its angle
    assert v[0, JOINT_INDEX["LHipSag"]] == pytest.approx(100.0 * pitch, rel=1e-5)
    assert v[0, JOINT_INDEX["RHipSag"]] == pytest.approx(eq25[0, JOINT_INDEX["RHipSag"]], rel=1e-5)
    # late in the phase the roles have switched
    assert v[-1, JOINT_INDEX["LHipSag"]] == pytest.approx(eq25[-1, JOINT_INDEX["LHipSag"]], rel=1e-5, abs=1e-6)
    assert v[-1, JOINT_INDEX["RHipSag"]] == pytest.approx(100.0 * pitch, rel=1e-5)


def test_vmap_matches_single_calls(fns, setup):
    params, height, posture, gaits, times = setup
    c, q = _run(fns, setup, 0.2, -1.0)
    for i in (0, 7, N_TIMES - 1):
        ci = ol.cartesian_targets(params, gaits[0.2], times[i], -1.0, height)
        qi = ol.joint_targets(ci, -1.0, posture)
        np.testing.assert_allclose(c.swing_m[i], ci.swing_m, atol=SMALL_TOL)
        np.testing.assert_allclose(q[i], qi, atol=ANGLE_TOL_RAD)
    # mixed phase signs within one batch
    ds = jnp.where(jnp.arange(N_TIMES) % 2 == 0, 1.0, -1.0)
    _, qm = fns["both"](gaits[0.2], times, ds)
    np.testing.assert_allclose(qm[1], q[1], atol=ANGLE_TOL_RAD)
