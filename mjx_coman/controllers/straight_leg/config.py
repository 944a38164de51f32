"""Settings and the config pytree of ``straight-leg``: ICP, momentum, privileged-configuration and task gains
(tunable); timing, knee mode, step adjustment, plant and solver (static).

Timing from Atlas's simulation (seed 004, sec. V: 0.60 s swing, 0.25 s transfer) by Froude scaling: times
scale with the square root of the leg length, COMAN's hip-to-ankle 0.43 m against Atlas's about 0.85 m, so
by 0.71: 0.42 s swing and 0.18 s transfer (on the 2 ms tick grid). The settings shared with ``footstep-mpc``
(its trajectory layer, tasks, filters and start) are its :data:`~mjx_coman.controllers.footstep_mpc.config.SETTINGS`.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp

from mjx_coman.controllers.base import PLANTS, Setting
from mjx_coman.controllers.footstep_mpc import config as fmpc
from mjx_coman.controllers.torque import stance_references
from mjx_coman.scenarios.terrain import parse_terrain

KNEE_MODES = ("straight", "bent")
MAX_FORWARD_MPS = 0.3
MAX_LATERAL_MPS = 0.1
MAX_TURN_RAD_PER_S = 0.5

_SHARED = {s.name: s for s in fmpc.SETTINGS}
_SHARED_STATIC = ("start_s", "knee_rad", "plant", "fixed_upper_body", "friction_coeff", "startup_s",
                  "contact_slack_weight", "qp_max_iter", "qp_retry_iter")
_SHARED_TUNABLE = ("half_width_m", "clearance_m", "touchdown_depth_m", "shift_m", "com_height_kp_per_s2",
                   "com_height_kd_per_s", "base_kp_per_s2", "base_kd_per_s", "base_weight", "swing_kp_per_s2",
                   "swing_kd_per_s", "swing_weight", "posture_kp_per_s2", "posture_kd_per_s", "posture_weight",
                   "qdd_weight", "force_weight_per_n2", "imu_filter_s", "joystick_ramp_s", "encoder_filter_s")

OWN = (
    Setting("swing_s", 0.42, "single-support (swing) duration, s (module docstring: Atlas's 0.60 s scaled)"),
    Setting("stairs_swing_s", 0.6, "the swing duration on a stairs terrain (replaces swing_s there): a step "
            "across a stair edge is at least a sole long, 0.21 m, and lifts the foot over the riser; at 0.42 s "
            "the swing foot fell short of the tread, s"),
    Setting("transfer_s", 0.18, "double-support (transfer) duration at the start of each step, s (Atlas's 0.25 s "
            "scaled)"),
    Setting("knee_mode", "straight", "straight: the privileged straight knee in the QP's null space, vertical force "
            "free (seed 004); bent: a CoM height task at the crouched stance instead (the baseline)"),
    Setting("step_adjust", False, "move the next footstep (and the later ones) by the ICP error the CMP cannot "
            "null before touchdown (beyond seed 004: jaxlp.icp.step_adjustment)"),
    Setting("toe_off", True, "roll the trailing foot onto its toe in transfer when the criteria of seed 004 "
            "Fig. 6 hold (sec. IV; :mod:`.toe_off`): one contact point, foot pitch free"),
    Setting("late_touchdown", True, "hold the step clock while the swing foot is still in the air at its expected "
            "touchdown (F/T contact flags), driving it down (seed 004 sec. III-B)"),
    Setting("terrain", "flat", "the terrain the footsteps are planned on (a --terrain string): their heights, "
            "and on stairs whole treads (:mod:`.foothold`; seed 004 walked stairs on a given plan)"),
    Setting("stair_overhang_m", 0.0, "on stairs, how far a sole may overhang a stair edge: the heel of a footstep "
            "just past an edge up, the toe of one just before an edge down, m (:mod:`.foothold`)"),
    Setting("stair_max_step_m", 0.2, "on stairs, the longest step that moves a footstep forward off an edge; a "
            "longer one moves it back before the edge, m (:mod:`.foothold`)"),
    Setting("step_over_fraction", 0.4, "on a known non-flat terrain the swing foot steps over edges: it rises to "
            "clearance_m above the higher of its lift-off and landing heights over this fraction of the swing, "
            "moves across, and drops over the last fraction (footstep_mpc.trajectory.step_over_reference)", True,
            (0.05, 0.45)),
    Setting("chest_weight", 1.0, "with fixed_upper_body=false: weight of the chest (torso) orientation task, "
            "upright at the heading (seed 004 eq. 5; the arms follow the posture task)", True, (0.0, None)),
    Setting("joint_limit_horizon_s", 0.05, "joint-acceleration bounds (seed 004 eq. 5): no joint may cross its "
            "position limit within this time at a constant acceleration, s (mjx_coman.wbc.limits)", True,
            (0.005, 1.0)),
    Setting("joint_limit_max_acc", 500.0, "the joint-limit bounds are clipped to +- this, rad/s^2", True,
            (1.0, None)),
    Setting("n_steps", 4, "footsteps the ICP plan looks ahead (static)"),
    Setting("momentum_weight", 0.12, "weight of the linear x-y momentum-rate rows (seed 004 eq. 6, 8), 1/N^2 "
            "(0.12: about footstep-mpc's CoM weight of 100 per (m/s^2)^2 on COMAN's 28.9 kg)", True, (0.0, None)),
    Setting("icp_gain", 2.5, "ICP feedback: r_cmp = r_ref + gain (xi - xi_ref); the error decays at "
            "omega (gain - 1)", True, (1.0, 10.0)),
    Setting("icp_height_m", 0.53, "omega = sqrt(g / icp_height_m) of the ICP dynamics (a design parameter, "
            "seed 004 sec. II-A); the crouched stance's CoM height", True, (0.2, 1.0)),
    Setting("com_height_weight", 100.0, "bent-knee only: weight of the CoM height row, 1/(m/s^2)^2", True,
            (0.0, None)),
    Setting("straight_knee_rad", 0.0, "privileged knee angle of a straight leg (the joint's limit is -0.17)", True,
            (-0.1, 0.6)),
    Setting("bent_knee_rad", 0.3, "privileged knee angle at the start of swing (seed 004: 0.3 rad on Atlas)", True,
            (0.0, 1.5)),
    Setting("collapse_knee_rad", 0.5, "privileged knee angle of a collapsing stance leg before lift-off", True,
            (0.0, 1.5)),
    Setting("straighten_s", 0.1, "time over which a new stance leg's privileged knee goes straight, s", True,
            (0.0, 1.0)),
    Setting("collapse_fraction", 0.85, "the stance leg collapses this far through the other leg's swing", True,
            (0.0, 1.0)),
    Setting("extend_fraction", 0.5, "the swing leg extends this far through its swing", True, (0.0, 1.0)),
    Setting("privileged_kp_per_s2", 100.0, "privileged configuration stiffness (seed 004 eq. 9), 1/s^2", True,
            (0.0, None)),
    Setting("privileged_kd_per_s", 20.0, "its damping, opposing the joint velocity (eq. 9 with k_d < 0), 1/s",
            True, (0.0, None)),
    Setting("privileged_weight", 1.0, "weight of the null-space privileged objective (seed 004 eq. 10)", True,
            (0.0, None)),
    Setting("late_max_s", 0.1, "late touchdown: the longest hold of the step clock per step, s", True, (0.0, 1.0)),
    Setting("late_down_mps", 0.3, "late touchdown: the swing foot's constant downward speed past its expected "
            "touchdown, m/s", True, (0.0, 2.0)),
    Setting("late_swing_weight_per_s", 50.0, "late touchdown: the swing-foot weight grows by this fraction per "
            "second past the expected touchdown, 1/s", True, (0.0, None)),
    Setting("late_pelvis_weight_per_s", 10.0, "late touchdown: the pelvis-orientation weight falls by this fraction "
            "per second past it (down to 0), 1/s", True, (0.0, None)),
    Setting("toe_off_delay_s", 0.06, "toe-off: not before this time into the transfer, s (the clock's touchdown "
            "is not sensed: the leading foot must have landed)", True, (0.0, 1.0)),
    Setting("toe_off_icp_distance_m", 0.15, "toe-off: largest distance of the desired and estimated ICP from "
            "the leading foot's centre, m", True, (0.0, 0.5)),
    Setting("toe_off_cop_distance_m", 0.06, "toe-off: largest distance of the trailing foot's CoP (last tick's "
            "QP forces) from its toe point, m (the sole is 0.20 long)", True, (0.0, 0.3)),
    Setting("toe_off_load_fraction", 0.2, "toe-off: a trailing foot carrying less than this fraction of the "
            "weight (last tick's QP forces) passes the CoP check: rolling it onto its toe changes little", True,
            (0.0, 1.0)),
    Setting("toe_off_cmp_distance_m", 0.03, "toe-off: largest distance of the desired CMP from the toe-off "
            "support polygon, m", True, (0.0, 0.3)),
    Setting("adjust_cmp_margin_x_m", 0.06, "step adjustment: the CMP's range forward and back of the stance foot's "
            "centre that the ICP feedback may use before a step moves, m (the sole reaches 0.10)", True, (0.0, 0.1)),
    Setting("adjust_cmp_margin_y_m", 0.03, "the same sideways, m (the sole reaches 0.05)", True, (0.0, 0.05)),
    Setting("adjust_deadband_m", 0.015, "step adjustment: ICP error (per axis, stance foot frame) that moves no "
            "step, m", True, (0.0, 0.2)),
    Setting("adjust_weight", 1.0, "step adjustment: weight of the footstep offset", True, (0.0, None)),
    Setting("adjust_icp_weight", 10.0, "step adjustment: weight of the ICP error left at touchdown", True,
            (0.0, None)),
    Setting("max_adjustment_m", 0.15, "step adjustment: largest offset per axis, m", True, (0.0, 0.3)),
)

# footstep-mpc's 1e-4 left a condition number of 1e6 in the QP with the null-space rows: float32 qpax broke down
# on a start-up tick of an in-place walk (compiled; the same QP solved eagerly); 1e-3 walked
# Stance rows relaxed at 1e4 per (m/s^2)^2: seed 004's QP (eq. 5) holds only the momentum equation hard, the
# feet are motion objectives. No retry: the iteration keeps its best iterate where float32 breaks down
# (mjx_coman.wbc.iteration); the batched 20 s flat walks gave the same figures with and without a retry at 8.
# The task weights and CoM-height gains this family was built and measured with (footstep-mpc moved its own at
# a1f33e2 for its 0.4 m/s walk; the straight-leg family was not re-tuned).
_DEFAULTS = {"qdd_weight": 1e-3, "contact_slack_weight": 1e4, "base_weight": 1.0, "swing_weight": 10.0,
             "com_height_kp_per_s2": 100.0, "com_height_kd_per_s": 20.0}
_shared = lambda n: _SHARED[n]._replace(default=_DEFAULTS.get(n, _SHARED[n].default))  # noqa: E731
SETTINGS = tuple(_shared(n) for n in _SHARED_STATIC) + OWN + tuple(_shared(n) for n in _SHARED_TUNABLE)
TUNABLE = tuple(s.name for s in SETTINGS if s.tunable)
STATIC = tuple(s.name for s in SETTINGS if not s.tunable)


# settings held as 0/1 array leaves
SWITCHES = {"knee_mode": "straight_legs", "step_adjust": "step_adjust_on", "toe_off": "toe_off_on",
            "late_touchdown": "late_touchdown_on"}


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["leaves", "posture_rad", "com_ref_m", "sole_anchor_m"],
    meta_fields=["statics"],
)
@dataclasses.dataclass(frozen=True)
class Config:
    """Array leaves (the tunables, named as the settings, and the variants' switches ``straight_legs``,
    ``step_adjust_on``, ``toe_off_on`` and ``late_touchdown_on``, 1 or 0, so that every variant has one tree
    structure and batches with the others), the stance's references, and the static choices (``(name, value)``
    pairs). All are read as attributes."""

    leaves: dict
    posture_rad: jax.Array  # (23,) the crouched stance
    com_ref_m: jax.Array  # (3,) its CoM over the mid-ankles (soles at z = 0)
    sole_anchor_m: jax.Array  # (2, 3) right and left sole sites at the reset
    statics: tuple

    def __getattr__(self, name):
        if name in ("leaves", "statics"):
            raise AttributeError(name)
        if name in self.leaves:
            return self.leaves[name]
        for key, value in self.statics:
            if key == name:
                return value
        raise AttributeError(f"straight-leg config has no {name!r}")

    @property
    def step_time_s(self) -> float:
        return self.swing_s + self.transfer_s

    @property
    def double_support_s(self) -> float:
        return self.transfer_s

    @property
    def dt_s(self) -> float:
        return 0.002

    def replace(self, **kw) -> "Config":
        """The config with array leaves replaced (tunables, or the switches).

        Raises:
            ValueError: a name that is not an array leaf.
        """
        bad = [k for k in kw if k not in self.leaves]
        if bad:
            raise ValueError(f"replace() takes the array leaves of straight-leg ({', '.join(self.leaves)}), "
                             f"not {bad[0]!r}")
        return dataclasses.replace(self, leaves={**self.leaves, **kw})


def _ticks(name, v, dt=0.002) -> float:
    if abs(round(v / dt) * dt - v) > 1e-9:
        raise ValueError(f"{name}={v!r} must be a whole number of {dt:g} s control ticks")
    return v


def make_config(**settings) -> Config:
    """A validated config (host).

    Raises:
        ValueError: an unknown setting or a value out of its range (naming it).
    """
    unknown = [k for k in settings if k not in TUNABLE + STATIC]
    if unknown:
        raise ValueError(f"unknown setting {unknown[0]!r} of straight-leg")
    v = {s.name: s.default for s in SETTINGS} | settings
    if v["plant"] not in PLANTS or v["plant"] == "position":
        raise ValueError(f"plant={v['plant']!r} must be torque-ideal or torque-sea")
    if v["knee_mode"] not in KNEE_MODES:
        raise ValueError(f"knee_mode={v['knee_mode']!r} must be one of {', '.join(KNEE_MODES)}")
    for name in ("fixed_upper_body", "step_adjust", "toe_off", "late_touchdown"):
        if not isinstance(v[name], bool):
            raise ValueError(f"{name}={v[name]!r} must be true or false")
    for name, lo, hi in (("n_steps", 2, 12), ("qp_max_iter", 1, 200), ("qp_retry_iter", 0, None)):
        hi = v["qp_max_iter"] - 1 if hi is None else hi  # the retry stops before the full solve
        if isinstance(v[name], bool) or not isinstance(v[name], int) or not lo <= v[name] <= hi:
            raise ValueError(f"{name}={v[name]!r} must be a whole number in [{lo}, {hi}]")
    if not isinstance(v["terrain"], str):
        raise ValueError(f"terrain={v['terrain']!r} must be a terrain string (flat, rough:CM[:SEED], stairs:CM)")
    terrain = parse_terrain(v["terrain"])  # raises ValueError naming a bad one
    v["terrain"] = terrain.text
    v["stairs_swing_s"] = _ticks("stairs_swing_s", fmpc.number_in("stairs_swing_s", v["stairs_swing_s"], 0.1, 2.0))
    if terrain.kind == "stairs":
        v["swing_s"] = v["stairs_swing_s"]
    v["swing_s"] = _ticks("swing_s", fmpc.number_in("swing_s", v["swing_s"], 0.1, 2.0))
    v["transfer_s"] = _ticks("transfer_s", fmpc.number_in("transfer_s", v["transfer_s"], 0.0, 1.0))
    if v["transfer_s"] >= v["swing_s"] + v["transfer_s"] or v["transfer_s"] >= v["swing_s"]:
        raise ValueError(f"transfer_s={v['transfer_s']!r} must be shorter than swing_s={v['swing_s']!r}")
    v["start_s"] = fmpc.number_in("start_s", v["start_s"], 0.0, 5.0)
    v["stair_overhang_m"] = fmpc.number_in("stair_overhang_m", v["stair_overhang_m"], 0.0, 0.1)
    v["stair_max_step_m"] = fmpc.number_in("stair_max_step_m", v["stair_max_step_m"], 0.05, 0.4)
    v["knee_rad"] = fmpc.number_in("knee_rad", v["knee_rad"], 0.1, 1.2)
    v["friction_coeff"] = fmpc.number_in("friction_coeff", v["friction_coeff"], 0.0, 2.0, lo_open=True)
    v["startup_s"] = fmpc.number_in("startup_s", v["startup_s"], 0.0, 1.0)
    v["contact_slack_weight"] = fmpc.number_in("contact_slack_weight", v["contact_slack_weight"], 0.0, 1e8)
    if v["contact_slack_weight"] == 0:  # every variant builds the toe-off rows (one structure), which need slack
        raise ValueError("contact_slack_weight=0 (hard stance rows) is not possible in straight-leg: the toe-off "
                         "rows free the foot pitch with a zero stance row, which needs slack")
    bounds = {s.name: s.bounds for s in SETTINGS if s.tunable}
    for name in TUNABLE:
        x = v[name]
        if isinstance(x, jax.core.Tracer):
            continue
        lo, hi = bounds[name]
        if not math.isfinite(float(x)) or float(x) < lo or (hi is not None and float(x) > hi):
            raise ValueError(f"{name}={x!r} must be finite and lie in [{lo:g}, {'inf' if hi is None else f'{hi:g}'}]")
    gain = v["icp_gain"]
    if not isinstance(gain, jax.core.Tracer) and float(gain) <= 1.0:
        raise ValueError(f"icp_gain={v['icp_gain']!r} must be above 1: the ICP error decays at omega (gain - 1)")
    f = jnp.result_type(float)
    q, com, soles = stance_references(v["knee_rad"])
    leaves = {k: jnp.asarray(v[k], f) for k in TUNABLE}
    leaves["straight_legs"] = jnp.asarray(1.0 if v["knee_mode"] == "straight" else 0.0, f)
    leaves["step_adjust_on"] = jnp.asarray(1.0 if v["step_adjust"] else 0.0, f)
    leaves["toe_off_on"] = jnp.asarray(1.0 if v["toe_off"] else 0.0, f)
    leaves["late_touchdown_on"] = jnp.asarray(1.0 if v["late_touchdown"] else 0.0, f)
    statics = tuple((k, v[k]) for k in STATIC if k not in SWITCHES)
    return Config(leaves, jnp.asarray(q, f), jnp.asarray(com, f), jnp.asarray(soles, f), statics)
