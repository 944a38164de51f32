"""Time-projection walking (seed 000) on the position-controlled simulated COMAN: the family's ``CONTROLLER``.

Modules: :mod:`.open_loop` (blocks A-C of Figure 3: gait targets, lifts, IK,
knee compensation, motor loops), :mod:`.estimation` (encoders + IMU, IIR
filter, error of eq. 15), :mod:`.config` (the config pytree and its
settings), :mod:`.controller` (``init``/``step``), :mod:`.identification`
(dead-zones and knee deflections from an open-loop walk) and
:mod:`.experiments` (the seed's experiments, ``python -m
mjx_coman.controllers.time_projection.experiments``). Variants (open loop,
no dead-zone, DLQR) are registered configurations (:mod:`mjx_coman.controllers`).
"""

from mjx_coman.controllers.base import Controller, Gait
from mjx_coman.controllers.time_projection import config as _config
from mjx_coman.controllers.time_projection import controller as _controller


def gait(config: _config.Config) -> Gait:
    """The start-up phase lasts one step: walking step ``k`` starts at ``(k + 1) T``."""
    T = config.ticks_per_step * config.dt_s
    return Gait(knee_rad=config.knee_rad, control_period_s=config.dt_s, first_step_s=T, step_time_s=T,
                max_forward_mps=_config.MAX_SPEED_MPS)


CONTROLLER = Controller(
    name="time-projection", make_config=_config.make_config, init=_controller.init, step=_controller.step,
    gait=gait, settings=_config.SETTINGS,
    description="seed 000: 3LP time projection, footstep adjustment at every tick",
    tune_default=("deadzone", "zeta"),
)
