"""Footstep-predictive walking (seed 001) on the torque-controlled simulated COMAN: the family's ``CONTROLLER``.

Three layers, each tick (seed 001, sec. II-IV): the footstep planner (:mod:`jaxlp.footsteps` on
:mod:`jaxlp.lipm`: the LIPM step map from the measured CoM state and the MPC of eq. 16 over ``n_steps``
footsteps), the trajectory layer (:mod:`.trajectory`: swing foot by Slerp and eq. 8, base yaw turned by the
steering rate, CoM by eq. 3 with a height PD) and the whole-body QP (:mod:`mjx_coman.wbc`, eq. 2: stance sole
in contact, swing foot, CoM above the base orientation, torque limits, friction and CoP at the feet's actual
orientation). The robot's own sensors only (IMU, joint encoders; no contact sensing: fixed step timing).

Modules: :mod:`.config` (settings, config pytree), :mod:`.trajectory`, :mod:`.controller` (``init``/``step``).

Registered as ``footstep-mpc`` (ideal-torque plant, fixed upper body). ``--set plant=torque-sea`` and
``--set fixed_upper_body=false`` select the series-elastic loop and the free upper body; neither is registered as a
variant yet (the series-elastic walk falls within the contract's first second; the free upper body is a second
compiled QP for the contract's batch).

"""

from mjx_coman.controllers.base import Controller, Gait
from mjx_coman.controllers.footstep_mpc import config as _config
from mjx_coman.controllers.footstep_mpc import stepping
from mjx_coman.controllers.footstep_mpc import controller as _controller


def gait(config: _config.Config) -> Gait:
    return stepping.gait(config, _config)


CONTROLLER = Controller(
    name="footstep-mpc", make_config=_config.make_config, init=_controller.init, step=_controller.step, gait=gait,
    settings=_config.SETTINGS,
    description="seed 001: LIPM footstep MPC with steering over the whole-body QP on the torque-controlled robot",
    tune_default=("mpc_com_step_weight", "mpc_footstep_step_weight", "swing_kp_per_s2", "com_weight"),
)
