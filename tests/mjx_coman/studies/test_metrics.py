"""Ground-truth figures of a walk, on synthetic records with known answers."""

from types import SimpleNamespace

import numpy as np
import pytest

from mjx_coman.studies import metrics


def _walk(t, com, yaw, fell=False, fall_time_s=np.inf):
    return SimpleNamespace(time_s=t, saved={"com_m": com, "pelvis_yaw_rad": yaw}, fell=fell, fall_time_s=fall_time_s,
                           nan=False, solve_failed=False, touchdowns=10, mean_speed_mps=np.float32(0.2),
                           steps_to_recover=np.int32(-1))


def test_heading_change_is_unwrapped_and_stops_at_a_fall():
    t = np.arange(1, 1001) * 0.02
    yaw = np.angle(np.exp(1j * 0.5 * t))  # 0.5 rad/s, wrapped to (-pi, pi]
    com = np.zeros((len(t), 3))
    assert metrics.heading_change_rad(_walk(t, com, yaw)) == pytest.approx(0.5 * (t[-1] - t[0]), rel=1e-6)
    fell = _walk(t, com, yaw, True, 1.0)
    assert metrics.heading_change_rad(fell) == pytest.approx(0.5 * (1.0 - t[0]), rel=1e-6)


def test_com_velocity_and_its_cycle_of_a_swaying_walk():
    t = np.arange(1, 501) * 0.02  # 10 s
    x = 0.2 * t + 0.01 * np.sin(2 * np.pi * 1.25 * t)  # 0.2 m/s with a step-rate wobble
    y = 0.03 * np.sin(2 * np.pi * 1.25 * t / 2)
    com = np.stack([x, y, 0.5 + 0 * t], -1)
    res = _walk(t, com, 0 * t)
    tm, v = metrics.com_velocity_mps(res)
    exact = 0.2 + 0.01 * 2 * np.pi * 1.25 * np.cos(2 * np.pi * 1.25 * tm)
    assert np.max(np.abs(v[:, 0] - exact)) < 2e-3  # central differences of a smooth path
    cyc = metrics.cycle(res)
    amp = 0.01 * 2 * np.pi * 1.25
    assert cyc["forward_mean_mps"] == pytest.approx(0.2, abs=2e-3)
    assert cyc["forward_max_mps"] == pytest.approx(0.2 + amp, abs=3e-3)
    assert cyc["forward_min_mps"] == pytest.approx(0.2 - amp, abs=3e-3)
    short = _walk(t, com, 0 * t, True, 3.0)  # fell after 3 s: no 4 s cycle to read
    assert metrics.cycle(short)["forward_mean_mps"] is None


def test_summary_of_a_fall():
    t = np.arange(1, 101) * 0.02
    res = _walk(t, np.zeros((100, 3)), 0 * t, True, 1.0)
    s = metrics.summary(res, pushed=True)
    assert s["fell"] and s["fall_time_s"] == 1.0 and s["steps_to_recover"] is None
    assert len(s["series"]["time_s"]) == 49 and s["series"]["com_m"].shape == (50, 3)


def test_knee_metrics_read_the_stance_knee_at_mid_stance_and_the_knee_torque_and_power():
    """A synthetic walk: the right knee at 0.1 rad while it stands alone, the left at 0.5; touchdowns every
    0.6 s alternating right, left; knee torques 2 and -4 N m, the right knee moving at 1 rad/s."""
    from types import SimpleNamespace

    from mjx_coman.actuators import JOINT_INDEX
    from mjx_coman.ground_truth import LEFT, RIGHT

    t = np.arange(1, 501) * 0.02  # 10 s of records
    td = np.arange(0.3, 10.0, 0.6)
    foot = np.where(np.arange(len(td)) % 2 == 0, RIGHT, LEFT)
    qpos = np.zeros((len(t), 30))
    r, l = 7 + JOINT_INDEX["RKneeSag"], 7 + JOINT_INDEX["LKneeSag"]
    k = np.searchsorted(td, t, side="right") - 1  # the last touchdown before each record
    right_alone = (k >= 0) & (foot[np.clip(k, 0, None)] == RIGHT)
    qpos[:, r] = np.where(right_alone, 0.1, 0.5)
    qpos[:, l] = np.where(right_alone, 0.5, 0.1)
    tau = np.zeros((len(t), 23))
    tau[:, JOINT_INDEX["RKneeSag"]], tau[:, JOINT_INDEX["LKneeSag"]] = 2.0, -4.0
    res = SimpleNamespace(time_s=t, fell=False, fall_time_s=np.inf, touchdowns=len(td),
                          log=SimpleNamespace(time_s=td, foot=foot), saved={"qpos": qpos, "link_torque_nm": tau})
    m = metrics.knee_metrics(res, qpos[:, [r, l]], tau[:, [r - 7, l - 7]], 0.02)
    assert m["stance_knee_mid_rad"] == pytest.approx(0.1)
    assert m["mean_abs_knee_torque_nm"] == pytest.approx(3.0)
    qpos[:, r], qpos[:, l] = t, 0.3  # the right knee at 1 rad/s, the left still
    m = metrics.knee_metrics(res, qpos[:, [r, l]], tau[:, [r - 7, l - 7]], 0.02)
    assert m["mean_abs_knee_power_w"] == pytest.approx(1.0, rel=1e-6)  # |2 N m x 1 rad/s| and 0 on the left
    res.fell, res.fall_time_s = True, 1.5  # nothing after the start before the fall
    assert metrics.knee_metrics(res, qpos[:, [r, l]], tau[:, [r - 7, l - 7]], 0.02) == {"stance_knee_mid_rad": None, "mean_abs_knee_torque_nm": None,
                                           "mean_abs_knee_power_w": None}


def test_toe_off_fraction_counts_steps_whose_trailing_heel_rose_on_its_toe():
    """Synthetic corners: touchdowns every 0.6 s alternating right, left; in every other step the trailing
    foot pitches heel-up about its front edge (toes on the ground), in the others it lifts flat."""
    from types import SimpleNamespace

    from mjx_coman.ground_truth import LEFT, RIGHT

    t = np.arange(1, 501) * 0.02
    td = np.arange(0.3, 10.0, 0.6)
    foot = np.where(np.arange(len(td)) % 2 == 0, RIGHT, LEFT)
    corners = np.zeros((len(t), 2, 4, 3))
    corners[..., 2] = 0.001  # every corner on the ground
    k = np.searchsorted(td, t, side="right") - 1
    late = (k >= 0) & (t - td[np.clip(k, 0, None)] > 0.1) & (t - td[np.clip(k, 0, None)] < 0.2)
    for i in np.flatnonzero(late):
        trailing = 1 if foot[k[i]] == RIGHT else 0  # corners: right foot first
        if k[i] % 2 == 0:
            corners[i, trailing, 2:, 2] = 0.02  # heel up, toes down: toe-off
        else:
            corners[i, trailing, :, 2] = 0.02  # the whole foot up: a flat lift-off
    res = SimpleNamespace(time_s=t, fell=False, fall_time_s=np.inf, touchdowns=len(td),
                          log=SimpleNamespace(time_s=td, foot=foot))
    assert metrics.toe_off_fraction(res, corners, after_s=1.0) == pytest.approx(0.5, abs=0.07)
    # the same feet on the third step of stairs:8 (x 0.9-1.2, top 0.24 m): measured from the terrain
    corners[..., 0], corners[..., 2] = 1.05, corners[..., 2] + 0.24
    assert metrics.toe_off_fraction(res, corners, "stairs:8", after_s=1.0) == pytest.approx(0.5, abs=0.07)
    assert metrics.toe_off_fraction(res, corners, after_s=1.0) == 0.0  # on flat ground they would float


def test_corner_positions_match_the_standing_robot_on_the_floor():
    import mjx_coman

    q = mjx_coman.load_model().qpos0.copy()
    c = metrics.corner_positions_m(q[None])
    assert c.shape == (1, 2, 4, 3)
    np.testing.assert_allclose(c[0, 0, 0, :2] - c[0, 0, 2, :2], [0.20, 0.0], atol=0.02)  # toe 0.20 ahead of heel


def test_step_length_is_the_distance_along_the_heading_between_the_feet_at_touchdown():
    from types import SimpleNamespace

    td = np.arange(0.3, 6.0, 0.6)
    n = len(td)
    yaw = np.full(n, np.pi / 2)  # walking along +y
    foot = np.stack([np.where(np.arange(n) % 2 == 0, 0.08, -0.08), 0.12 * np.arange(1, n + 1), np.zeros(n)], 1)
    other = np.stack([-foot[:, 0], 0.12 * np.arange(0, n), np.zeros(n)], 1)
    res = SimpleNamespace(touchdowns=n, fell=False, fall_time_s=np.inf,
                          log=SimpleNamespace(time_s=td, foot_m=foot, other_foot_m=other, yaw_rad=yaw))
    assert metrics.step_length_m(res, after_s=1.0) == pytest.approx(0.12)
    res.fell, res.fall_time_s = True, 0.5
    assert metrics.step_length_m(res, after_s=1.0) is None
