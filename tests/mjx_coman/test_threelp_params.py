"""3LP parameters derived from the MJCF."""

import pytest

from jaxlp.presets import get_params
from mjx_coman.threelp_params import coman_mjcf_params, mjcf_segments


def test_mjcf_segments_values():
    s = mjcf_segments()
    assert s["h1"] == pytest.approx(0.5168, abs=1e-4)
    assert s["pw"] == pytest.approx(0.0726, abs=1e-6)
    assert s["m1"] + 2 * s["m2"] == pytest.approx(28.8934, abs=1e-3)
    assert s["leg_mass_left_kg"] == pytest.approx(s["m2"], rel=1e-9)
    assert 0.0 < s["h2"] < s["h1"]
    assert 0.1 < s["h3"] < 0.35  # torso CoM above the hips, below the shoulders (0.32 m)
    assert 0.05 < s["I2"] < 0.5


def test_params_are_built_and_validated():
    p = coman_mjcf_params(g=9.81)
    assert float(p.total_mass_kg) == pytest.approx(28.8934, abs=1e-3)
    with pytest.raises(ValueError, match="g"):
        coman_mjcf_params(g=-1.0)


def test_preset_coman_mjcf():
    p = get_params("coman-mjcf")
    assert float(p.h1) == pytest.approx(0.5168, abs=1e-4)
