"""Tests of the time-projection controller: config, blocks (Figure 3), phase clock, telemetry, mirror symmetry."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp.filters import FOOTSTEP_TRUNCATION_RATIO
from mjx_coman.actuators import JOINT_INDEX, NU
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT, Observation, joystick
from mjx_coman.controllers.time_projection import config as cfg_mod
from mjx_coman.controllers.time_projection import controller as ctl
from mjx_coman.controllers.time_projection import estimation as est
from mjx_coman.controllers.time_projection.open_loop import LEFT_LEG_INDEX

MIRROR_TOL_RAD = 2e-5
LATERAL_JOINTS = ("HipLat", "HipYaw", "AnkLat")  # sign flips under the left/right mirror
LEG_JOINTS = ("HipSag", "HipLat", "HipYaw", "KneeSag", "AnkLat", "AnkSag")


@pytest.fixture(scope="module")
def params():
    from mjx_coman import controllers

    return controllers.default_config("time-projection")


params_fast = params  # the speed is the joystick's: one config for every speed
FAST_MPS = 0.2


@pytest.mark.parametrize("kwargs, name", [
    (dict(step_time_s=0.401), "step_time_s"),
    (dict(robot="nope"), "robot"),
    (dict(hold_adjustment=1.5), "hold_adjustment"),
    (dict(lqr_weight_scale=(1.0, 0.0, 1.0)), "lqr_weight_scale"),
    (dict(zeta="x"), "zeta"),
    (dict(zeta=0.0), "zeta"),
    (dict(zeta=1.5), "zeta"),
    (dict(deadzone=(0.01, 0.01, 0.1)), "deadzone"),
    (dict(deadzone=(0.01, -0.01, 0.1, 0.1)), "deadzone"),
    (dict(window=0), "window"),
    (dict(mu_left_rad=-0.01), "mu_left_rad"),
    (dict(footstep_gain=-1.0), "footstep_gain"),
    (dict(hip_switch=2.0), "hip_switch"),
    (dict(ankle_compliance=1.5), "ankle_compliance"),
    (dict(hip_attack=-0.1), "hip_attack"),
    (dict(step_width_m=-0.1), "step_width_m"),
])
def test_make_config_rejects_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        cfg_mod.make_config(**kwargs)


def test_settings_are_the_keywords_of_make_config():
    import inspect

    assert [s.name for s in cfg_mod.SETTINGS] == list(inspect.signature(cfg_mod.make_config).parameters)
    defaults = {k: v.default for k, v in inspect.signature(cfg_mod.make_config).parameters.items()}
    assert {s.name: s.default for s in cfg_mod.SETTINGS} == defaults


def test_params_hold_the_gait_tables(params, params_fast):
    n = params.ticks_per_step
    assert n == 200 and params.dt_s == pytest.approx(0.002)
    assert params.nominal_base.shape == (n + 1, 2, 6) and params.footstep_table.shape == (n, 4)
    # The sagittal gait is linear in the speed: the step length of the commanded speed is v T.
    q_end = ctl.nominal_at(params_fast, n, 10, 1.0, FAST_MPS)
    assert float(q_end[0, 0] - q_end[0, 2]) == pytest.approx(0.2 * 0.4, rel=1e-3)  # lands v T ahead of the stance foot
    assert float(params.max_adjustment_m) == pytest.approx(FOOTSTEP_TRUNCATION_RATIO * float(params.h1_m))
    # In place, the speed ramp does not matter and the sagittal nominal is zero.
    np.testing.assert_allclose(ctl.nominal_at(params, 57, 3, 1.0, 0.0)[0], 0.0, atol=1e-6)


@pytest.mark.parametrize("hold", [0.0, 1.0])
@pytest.mark.parametrize("tick", [0, 77, 199])
def test_zero_error_gives_zero_adjustment(params, hold, tick):
    p = params.replace(hold_adjustment=jnp.asarray(hold, params.h1_m.dtype))
    adj, _ = ctl.footstep_block(p, jnp.asarray(tick), jnp.zeros(4), jnp.asarray(0.0))
    assert float(adj) == 0.0
    lift, pitch, theta = ctl.lift_block(params, tick * 0.002, jnp.zeros(4), adj)
    assert float(lift) == 0.0 and float(pitch) == 0.0 and float(theta) == 0.0


def test_footstep_adjustment_follows_table_b_and_truncates(params):
    e = jnp.array([0.002, 0.004, -0.01, 0.03])
    for tick in (0, 60, 150):
        adj, _ = ctl.footstep_block(params, jnp.asarray(tick), e, jnp.asarray(0.0))
        assert float(adj) == pytest.approx(float(params.footstep_table[tick] @ e), rel=1e-5)
    # a forward pelvis error steps forward; a huge one is truncated at 0.35 h1
    big, _ = ctl.footstep_block(params, jnp.asarray(10), jnp.array([0.0, 1.0, 0.0, 3.0]), 0.0)
    assert float(big) == pytest.approx(float(params.max_adjustment_m), rel=1e-6)
    neg, _ = ctl.footstep_block(params, jnp.asarray(10), jnp.array([0.0, -1.0, 0.0, -3.0]), 0.0)
    assert float(neg) == pytest.approx(-float(params.max_adjustment_m), rel=1e-6)
    # the setting is the truncation, above the seed's 0.35 h1 too (it was clipped at 0.35 h1 first)
    wide = dataclasses.replace(params, max_adjustment_m=jnp.asarray(0.25, params.h1_m.dtype))
    far, _ = ctl.footstep_block(wide, jnp.asarray(10), jnp.array([0.0, 1.0, 0.0, 3.0]), 0.0)
    assert float(far) == pytest.approx(0.25, rel=1e-6) and 0.25 > float(params.max_adjustment_m)


def test_dlqr_holds_the_phase_start_adjustment_and_open_loop_never_steps(params):
    """The registered variants as configurations: ``hold_adjustment = 1`` (dlqr), ``footstep_gain = 0`` (open loop)."""
    from mjx_coman import controllers

    dlqr, ol_cfg = controllers.default_config("dlqr"), controllers.default_config("open-loop")
    e0 = jnp.array([0.0, 0.01, 0.0, 0.05])
    adj0, held = ctl.footstep_block(dlqr, jnp.asarray(0), e0, jnp.asarray(0.0))
    assert float(adj0) == pytest.approx(float(params.footstep_table[0] @ e0), rel=1e-5) and float(adj0) > 0
    adj1, held1 = ctl.footstep_block(dlqr, jnp.asarray(120), -3 * e0, held)
    assert float(adj1) == float(adj0) and float(held1) == float(held)
    tp, _ = ctl.footstep_block(params, jnp.asarray(120), -3 * e0, held)
    assert float(tp) < 0  # time projection reacts to the new error at once
    ol, _ = ctl.footstep_block(ol_cfg, jnp.asarray(120), -3 * e0, held)
    assert float(ol) == 0.0
    # a variant changes its one setting only: the tables are the same
    np.testing.assert_array_equal(np.asarray(ol_cfg.footstep_table), np.asarray(params.footstep_table))
    assert float(ol_cfg.hold_adjustment) == 0.0 and float(dlqr.footstep_gain) == 1.0


def test_adaptive_lift_and_foot_pitch_follow_the_leg_angle(params):
    """Eq. 28-30: the swing leg left behind (pelvis ahead of it) gets extra lift and toes-up pitch."""
    e = jnp.array([-0.05, 0.03, 0.0, 0.0])  # pelvis - swing 8 cm beyond the nominal
    lift, pitch, theta = ctl.lift_block(params, 0.1, e, 0.0)
    h1 = float(params.h1_m)
    assert float(theta) == pytest.approx(np.arctan(0.08 / h1), rel=1e-5)
    assert float(lift) == pytest.approx(h1 * (1 - np.cos(float(theta))) * np.sin(np.pi * 0.25), rel=1e-4)
    assert float(pitch) == pytest.approx(-float(theta))
    # measured from the commanded (adjusted) swing position: the adjustment itself does not count
    lift2, _, theta2 = ctl.lift_block(params, 0.1, jnp.array([0.08, 0.0, 0.0, 0.0]), 0.08)
    assert abs(float(theta2)) < 1e-7 and abs(float(lift2)) < 1e-9


def _mirror(q):
    q = np.asarray(q).copy()
    out = q.copy()
    for n in LEG_JOINTS:
        sign = -1.0 if n in LATERAL_JOINTS else 1.0
        out[JOINT_INDEX["L" + n]] = sign * q[JOINT_INDEX["R" + n]]
        out[JOINT_INDEX["R" + n]] = sign * q[JOINT_INDEX["L" + n]]
    return out


@pytest.mark.parametrize("tick", [0, 40, 130])
@pytest.mark.parametrize("adjustment", [0.0, 0.05])
def test_leg_targets_mirror_between_phases(params_fast, tick, adjustment):
    """d = -1 is the left/right mirror of d = +1 (sagittal joints equal, lateral ones negated)."""
    t = tick * 0.002

    def targets(d):
        q_nom = ctl.nominal_at(params_fast, tick, 10, d, FAST_MPS)
        return ctl.joint_targets_block(params_fast, q_nom, t, d, jnp.asarray(adjustment), jnp.asarray(0.004),
                                       jnp.asarray(-0.05))

    q_left, q_right = np.asarray(targets(1.0)), np.asarray(targets(-1.0))
    assert q_left.shape == (NU,) and np.all(np.isfinite(q_left))
    np.testing.assert_allclose(q_right, _mirror(q_left), atol=MIRROR_TOL_RAD)
    # the swing (left) hip flexes further for a forward footstep adjustment
    if adjustment > 0:
        base = ctl.joint_targets_block(params_fast, ctl.nominal_at(params_fast, tick, 10, 1.0, FAST_MPS), t, 1.0,
                                       jnp.asarray(0.0), jnp.asarray(0.004), jnp.asarray(-0.05))
        assert q_left[JOINT_INDEX["LHipSag"]] < float(base[JOINT_INDEX["LHipSag"]]) - 0.05


@pytest.mark.parametrize("hip_attack", [0.0, 0.75, 1.0])
def test_hip_attack_splits_the_adjustment_between_ik_and_hip(params, hip_attack):
    """``a Delta / h1`` on the swing hip and ankle pitch (knee untouched), ``(1 - a) Delta`` through the IK."""
    from mjx_coman.kinematics import leg_fk, rot_y

    p = params.replace(hip_attack=jnp.asarray(hip_attack, params.h1_m.dtype))
    tick, delta = 130, 0.05
    q_nom = ctl.nominal_at(p, tick, 10, 1.0, 0.0)  # left swing

    def targets(adj, prm=p):
        return np.asarray(ctl.joint_targets_block(prm, q_nom, tick * 0.002, 1.0, jnp.asarray(adj), jnp.asarray(0.0),
                                                  jnp.asarray(0.0)))

    q0, q1 = targets(0.0), targets(delta)
    h1 = float(p.h1_m)
    right = [JOINT_INDEX["R" + n] for n in LEG_JOINTS]
    np.testing.assert_allclose(q1[right], q0[right], atol=1e-6)  # the stance leg does not move
    # what the IK does with (1 - a) Delta, then the attack angle on top
    q_ik = targets((1 - hip_attack) * delta, p.replace(hip_attack=jnp.zeros_like(p.hip_attack)))
    angle = hip_attack * delta / h1
    expected = q_ik.copy()
    expected[JOINT_INDEX["LHipSag"]] -= angle
    expected[JOINT_INDEX["LAnkSag"]] += angle
    np.testing.assert_allclose(q1, expected, atol=1e-6)
    # the swing foot: moved by (1 - a) Delta through the IK, then turned by the angle about the hip, foot flat
    pose_ik, pose = leg_fk(jnp.asarray(q_ik[LEFT_LEG_INDEX]), 1.0), leg_fk(jnp.asarray(q1[LEFT_LEG_INDEX]), 1.0)
    turned = np.asarray(pose_ik.hip_m) + np.asarray(rot_y(jnp.asarray(-angle))) @ np.asarray(
        pose_ik.ankle_m - pose_ik.hip_m)
    np.testing.assert_allclose(np.asarray(pose.ankle_m), turned, atol=2e-5)
    # the foot's pitch is kept (with the pelvis rolled the hip and ankle pitch axes differ: a small yaw remains)
    pitch = lambda r: float(np.arctan2(r[0, 2], r[2, 2]))  # noqa: E731
    assert abs(pitch(np.asarray(pose.foot_rot)) - pitch(np.asarray(pose_ik.foot_rot))) < 1e-3
    pose0 = leg_fk(jnp.asarray(q0[LEFT_LEG_INDEX]), 1.0)
    np.testing.assert_allclose(float(pose_ik.foot_point_m[0] - pose0.foot_point_m[0]), (1 - hip_attack) * delta,
                               atol=1e-4)


@pytest.fixture(scope="module")
def rolled(params, reset_state):
    """2 n + 2 controller ticks on the reset readings, every state and telemetry recorded (one compilation)."""
    n = params.ticks_per_step
    obs = Observation(reset_state.readings, joystick(), jnp.zeros(()))

    def run(p):
        def body(s, _):
            s, cmd, tel = ctl.step(p, s, obs)
            return s, (s.tick, s.step, s.d, cmd.target, s.adjustment_m, tel)

        return jax.lax.scan(body, ctl.init(p), None, length=2 * n + 2)

    return jax.jit(run)(params)


def test_step_runs_the_phase_clock(params, rolled):
    """Start-up phase (-1, d = -1), then a left swing (0, d = +1), then a right swing (1, d = -1)."""
    n = params.ticks_per_step
    _, (tick, step, d, target, adj, _) = rolled
    tick, step, d = np.asarray(tick), np.asarray(step), np.asarray(d)
    assert target.shape == (2 * n + 2, NU) and np.all(np.isfinite(np.asarray(target)))
    np.testing.assert_array_equal(step[:n], -1)
    np.testing.assert_array_equal(step[n:2 * n], 0)
    np.testing.assert_array_equal(step[2 * n:], 1)
    np.testing.assert_array_equal(d[:n], -1.0)
    np.testing.assert_array_equal(d[n:2 * n], 1.0)
    np.testing.assert_array_equal(tick[[0, n - 1, n, 2 * n]], [1, n, 1, 1])
    np.testing.assert_array_equal(np.asarray(adj)[:n], 0.0)  # no footstep adjustment before walking


def test_telemetry_reports_support_phase_and_the_planned_landing(params, rolled):
    """Both feet in the start-up phase, then the right foot stands while the left swings, and so on."""
    n = params.ticks_per_step
    _, (_, step, d, _, adj, tel) = rolled
    support, phase = np.asarray(tel.support), np.asarray(tel.phase)
    np.testing.assert_array_equal(support[:n], SUPPORT_DOUBLE)
    np.testing.assert_array_equal(support[n:2 * n], SUPPORT_RIGHT)
    np.testing.assert_array_equal(support[2 * n:], SUPPORT_LEFT)
    np.testing.assert_array_equal(np.asarray(tel.step), np.asarray(step))
    np.testing.assert_allclose(phase[[0, n - 1, n, n + 100]], [0.0, (n - 1) / n, 0.0, 0.5], atol=1e-6)
    land = np.asarray(tel.next_footstep_m)
    # in place, the left foot lands a step width to the left of the right stance foot, plus the adjustment
    np.testing.assert_allclose(land[n + 10, 1], float(params.step_width_m), atol=0.02)
    np.testing.assert_allclose(land[n:2 * n, 0] - np.asarray(tel.footstep_adjustment_m)[n:2 * n, 0], 0.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(tel.footstep_adjustment_m)[:, 0], np.asarray(adj), atol=0)
    assert tel.extra.error.shape == (2 * n + 2, 2, 4)


def test_start_up_phase_keeps_the_feet_down(params, rolled, reset_state):
    """Without lift or roll the start-up targets stay near the crouched posture (sway only, a few cm)."""
    n = params.ticks_per_step
    _, (_, _, _, target, _, _) = rolled
    dev = np.abs(np.asarray(target)[:n] - np.asarray(reset_state.actuator.motor_angle_rad)[None])
    legs = [JOINT_INDEX[s + j] for s in "LR" for j in ("HipLat", "AnkLat", "KneeSag")]
    assert dev[:, legs].max() < 0.15
    assert dev[:, [JOINT_INDEX["LKneeSag"], JOINT_INDEX["RKneeSag"]]].max() < 0.05  # no knee-bending lift


class _Poses(NamedTuple):
    """The fields of ``mjx.Data`` the true relative positions read."""

    xpos: jax.Array
    xquat: jax.Array
    xmat: jax.Array


def test_a_privileged_run_estimates_from_the_simulators_truth(params, reset_state):
    """With ``observation.truth`` the raw relative positions are the simulator's, else the sensors' (eq. 15 input)."""
    data = reset_state.data
    moved = _Poses(data.xpos.at[1:, 0].add(jnp.arange(data.xpos.shape[0] - 1) * 0.01),  # every body but the world
                   data.xquat, data.xmat)  # moved forward by its own amount: the feet move against the pelvis
    state = ctl.init(params)

    @jax.jit
    def raw(truth):
        obs = Observation(reset_state.readings, joystick(), jnp.zeros(()), truth)
        _, _, tel = ctl.step(params, state, obs)
        return tel.extra.measured_rel_m, tel.extra.d

    sensed, d = raw(None)
    np.testing.assert_allclose(np.asarray(sensed), np.asarray(est.measure_relative(reset_state.readings, d)), atol=1e-6)
    true, d = raw(moved)
    np.testing.assert_allclose(np.asarray(true), np.asarray(est.true_relative(moved, d)), atol=1e-6)
    assert np.max(np.abs(np.asarray(true) - np.asarray(sensed))) > 0.05  # the moved bodies, not the readings
