"""Motor, spring, position loop and delay line, without the rigid-body simulation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import actuators as act
from mjx_coman.actuators import JOINT_INDEX, NU, SEA_MASK

KNEE = JOINT_INDEX["RKneeSag"]
SHANK_INERTIA_KGM2 = 0.03  # shank + foot about the knee, roughly


def _simulate_sea_on_inertia(params, target, n_steps, dt=0.001, link_inertia=SHANK_INERTIA_KGM2, voltage_mode=False):
    """Every joint drives a free link of inertia ``link_inertia`` (no gravity)."""

    def body(carry, _):
        st, q, dq = carry
        v = act.motor_voltage_v(params, target, st.motor_angle_rad, jnp.asarray(voltage_mode))
        st, tau = act.actuator_substep(params, st, v, q, dq, dt)
        # Rigid joints carry the rotor inertia with the link.
        inertia = jnp.where(jnp.asarray(SEA_MASK), link_inertia, link_inertia + params.rotor_inertia_nms2_per_rad)
        dq = dq + dt * tau / inertia
        q = q + dt * dq
        return (st, q, dq), (st.motor_vel_rad_per_s, q)

    q0 = jnp.zeros(NU)
    st = act.init_actuator_state(q0, q0, q0)
    (_, q, _), (mv, qs) = jax.lax.scan(body, (st, q0, q0), None, length=n_steps)
    return np.asarray(mv), np.asarray(qs)


def test_default_gains_follow_the_seed():
    kp = act.default_kp_v_per_rad()
    assert kp[JOINT_INDEX["RAnkLat"]] == 10 and kp[JOINT_INDEX["LAnkLat"]] == 10
    assert kp[JOINT_INDEX["RHipSag"]] == 100 and kp[JOINT_INDEX["LHipSag"]] == 100
    assert kp[KNEE] == 500 and kp[JOINT_INDEX["WaistYaw"]] == 500


@pytest.mark.parametrize("voltage_mode", [False, True])
def test_step_saturates_at_the_seed_speed_bound(voltage_mode):
    p = act.make_actuator_params()
    target = jnp.full(NU, 15.0 if voltage_mode else 1.0)
    mv, q = _simulate_sea_on_inertia(p, target, 300, voltage_mode=voltage_mode)
    bound = 15.0 / (5.42 + 0.45 * 1.66)  # 2.43 rad/s
    assert mv[:, KNEE].max() == pytest.approx(bound, rel=0.03)
    # rigid joints too (same motor, rotor inertia moving with the link)
    assert mv[:, JOINT_INDEX["WaistYaw"]].max() == pytest.approx(bound, rel=0.03)


def test_position_loop_converges_on_the_motor_shaft():
    p = act.make_actuator_params()
    mv, q = _simulate_sea_on_inertia(p, jnp.full(NU, 0.3), 3000)
    assert q[-1, KNEE] == pytest.approx(0.3, abs=1e-3)


def test_voltage_saturates():
    p = act.make_actuator_params(supply_v=12.0)
    v = act.motor_voltage_v(p, jnp.full(NU, 1.0), jnp.zeros(NU), jnp.asarray(False))
    assert float(v.max()) == pytest.approx(12.0)
    assert float(v[JOINT_INDEX["RAnkLat"]]) == pytest.approx(10.0)  # 10 V/rad * 1 rad, unsaturated


@pytest.mark.parametrize("delay_s,ticks", [(0.0, 0), (0.002, 1), (0.02, 10), (0.05, 25)])
def test_delay_line_returns_the_command_from_n_ticks_ago(delay_s, ticks):
    p = act.make_actuator_params(delay_s=delay_s)
    assert int(p.delay_ticks) == ticks
    st = act.init_actuator_state(jnp.zeros(NU), jnp.zeros(NU), jnp.full(NU, -1.0))
    out = []
    for k in range(40):
        st, d, _ = act.delay_command(p, st, jnp.full(NU, float(k)))
        out.append(float(d[0]))
    expected = [k - ticks if k >= ticks else -1.0 for k in range(40)]
    assert out == expected


def test_delay_vmaps_over_rollouts():
    delays = jnp.array([0, 3, 10], jnp.int32)
    p = act.make_actuator_params()
    ps = jax.vmap(lambda d: act.ActuatorParams(**{**p.__dict__, "delay_ticks": d}))(delays)
    st = act.init_actuator_state(jnp.zeros(NU), jnp.zeros(NU), jnp.zeros(NU))
    sts = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 3), st)

    def run(pp, s):
        def body(s, k):
            s, d, _ = act.delay_command(pp, s, jnp.full(NU, k))
            return s, d[0]
        return jax.lax.scan(body, s, jnp.arange(1.0, 21.0))[1]

    out = np.asarray(jax.vmap(run)(ps, sts))
    assert out[:, -1].tolist() == [20.0, 17.0, 10.0]


def test_series_stiffness_is_spring_and_position_loop_in_series():
    p = act.make_actuator_params()
    k = np.asarray(act.series_stiffness_nm_per_rad(p))
    k_pos = 500 / 0.45
    assert k[JOINT_INDEX["RAnkSag"]] == pytest.approx(1 / (1 / 390 + 1 / k_pos), rel=1e-5)
    assert k[JOINT_INDEX["WaistYaw"]] == pytest.approx(k_pos, rel=1e-5)


def test_static_spring_deflection():
    p = act.make_actuator_params()
    d = np.asarray(act.static_spring_deflection_rad(p, jnp.full(NU, 3.9)))
    assert d[KNEE] == pytest.approx(0.01, rel=1e-5) and d[JOINT_INDEX["WaistYaw"]] == 0.0


def test_link_torque_is_differentiable_in_the_stiffness():
    p = act.make_actuator_params(coulomb_nm=0.5)

    def f(k):
        pp = act.ActuatorParams(**{**p.__dict__, "spring_stiffness_nm_per_rad": jnp.full(NU, k)})
        st = act.init_actuator_state(jnp.zeros(NU), jnp.zeros(NU), jnp.zeros(NU))
        st, tau = act.actuator_substep(pp, st._replace(motor_angle_rad=jnp.full(NU, 0.1)), jnp.zeros(NU),
                                       jnp.zeros(NU), jnp.zeros(NU), 0.001)
        return tau[KNEE]

    g = float(jax.grad(f)(390.0))
    assert g == pytest.approx(0.1, rel=1e-5)


@pytest.mark.parametrize(
    "kwargs,name",
    [
        (dict(spring_stiffness_nm_per_rad=-1.0), "spring_stiffness_nm_per_rad"),
        (dict(delay_s=-0.01), "delay_s"),
        (dict(delay_s=1.0), "delay_s"),
        (dict(beta_v_per_nm=0.0), "beta_v_per_nm"),
        (dict(supply_v=float("nan")), "supply_v"),
        (dict(control_period_s=0.0), "control_period_s"),
        (dict(kp_v_per_rad=np.full(NU, -5.0)), "kp_v_per_rad"),
    ],
)
def test_bad_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        act.make_actuator_params(**kwargs)


def test_torque_limits_follow_eq20_at_the_supply():
    p = act.make_actuator_params()
    lo, hi = act.torque_limits_nm(p, jnp.zeros(NU))
    np.testing.assert_allclose(np.asarray(hi), 15.0 / 0.45, rtol=1e-6)  # 33.3 N m at stall
    np.testing.assert_allclose(np.asarray(lo), -15.0 / 0.45, rtol=1e-6)
    lo, hi = act.torque_limits_nm(p, jnp.full(NU, 1.0))  # 1 rad/s: (15 - 5.42 - 0.45 * 1.66) / 0.45
    np.testing.assert_allclose(np.asarray(hi), (15.0 - 5.42 - 0.45 * 1.66) / 0.45, rtol=1e-6)
    no_load = 15.0 / (5.42 + 0.45 * 1.66)  # the seed's theoretic velocity bound: no torque left
    assert float(act.torque_limits_nm(p, jnp.full(NU, no_load))[1][0]) == pytest.approx(0.0, abs=1e-5)
    lo, hi = act.torque_limits_nm(p, jnp.full(NU, -1.0))  # braking: capped at the stall torque
    np.testing.assert_allclose(np.asarray(hi), 15.0 / 0.45, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(lo), -(15.0 - 5.42 - 0.45 * 1.66) / 0.45, rtol=1e-6)
    tau = act.ideal_torque_nm(p, jnp.full(NU, 50.0), jnp.zeros(NU))
    np.testing.assert_allclose(np.asarray(tau), 15.0 / 0.45, rtol=1e-6)


def _torque_loop_on_fixed_link(params, tau_des, n_steps, dt=0.001):
    """Every joint's link is held still; the torque loop drives the spring (SEA) or the joint (rigid)."""
    q0 = jnp.zeros(NU)

    def body(st, _):
        v = act.torque_loop_voltage_v(params, st, tau_des, q0, q0)
        st, tau = act.actuator_substep(params, st, v, q0, q0, dt)
        return st, tau

    _, taus = jax.lax.scan(body, act.init_actuator_state(q0, q0, q0), None, length=n_steps)
    return np.asarray(taus)


@pytest.mark.parametrize("bandwidth_hz", [5.0, 10.0, 20.0])
def test_series_elastic_torque_loop_is_the_designed_second_order_system(bandwidth_hz):
    # Without spring damping the link torque is k (theta - q), the designed output.
    p = act.make_actuator_params(torque_loop="sea", torque_bandwidth_hz=bandwidth_hz, spring_damping_nms_per_rad=0.0)
    dt, n = 0.0002, 3000
    taus = _torque_loop_on_fixed_link(p, jnp.full(NU, 3.0), n, dt)
    # Critically damped step response 1 - (1 + w t) exp(-w t), from the spring at rest.
    w = 2 * np.pi * bandwidth_hz
    t = dt * np.arange(n)
    expected = 3.0 * (1 - (1 + w * t) * np.exp(-w * t))
    knee = taus[:, KNEE]
    assert np.max(np.abs(knee - expected)) < 0.02 * 3.0
    assert knee[-1] == pytest.approx(3.0, rel=1e-3)
    # With the model's spring damping the loop still settles on the desired torque.
    damped = _torque_loop_on_fixed_link(act.make_actuator_params(torque_loop="sea", torque_bandwidth_hz=bandwidth_hz),
                                        jnp.full(NU, 3.0), n, dt)
    assert damped[-1, KNEE] == pytest.approx(3.0, rel=1e-3)
    rigid = ~SEA_MASK
    np.testing.assert_allclose(taus[:, rigid], 3.0, rtol=1e-6)  # rigid joints: eq. 20 feed-forward is exact


def test_torque_loop_saturates_at_the_supply():
    p = act.make_actuator_params(torque_loop="sea")
    taus = _torque_loop_on_fixed_link(p, jnp.full(NU, 100.0), 800)
    assert np.all(taus[-1] <= 15.0 / 0.45 + 1e-3)  # 100 N m asked, 33 N m at stall given
    assert taus[-1, KNEE] == pytest.approx(15.0 / 0.45, rel=0.02)


def test_unknown_torque_loop_is_refused():
    with pytest.raises(ValueError, match="torque_loop='fast'"):
        act.make_actuator_params(torque_loop="fast")
    with pytest.raises(ValueError, match="torque_bandwidth_hz"):
        act.make_actuator_params(torque_bandwidth_hz=0.0)
