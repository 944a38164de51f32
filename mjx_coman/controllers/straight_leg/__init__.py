"""Straight-leg capture-point walking (seed 004) on the torque-controlled simulated COMAN: the family's ``CONTROLLER``.

ICP planning over constant CMPs and ICP feedback (:mod:`jaxlp.icp`), the momentum-based whole-body QP with only
the x-y linear momentum rate prescribed (:mod:`mjx_coman.wbc`, seed 004 eq. 5-8), the privileged straight-knee
configuration in the null space of the tasks, feet included (eq. 9-10), set per leg by the state machine of
Fig. 5 (:mod:`.legs`), joint-acceleration bounds from the joint limits, toe-off of the trailing foot in transfer
(sec. IV, :mod:`.toe_off`), late touchdown (sec. III-B), seed 001's swing-foot and pelvis trajectories (over each
edge on stairs), the chest upright with the upper body in the QP. The robot's own sensors only; fixed step timing.

Modules: :mod:`.config` (settings, config pytree), :mod:`.legs` (state machine), :mod:`.toe_off` (the criteria
of Fig. 6), :mod:`.foothold` (footholds on a known terrain: whole treads on stairs), :mod:`.controller`
(``init``/``step``). Variants (registered in :mod:`mjx_coman.controllers`):
``straight-leg``, ``straight-leg-no-toe-off`` (``toe_off=false``), ``bent-knee`` (``knee_mode=bent``: a CoM
height task at the crouched stance instead of the null-space straightening) and ``straight-leg-step-adjust``
(``step_adjust=true``).
"""

from mjx_coman.controllers.base import Controller, Gait
from mjx_coman.controllers.straight_leg import config as _config
from mjx_coman.controllers.footstep_mpc import stepping
from mjx_coman.controllers.straight_leg import controller as _controller


def gait(config: _config.Config) -> Gait:
    return stepping.gait(config, _config)


CONTROLLER = Controller(
    name="straight-leg", make_config=_config.make_config, init=_controller.init, step=_controller.step, gait=gait,
    settings=_config.SETTINGS,
    description="seed 004: ICP planning and feedback, momentum-based whole-body QP, straight knees in its null space",
    tune_default=("icp_gain", "momentum_weight", "swing_kp_per_s2", "privileged_weight"),
)
