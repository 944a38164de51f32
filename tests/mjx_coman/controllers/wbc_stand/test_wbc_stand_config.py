"""wbc-stand's settings' checks.

Its walks (ideal and series-elastic plants, a forward-mode gradient) are the contract test's torque batch; its
filter and start-up ramp are shared (tests/mjx_coman/controllers/test_torque.py).
"""

import pytest

from mjx_coman.controllers.wbc_stand.config import make_config


@pytest.mark.parametrize("kw, name", [(dict(startup_s=-0.1), "startup_s"), (dict(startup_s=2.0), "startup_s"),
                                      (dict(imu_filter_s=-1.0), "imu_filter_s"), (dict(plant="position"), "plant")])
def test_bad_settings_name_the_value(kw, name):
    with pytest.raises(ValueError, match=name):
        make_config(**kw)
