import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from jaxlp import gait as G
from jaxlp.control import M_ERR, SWAP
from jaxlp.dynamics import propagate, transition


@pytest.fixture(scope="module")
def check_gait(coman):
    return G.periodic_gait(coman, 0.4, 0.1, step_width_m=2 * coman.pw)


# brief section 4 check values (COMAN, T = 0.4 s, v = 0.1 m/s, width 2 pw, ankle torque 0)
@pytest.mark.parametrize(
    "getter,value,tol",
    [
        (lambda g: g.q0[0, 0], -0.04, 1e-12),  # swing foot -v T behind the stance foot
        (lambda g: g.q0[0, 1], -0.02, 1e-12),  # pelvis midway
        (lambda g: g.q0[0, 4], 0.13353, 1e-5),
        (lambda g: -g.q0[1, 4], 0.215035, 1e-6),  # lateral, towards the stance side
        (lambda g: g.u[0, 0], -2.12209, 1e-5),
        (lambda g: g.u[0, 1], 10.6105, 1e-4),
        (lambda g: g.u[1, 0], 0.868937, 3e-6),
        (lambda g: g.u[1, 1], 0.0, 1e-9),
    ],
)
def test_brief_check_values(check_gait, getter, value, tol):
    assert float(getter(check_gait)) == pytest.approx(value, abs=tol)


def test_lateral_excursion(coman, check_gait):
    assert float(G.lateral_excursion_m(coman, check_gait, 401)) == pytest.approx(0.0205, abs=5e-4)


@pytest.mark.parametrize("speed,width", [(0.0, None), (0.1, None), (0.2, 0.15), (-0.1, 0.1)])
def test_gait_is_periodic(coman, speed, width):
    g = G.periodic_gait(coman, 0.4, speed, width)
    for axis, lateral in ((0, False), (1, True)):
        q0 = g.q0[axis]
        qT = propagate(transition(coman, 0.4, lateral), q0, g.u[axis], d=1.0)
        sign = -1.0 if lateral else 1.0
        np.testing.assert_allclose(np.asarray(sign * M_ERR @ SWAP @ qT), np.asarray(M_ERR @ q0), atol=1e-10)
        assert abs(float(qT[3])) < 1e-10  # the swing foot lands at rest
    assert float(g.q0[0, 0]) == pytest.approx(-speed * 0.4, abs=1e-12)


def test_minimal_torque_width_beats_fixed_width(coman):
    def effort(g):
        ts = jnp.linspace(0, 0.4, 401)
        return float(jnp.trapezoid((g.u[1, 0] + ts * g.u[1, 1]) ** 2, ts))

    best = G.periodic_gait(coman, 0.4, 0.1)
    for w in (0.06, 0.1272, 0.2):
        assert effort(best) <= effort(G.periodic_gait(coman, 0.4, 0.1, w)) + 1e-12
    assert 0.0 < float(best.step_width_m) < 0.3


def test_nominal_trajectory_starts_at_q0(coman, check_gait):
    ts, qs = G.nominal_trajectory(coman, check_gait, 11)
    np.testing.assert_allclose(np.asarray(qs[0]), np.asarray(check_gait.q0), atol=1e-12)
    assert qs.shape == (11, 2, 6)


def test_gait_gradient_wrt_step_time(coman):
    f = lambda T: G.periodic_gait(coman, T, 0.1, 0.1272).u[0, 0]  # noqa: E731
    eps = 1e-6
    fd = (f(0.4 + eps) - f(0.4 - eps)) / (2 * eps)
    assert float(jax.grad(f)(0.4)) == pytest.approx(float(fd), rel=1e-5)


@pytest.mark.parametrize(
    "kwargs,match",
    [(dict(step_time_s=0.4, speed_mps=1.0), "infeasible"), (dict(step_time_s=0.0, speed_mps=0.1), "step_time_s"),
     (dict(step_time_s=-0.4, speed_mps=0.1), "step_time_s"), (dict(step_time_s=0.4, speed_mps=float("nan")), "speed_mps"),
     (dict(step_time_s=0.4, speed_mps=0.1, step_width_m=-0.1), "step_width_m")],
)
def test_bad_gait_raises(coman, kwargs, match):
    with pytest.raises(ValueError, match=match):
        G.periodic_gait(coman, **kwargs)


def test_infeasible_gaits_are_refused_by_their_reason():
    from jaxlp.gait import MAX_STEP_TIME_S, check_feasible
    from jaxlp.presets import get_params

    p = get_params("coman")
    for kw, match in ((dict(step_time_s=1000.0, speed_mps=0.0), "longer than 2.0 s"),
                      (dict(step_time_s=0.4, speed_mps=5.0), "infeasible"),
                      (dict(step_time_s=0.4, speed_mps=0.1, step_width_m=100.0), "wider than 1 h1")):
        with pytest.raises(ValueError, match=match):
            check_feasible(p, **kw)
    check_feasible(p, MAX_STEP_TIME_S, 0.0, 0.1)


@settings(max_examples=300, deadline=None)
@given(t=st.floats(allow_nan=True, allow_infinity=True), v=st.floats(allow_nan=True, allow_infinity=True),
       w=st.floats(allow_nan=True, allow_infinity=True))
def test_check_feasible_refuses_or_accepts_in_range(t, v, w):
    from jaxlp.gait import MAX_STEP_LENGTH_RATIO, MAX_STEP_TIME_S, check_feasible
    from jaxlp.presets import get_params

    p = get_params("coman")
    h1 = float(p.h1)
    try:
        check_feasible(p, t, v, w)
    except ValueError:
        return
    assert 0 < t <= MAX_STEP_TIME_S and abs(v) * t <= MAX_STEP_LENGTH_RATIO * h1 and 0 <= w <= h1
