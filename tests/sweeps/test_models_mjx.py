"""sweeps.models.mjx: per-rollout robot randomisation, controllers by name, a small MJX map (slow)."""

import json

import jax
import numpy as np
import pytest

from sweeps.grid import SweepConfig
from sweeps.models import mjx

CFG = SweepConfig(model="mjx", randomize_mass_pct=10.0, randomize_spring_pct=20.0, randomize_delay_ticks=3,
                  encoder_offset_std_rad=0.01, sensor_noise_scale=2.0)


def test_randomized_robots_stay_within_bounds_and_follow_the_key():
    env = mjx.nominal_env(CFG.sensor_noise_scale)
    draw = jax.jit(jax.vmap(lambda k: mjx.randomized_env(env, CFG, k)))
    robots = draw(jax.random.split(jax.random.PRNGKey(0), 64))
    m0 = np.asarray(env.model.body_mass)
    ratio = np.asarray(robots.model.body_mass)[:, m0 > 0] / m0[m0 > 0]
    assert np.all(np.abs(ratio - 1) <= 0.1 + 1e-6) and ratio.std() > 0.03  # spread over +-10 %
    np.testing.assert_allclose(np.asarray(robots.model.body_inertia)[:, m0 > 0] / np.asarray(env.model.body_inertia)[m0 > 0],
                               np.repeat(ratio[..., None], 3, -1), rtol=1e-5)  # inertia scales with the mass
    k = np.asarray(robots.actuator.spring_stiffness_nm_per_rad) / np.asarray(env.actuator.spring_stiffness_nm_per_rad)
    assert np.all(np.abs(k - 1) <= 0.2 + 1e-6) and k.std() > 0.05
    delay = np.asarray(robots.actuator.delay_ticks) - int(env.actuator.delay_ticks)
    assert set(delay.tolist()) <= set(range(-3, 4)) and len(set(delay.tolist())) >= 5
    off = np.asarray(robots.sensor.encoder_offset_rad)
    assert 0.007 < off.std() < 0.013
    assert float(robots.sensor.imu_orientation_noise_rad[0]) == pytest.approx(2 * 0.002)
    again = draw(jax.random.split(jax.random.PRNGKey(0), 64))
    np.testing.assert_array_equal(np.asarray(again.model.body_mass), np.asarray(robots.model.body_mass))


def test_the_walk_is_timed_by_the_controllers_gait():
    cfg = SweepConfig(model="mjx", n_steps=8).validate()
    assert mjx.walk_spec(cfg).seconds == pytest.approx(0.4 + 8 * 0.4)  # its start-up phase, then 8 steps
    assert mjx.ticks_per_rollout(cfg) == 1800 and mjx.env_step_s(cfg) == 0.002
    pd = SweepConfig(model="mjx", controller="joint-pd", n_steps=8).validate()
    assert mjx.walk_spec(pd).seconds == pytest.approx(8 * 0.4)  # no start-up phase
    assert "joint-pd" not in mjx.compare_default() and "open-loop" in mjx.compare_default()


@pytest.mark.slow
def test_small_mjx_map(tmp_path):
    """2 x 2 map of 2.4 s walks (push in walking step 2): unpushed walks stand, a 200 N push falls."""
    from sweeps import report
    from sweeps.runner import run_sweep

    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(0.0, 20.0), n_steps=5, push_step=2, chunk=4)
    run = run_sweep(cfg, tmp_path, progress=False)
    summary = report.write_outputs(tmp_path, run)
    res = run.results
    assert not res["nan"].any()
    assert not res["fell"][res["impulse_ns"] == 0].any() and res["fell"][res["impulse_ns"] == 20].all()
    assert np.all(res["fall_time_s"][res["fell"]] > (cfg.push_step + 1 + res["phase"][res["fell"]]) * 0.4)
    assert summary["env_step_s"] == 0.002 and summary["env_steps_per_rollout"] == 1200
    assert json.loads((tmp_path / "summary.json").read_text())["model"] == "mjx"
    assert np.all(res["touchdowns"][res["impulse_ns"] == 0] >= 5)
    header = (tmp_path / "results.csv").read_text().splitlines()[0]
    assert "cycle_forward_mps" in header and "touchdowns" in header


def test_effort_is_the_mean_knee_torque_and_work_per_weight_and_distance_while_walking():
    """Records every 10 ms: constant 20 W and |knee torques| 3 and 5 N m while the CoM walks 0.1 m/s from 0.4 s
    (the first step) to the push at 1.4 s; a 40 N m knee torque after the push. CoT = 20 W / (m g 0.1 m/s)."""
    t = np.arange(0.0, 2.0, 0.01)
    saved = dict(knee_nm=np.stack([np.full(t.size, 3.0), np.full(t.size, -5.0)], 1),
                 power_w=np.full(t.size, 20.0), com_xy_m=np.stack([0.1 * t, np.zeros(t.size)], 1))
    saved["knee_nm"][t > 1.6, 0] = 40.0
    e = mjx.effort(t, saved, 0.4, 1.4, np.inf, 30.0)
    assert float(e["mean_abs_knee_torque_nm"]) == pytest.approx(4.0)
    assert float(e["cost_of_transport"]) == pytest.approx(20.0 / (30.0 * 9.81 * 0.1), rel=0.02)  # 99 of 100 gaps
    assert float(e["peak_abs_knee_torque_nm"]) == 40.0
    fell = mjx.effort(t, saved, 0.4, 1.4, 1.5, 30.0)  # the peak after a fall does not count
    assert float(fell["peak_abs_knee_torque_nm"]) == 5.0
    still = dict(saved, com_xy_m=np.zeros((t.size, 2)))
    assert np.isnan(float(mjx.effort(t, still, 0.4, 1.4, np.inf, 30.0)["cost_of_transport"]))  # no travel


@pytest.mark.slow
def test_the_native_engine_writes_the_same_outputs_and_outcomes(tmp_path):
    """The 2 x 2 map above on MuJoCo C: the same files and result columns as on MJX, the same outcomes."""
    import dataclasses

    from sweeps import report
    from sweeps.cross_engine import outcome_agreement
    from sweeps.runner import run_sweep

    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(0.0, 20.0), n_steps=5, push_step=2, chunk=4)
    runs = {}
    for engine in ("mjx", "native"):
        runs[engine] = run_sweep(dataclasses.replace(cfg, engine=engine), tmp_path / engine, progress=False)
        report.write_outputs(tmp_path / engine, runs[engine])
    assert sorted(p.name for p in (tmp_path / "mjx").iterdir()) == sorted(p.name for p in (tmp_path / "native").iterdir())
    assert set(runs["mjx"].results) == set(runs["native"].results)
    assert outcome_agreement(runs["mjx"].results, runs["native"].results)["identical"] == 4
    summary = json.loads((tmp_path / "native" / "summary.json").read_text())
    assert summary["engine"] == "native" and summary["config"]["engine"] == "native"
