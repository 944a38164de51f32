"""Standing balance by the whole-body QP on the torque-controlled COMAN: the family's ``CONTROLLER``.

The stack of seeds 001 and 004 without any walking: each tick the pelvis
orientation is the gyro's, corrected toward the IMU's by a complementary
filter (``imu_filter_s``: seed 001's 3 deg IMU noise, white at 500 Hz, would
otherwise shake the robot through the orientation tasks), the floating
base is estimated from the sensors (:mod:`mjx_coman.floating_base`, both
soles anchored), the whole-body terms of the controller's nominal model are
computed (:mod:`mjx_coman.dynamics`) and one QP (:mod:`mjx_coman.wbc`) turns
a CoM PD, an upright pelvis and torso, a joint posture PD and small
regularizations into joint torques under the floating-base dynamics, both
feet in contact, friction pyramids and the motor's torque limits (seed 001,
eq. 2). The torques go out in torque mode; the plant is ideal
(``wbc-stand``) or series-elastic (``wbc-stand-sea``). A failed solve is
reported in ``Telemetry.ok`` (and the command is gravity compensation).
The torques ramp in over ``startup_s`` from the reset, where the robot
touches the floor without contact force yet.

Modules: :mod:`.config` (settings, config pytree), :mod:`.controller` (``init``/``step``).
"""

from mjx_coman.controllers.base import Controller, Gait
from mjx_coman.controllers.wbc_stand import config as _config
from mjx_coman.controllers.wbc_stand import controller as _controller


def gait(config: _config.Config) -> Gait:
    return Gait(knee_rad=config.knee_rad, control_period_s=config.dt_s, first_step_s=0.0, step_time_s=0.4,
                max_forward_mps=0.0, plant=config.plant)


CONTROLLER = Controller(
    name="wbc-stand", make_config=_config.make_config, init=_controller.init, step=_controller.step, gait=gait,
    settings=_config.SETTINGS,
    description="stands by the whole-body QP (CoM, pelvis, torso, posture tasks) on the torque-controlled robot",
)
