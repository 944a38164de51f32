"""The environment: standing, pushes, velocity limit, batches, validation."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import env, experiments
from mjx_coman import actuators as act
from mjx_coman.actuators import JOINT_INDEX, NU, make_actuator_params

KNEE = JOINT_INDEX["RKneeSag"]
ANKLE = JOINT_INDEX["RAnkSag"]


def test_reset_places_the_feet_on_the_floor(reset_state, standing_q):
    d = reset_state.data
    ids = env.model_ids()
    assert float(d.site_xpos[ids["r_sole_site"], 2]) == pytest.approx(0.0, abs=1e-5)
    assert float(d.site_xpos[ids["l_sole_site"], 2]) == pytest.approx(0.0, abs=1e-5)
    assert np.asarray(reset_state.actuator.motor_angle_rad) == pytest.approx(standing_q, abs=1e-6)
    assert standing_q[KNEE] == pytest.approx(0.4)
    # feet flat: hip + knee + ankle pitch = 0
    assert standing_q[JOINT_INDEX["RHipSag"]] + standing_q[KNEE] + standing_q[ANKLE] == pytest.approx(0.0, abs=1e-9)


def test_standing_one_second_stays_up_and_still(stand_run, reset_state):
    _, rec = stand_run
    p0 = np.asarray(reset_state.data.qpos[:3])
    drift = rec["pelvis_m"] - p0
    assert np.max(np.linalg.norm(drift[:, :2], axis=1)) < 0.01
    assert abs(drift[-1, 2]) < 0.01


def test_ghost_robot_springs_deflect_under_load(stand_run, standing_q, env_params):
    _, rec = stand_run
    k = float(env_params.actuator.spring_stiffness_nm_per_rad[ANKLE])
    defl = rec["motor_rad"][-1] - rec["q_rad"][-1]
    # the ankles hold the body (CoM ahead of the ankle axis): a deflection of a few mrad
    assert 0.003 < abs(defl[ANKLE]) < 0.05
    assert abs(defl[KNEE]) > 0.002
    # the actual (link) posture differs from the commanded (ghost) one by more than the motor error
    assert abs(rec["q_rad"][-1, ANKLE] - standing_q[ANKLE]) > abs(rec["motor_rad"][-1, ANKLE] - standing_q[ANKLE])
    # the ankle spring torque is the F/T moment about the ankle axis
    ft = rec["ft_r"][-1]
    assert k * defl[ANKLE] == pytest.approx(-(ft[4] - 0.065 * ft[0]), abs=0.6)


def test_knee_step_saturates_near_the_seed_bound(env_params):
    res = experiments.knee_step(step_rad=1.0, duration_s=0.5, params=env_params)
    assert res["peak_motor_vel_rad_per_s"] == pytest.approx(2.43, rel=0.04)
    assert res["peak_link_vel_rad_per_s"] < 2.7


def test_torso_pull_leans_the_robot_forward(env_params):
    res = experiments.ankle_stiffness(max_pull_n=7.0, ramp_s=1.0, hold_s=0.5, settle_s=0.5, params=env_params)
    assert res["pelvis_displacement_m"] > 0.003
    # effective ankle stiffness: spring and position loop in series (~289 N m/rad), within 30 %
    assert res["mean_effective_stiffness_nm_per_rad"] == pytest.approx(res["series_prediction_nm_per_rad"], rel=0.3)


BATCH_ROWS, BATCH_TICKS = 16, 100  # the shape of the one vmapped program the batch tests share


@functools.partial(jax.jit, static_argnames="ticks")
def _batch_run(params, states, cmd, ticks):
    """One robot per row of ``params`` and ``states``, all under ``cmd`` for ``ticks`` ticks: the final states and
    each tick's link torques (the last substep's ``ctrl``) and velocities."""
    def one(pp, ss):
        def tick(c, _):
            c = env.step(pp, c, cmd)
            return c, (c.data.ctrl, c.data.qvel)
        return jax.lax.scan(tick, ss, None, length=ticks)
    return jax.vmap(one, in_axes=(env.batch_axes(params), 0))(params, states)


def _batch(env_params, reset_state, acts, cmd, ticks=BATCH_TICKS):
    """Roll out one robot per actuator parameter set (padded to ``BATCH_ROWS`` with the last) in one vmap."""
    n = BATCH_ROWS if ticks == BATCH_TICKS and len(acts) < BATCH_ROWS else len(acts)
    acts = list(acts) + [acts[-1]] * (n - len(acts))
    params = dataclasses.replace(env_params, actuator=jax.tree_util.tree_map(lambda *x: jnp.stack(x), *acts),
                                 sensor=jax.tree_util.tree_map(lambda x: jnp.stack([x] * n), env_params.sensor))
    states = jax.tree_util.tree_map(lambda x: jnp.stack([x] * n), reset_state)
    return _batch_run(params, states, cmd, ticks)


@pytest.fixture(scope="module")
def batch16(env_params, reset_state, standing_q):
    springs = np.linspace(150.0, 600.0, BATCH_ROWS)
    acts = [make_actuator_params(spring_stiffness_nm_per_rad=k, delay_s=0.002 * (i % 12)) for i, k in enumerate(springs)]
    return springs, _batch(env_params, reset_state, acts, env.make_command(standing_q))[0]


def test_batch_of_16_different_robots(batch16, reset_state):
    springs, final = batch16
    z = np.asarray(final.data.qpos[:, 2])
    assert np.all(z > float(reset_state.data.qpos[2]) - 0.02)
    defl = np.abs(np.asarray(final.actuator.motor_angle_rad[:, ANKLE] - final.data.qpos[:, 7 + ANKLE]))
    # softer springs deflect more under the same ankle torque
    assert defl[0] > 2.0 * defl[-1]
    assert np.allclose(np.asarray(final.time_s), 0.2, atol=1e-5)


@pytest.mark.slow
def test_batch_of_256_standing_rollouts_two_seconds(env_params, reset_state, standing_q):
    n, ticks = 256, 1000
    key = jax.random.PRNGKey(3)
    springs = np.asarray(jax.random.uniform(key, (n,), minval=250.0, maxval=550.0))
    acts = [make_actuator_params(spring_stiffness_nm_per_rad=float(k)) for k in springs]
    final = _batch(env_params, reset_state, acts, env.make_command(standing_q), ticks)[0]
    drift = np.linalg.norm(np.asarray(final.data.qpos[:, :2] - reset_state.data.qpos[:2]), axis=1)
    assert np.all(drift < 0.02)


@pytest.mark.parametrize(
    "kwargs,name",
    [
        (dict(timestep_s=0.0), "timestep_s"),
        (dict(timestep_s=-0.001), "timestep_s"),
        (dict(control_period_s=0.0025), "control_period_s"),
        (dict(control_period_s=float("nan")), "control_period_s"),
    ],
)
def test_bad_env_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        env.make_env_params(**kwargs)


def test_mass_randomisation_through_the_model(env_params, reset_state, standing_q):
    """A heavier torso (model.body_mass replaced, no recompile) deflects the ankle springs more."""
    ids = env.model_ids()
    heavy = env_params.model.replace(body_mass=env_params.model.body_mass.at[ids["torso_body"]].add(5.0))
    p2 = dataclasses.replace(env_params, model=heavy)
    n = 250
    tg = np.broadcast_to(standing_q, (n, NU))
    _, light = experiments.run(env_params, reset_state, tg, np.zeros((n, 3)))
    _, heavy_rec = experiments.run(p2, reset_state, tg, np.zeros((n, 3)))
    total = lambda r: r["normal_n"][-20:].sum(axis=1).mean()
    assert total(heavy_rec) - total(light) == pytest.approx(5.0 * 9.81, rel=0.05)


def test_torque_commands_reach_the_links_after_the_delay(env_params, reset_state, standing_q):
    """Ideal torque loop: the link gets the commanded torque (within eq. 20's limits) once it is through the delay."""
    plants = [make_actuator_params(torque_loop="ideal", delay_s=0.0), make_actuator_params(torque_loop="ideal", delay_s=0.004),
              make_actuator_params(torque_loop="sea", delay_s=0.0)]
    tau = jnp.full(NU, 2.0).at[KNEE].set(50.0)  # the knee asks for more than the motor can give
    cmd = env.make_command(tau, mode="torque")
    ctrl, qvel = (np.asarray(x)[:len(plants), :5] for x in _batch(env_params, reset_state, plants, cmd)[1])
    # ctrl: (plant, tick, NU), the last substep's link torques over the first 5 ticks
    others = np.arange(NU) != KNEE
    np.testing.assert_allclose(ctrl[0, :, others], 2.0, rtol=1e-6)
    # clipped at the speed-dependent limit: the light shank speeds up to the motor's no-load speed, no further
    assert np.all((ctrl[0, :, KNEE] > 0) & (ctrl[0, :, KNEE] <= 15.0 / 0.45 + 1e-4))
    assert ctrl[0, -1, KNEE] < 0.5 * 15.0 / 0.45
    assert np.max(np.abs(qvel[0, :, 6 + KNEE])) < 15.0 / (5.42 + 0.45 * 1.66) + 0.05
    # 2 ticks of delay: the boards hold the reset position until the first torque command arrives
    assert not np.allclose(ctrl[1, :2, others], 2.0, atol=0.1)
    np.testing.assert_allclose(ctrl[1, 2:, others], 2.0, rtol=1e-6)
    # series-elastic loop: rigid joints get the torque by the eq. 20 feed-forward at once
    rigid = ~act.SEA_MASK
    np.testing.assert_allclose(ctrl[2, :, rigid & others], 2.0, rtol=1e-4)
    with pytest.raises(ValueError, match="mode='current'"):
        env.make_command(tau, mode="current")
