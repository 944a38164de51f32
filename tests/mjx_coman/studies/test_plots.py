"""The figures' derived curves: the ground-truth capture point of a walk's series (seed 004 eq. 1)."""

import numpy as np
import pytest

from mjx_coman.studies import plots


def test_icp_path_is_the_com_plus_its_velocity_over_omega():
    t = np.arange(0, 2, 0.02)
    z = 0.5
    com = np.stack([0.1 * t, 0.03 * np.sin(2 * t), np.full_like(t, z)], 1)
    vel = np.diff(com[:, :2], axis=0) / 0.02
    icp = plots.icp_path_m({"com_m": com, "com_vel_mps": vel})
    omega = np.sqrt(9.81 / z)
    np.testing.assert_allclose(icp[:, 0], 0.5 * (com[1:, 0] + com[:-1, 0]) + 0.1 / omega, atol=1e-12)
    # the lateral sway: amplitude grows by sqrt(1 + (2 / omega)^2) and leads the CoM
    assert np.abs(icp[:, 1]).max() == pytest.approx(0.03 * np.sqrt(1 + (2 / omega) ** 2), rel=0.01)
    assert plots.icp_path_m({"com_m": com[:1], "com_vel_mps": vel[:0]}).shape == (0, 2)
