"""bench/numpy_twin.py: the native baseline's controller is the walking controller, run by NumPy."""

import sys
from pathlib import Path

import jax
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[2] / "bench"))
import numpy_twin  # noqa: E402


def test_at_updates_copy_and_accumulate_like_jax():
    a = numpy_twin.as_twin(np.zeros(4))
    b = a.at[np.array([1, 1, 3])].add(2.0)
    np.testing.assert_array_equal(b, np.asarray(jax.numpy.zeros(4).at[np.array([1, 1, 3])].add(2.0)))
    assert np.all(a == 0)  # out of place
    c = b.at[0].set(5.0)
    assert c[0] == 5.0 and b[0] == 0.0 and isinstance(c + 1.0, numpy_twin.TwinArray)


def test_twinned_kinematics_match_jax():
    from mjx_coman import kinematics as K

    q = np.array([-0.3, 0.05, 0.1, 0.6, -0.02, -0.25])
    rot = np.asarray(K.rot_y(0.1) @ K.rot_x(-0.05))
    for fn, args in ((K.leg_ik, ([0.05, 0.08, -0.40], rot, 1.0)), (K.leg_fk, (q, -1.0))):
        want = jax.tree_util.tree_map(np.asarray, fn(*[jax.numpy.asarray(a) for a in args]))  # float32
        got = numpy_twin.twin(fn)(*[numpy_twin.as_twin(np.asarray(a, float)) for a in args])  # float64
        for w, g in zip(jax.tree_util.tree_leaves(want), jax.tree_util.tree_leaves(got)):
            np.testing.assert_allclose(g, w, atol=2e-6)


@pytest.mark.slow
def test_twin_controller_gives_the_jax_controllers_targets(controller="time-projection"):
    """260 ticks (the start-up phase and the start of walking) of readings with swaying encoders and pitch.

    No ``jax.enable_x64`` here: toggling it in the test session broke later 32-bit tests (``lax.add`` of int64
    and int32 indices inside ``.at`` updates with NumPy index arrays), so float32 JAX meets float64 NumPy.
    """
    from mjx_coman import controllers, env as E
    from mjx_coman.controllers.base import Observation
    from mjx_coman.controllers.time_projection import controller as C
    from mjx_coman.rollout import walking_env_params

    env = walking_env_params()
    cp = controllers.load(controller)[1]
    r0 = jax.tree_util.tree_map(np.asarray, E.reset(jax.random.PRNGKey(0), env, cp.knee_rad).readings)
    step = jax.jit(C.step)
    js, ts = C.init(cp), numpy_twin.twin(C.init)(numpy_twin.to_twin_tree(cp))
    tcp, tstep = numpy_twin.to_twin_tree(cp), numpy_twin.twin(C.step)
    joy = controllers.joystick(0.1)
    worst = 0.0
    for k in range(260):
        sway = 0.02 * np.sin(2 * np.pi * k / 80.0)
        r = r0._replace(link_angle_rad=r0.link_angle_rad + sway, motor_angle_rad=r0.motor_angle_rad + 0.5 * sway,
                        imu_rpy_rad=r0.imu_rpy_rad + np.array([0.0, sway, 0.0]),
                        foot_normal_force_n=np.array([150.0 + 100 * sway / 0.02, 130.0]))
        js, jcmd, _ = step(cp, js, Observation(jax.tree_util.tree_map(jax.numpy.asarray, r), joy, k * 0.002))
        ts, tcmd, _ = tstep(tcp, ts, Observation(jax.tree_util.tree_map(numpy_twin.as_twin, r),
                                                   numpy_twin.to_twin_tree(joy), k * 0.002))
        worst = max(worst, float(np.max(np.abs(np.asarray(jcmd.target) - np.asarray(tcmd.target)))))
    assert int(js.step) == int(ts.step) == 0  # walking began
    assert abs(float(ts.adjustment_m)) > 1e-4  # the footstep feedback acted
    assert worst < 1e-4  # rad: float32 JAX against float64 NumPy
