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
