"""Pushes: validation, impulses and headings, and the force a tick sees (its exact share of the impulse)."""

import math

import numpy as np
import pytest

from mjx_coman.pushes import make_push, no_push, push_force


@pytest.mark.parametrize("kwargs, name", [
    (dict(start_s=-1.0, force_n=[1.0, 0, 0]), "start_s"),
    (dict(start_s=1.0, duration_s=0.0, force_n=[1.0, 0, 0]), "duration_s"),
    (dict(start_s=1.0, impulse_ns=-2.0), "impulse_ns"),
    (dict(start_s=1.0, force_n=[1.0, 0.0]), "force_n"),
    (dict(start_s=1.0, force_n=[float("nan"), 0, 0]), "force_n"),
    (dict(start_s=1.0), "exactly one"),
])
def test_make_push_rejects_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        make_push(**kwargs)


def test_make_push_from_impulse():
    p = make_push(2.0, 0.1, impulse_ns=4.0, direction_rad=math.pi / 2)
    np.testing.assert_allclose(p.force_n, [0.0, 40.0, 0.0], atol=1e-5)


def test_ticks_receive_the_whole_impulse_and_nothing_outside_the_push():
    """A push of 0.0105 s starting mid-tick: the ticks' mean forces times dt sum to the impulse exactly."""
    dt = 0.002
    p = make_push(0.0031, 0.0105, force_n=[10.0, -4.0, 0.0])
    ticks = np.arange(20) * dt
    f = np.stack([np.asarray(push_force(p, t, dt)) for t in ticks])
    np.testing.assert_allclose(f.sum(0) * dt, [0.105, -0.042, 0.0], rtol=1e-5)
    inside = (ticks + dt > 0.0031) & (ticks < 0.0031 + 0.0105)
    assert np.all(f[~inside] == 0.0) and np.all(f[inside, 0] > 0)
    np.testing.assert_allclose(f[inside][1:-1, 0], 10.0, rtol=1e-5)  # whole ticks inside: the full force
    assert np.all(np.asarray(push_force(no_push(), 0.5, dt)) == 0.0)
