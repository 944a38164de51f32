"""The controller interface: what every walking controller of the simulated COMAN is.

A controller is a :class:`Controller`, a NamedTuple of pure functions made
once per family (as an optax ``GradientTransformation`` is):

    config = controller.make_config(**settings)        # host; validated; ValueError names a bad value
    state = controller.init(config, env_params, key)
    state, command, telemetry = controller.step(config, state, observation)

``config`` is a pytree: its array leaves are the tunables (``jax.grad`` and
optax reach them, ``config.replace(name=value)`` moves them), its static
fields (sizes, tables' shapes, the step time) are fixed when it is built.
Every settable name of ``make_config`` is declared by a :class:`Setting`.

The observation holds only what the robot measures (:class:`Observation`:
sensor readings, the joystick's commanded velocities, the time). A controller
that reads the simulator's ground truth says so (``privileged=True``); it then
gets the ``mjx.Data`` in ``observation.truth``, and the rollout refuses it
unless the caller allows privileged controllers (:func:`mjx_coman.rollout.walk`).

Each step also returns a :class:`Telemetry`: the same fields for every
controller (support foot, step and phase, planned next footstep and its
adjustment, the estimated CoM or pelvis state) plus a controller-specific
pytree in ``extra``, so plots and sweeps need no knowledge of the controller.
Nothing here judges a controller: falls and recoveries are measured on the
simulator (:mod:`mjx_coman.ground_truth`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

SUPPORT_DOUBLE, SUPPORT_LEFT, SUPPORT_RIGHT = 0, 1, 2
PLANTS = ("position", "torque-ideal", "torque-sea")


class Setting(NamedTuple):
    """One settable name of a controller family's ``make_config``.

    Attributes:
        name: keyword of ``make_config`` (units in the name).
        default: plain value: float, int, bool, str, ``None`` or a tuple of floats.
        help: one line.
        tunable: the config holds it as an array leaf of the same name, which
            ``jax.grad`` and optax reach without rebuilding the config.
        bounds: ``(low, high)`` of a tunable (either ``None``: unbounded on that side);
            a tuner moves it in unconstrained coordinates within them.
    """

    name: str
    default: Any
    help: str
    tunable: bool = False
    bounds: tuple | None = None


class Joystick(NamedTuple):
    """Commanded velocities (arrays; vmappable), heading frame.

    Attributes:
        forward_mps: forward speed, m/s.
        lateral_mps: leftward speed, m/s.
        turn_rad_per_s: turn rate about the vertical, rad/s (left > 0).
    """

    forward_mps: jax.Array
    lateral_mps: jax.Array
    turn_rad_per_s: jax.Array


def joystick(forward_mps=0.0, lateral_mps=0.0, turn_rad_per_s=0.0) -> Joystick:
    """A validated :class:`Joystick` of JAX's default float.

    Raises:
        ValueError: a non-finite velocity, naming it.
    """
    vals = dict(forward_mps=forward_mps, lateral_mps=lateral_mps, turn_rad_per_s=turn_rad_per_s)
    for name, v in vals.items():
        if not isinstance(v, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(v, float))):
            raise ValueError(f"{name}={v!r} must be finite")
    f = jnp.result_type(float)
    return Joystick(*(jnp.asarray(v, f) for v in vals.values()))


class Observation(NamedTuple):
    """What a controller sees at one control tick.

    Attributes:
        readings: the sensors (:class:`mjx_coman.sensors.Readings`).
        joystick: the commanded velocities.
        time_s: time since the walk started, s.
        truth: ``mjx.Data`` for a privileged controller; ``None`` otherwise.
    """

    readings: Any
    joystick: Joystick
    time_s: jax.Array
    truth: Any = None


class Telemetry(NamedTuple):
    """What every controller reports each tick (its own estimates, never a verdict).

    Positions are horizontal ``(x, y)`` in the heading frame (x along the pelvis
    heading, z up), relative to the current stance foot.

    Attributes:
        support: int32, :data:`SUPPORT_DOUBLE`, :data:`SUPPORT_LEFT` or :data:`SUPPORT_RIGHT`.
        step: int32 index of the controller's step (-1: start-up, before the first).
        phase: share of the current step done, in [0, 1].
        next_footstep_m: (2,) planned landing of the swing foot, m.
        footstep_adjustment_m: (2,) its offset from the controller's nominal plan, m.
        com_m: (2,) estimated CoM (or pelvis) position, m.
        com_vel_mps: (2,) its velocity, m/s.
        extra: controller-specific pytree (``()`` for none).
        ok: bool scalar, False when the controller could not compute a valid
            command this tick (a failed or inaccurate QP solve: its command is
            then a finite fallback); the rollout records it as a fall.
            ``None`` (the default) for a controller that cannot fail.
    """

    support: jax.Array
    step: jax.Array
    phase: jax.Array
    next_footstep_m: jax.Array
    footstep_adjustment_m: jax.Array
    com_m: jax.Array
    com_vel_mps: jax.Array
    extra: Any = ()
    ok: Any = None


def standing_telemetry(dtype=jnp.float32, extra=()) -> Telemetry:
    """The telemetry of a controller that stands on both feet and plans no step."""
    z = jnp.zeros(2, dtype)
    return Telemetry(jnp.asarray(SUPPORT_DOUBLE, jnp.int32), jnp.asarray(-1, jnp.int32), jnp.zeros((), dtype),
                     z, z, z, z, extra)


class Gait(NamedTuple):
    """Host facts of a configured controller that the rollout and the sweeps need (plain values).

    Attributes:
        knee_rad: knee flexion of the crouched stance the walk is reset to.
        control_period_s: the controller's tick, s (must equal the environment's).
        first_step_s: when walking step 0 begins, s (after any start-up).
        step_time_s: nominal duration of one step, s (pushes are timed by it).
        max_forward_mps: largest commanded forward speed it walks, m/s.
        max_lateral_mps: largest commanded lateral speed, m/s (0: it does not side-step).
        max_turn_rad_per_s: largest commanded turn rate, rad/s (0: it does not turn).
        plant: how its commands reach the joints, one of :data:`PLANTS`: ``"position"``
            (motor-angle commands through the seed 000 position loops), ``"torque-ideal"``
            (link torques, ideal tracking), ``"torque-sea"`` (link torques through the
            series-elastic torque loop); :func:`mjx_coman.rollout.plant_env_params` builds it.
    """

    knee_rad: float
    control_period_s: float
    first_step_s: float
    step_time_s: float
    max_forward_mps: float
    max_lateral_mps: float = 0.0
    max_turn_rad_per_s: float = 0.0
    plant: str = "position"

    def check_joystick(self, forward_mps: float, lateral_mps: float = 0.0, turn_rad_per_s: float = 0.0) -> None:
        """Raise ``ValueError`` naming a commanded velocity beyond what the controller walks."""
        for name, v, top in (("forward_mps", forward_mps, self.max_forward_mps),
                             ("lateral_mps", lateral_mps, self.max_lateral_mps),
                             ("turn_rad_per_s", turn_rad_per_s, self.max_turn_rad_per_s)):
            if not math.isfinite(v) or abs(v) > top + 1e-12:
                raise ValueError(f"{name}={v!r} is beyond this controller's +-{top:g}")


class Core(NamedTuple):
    """The part of a controller a compiled rollout depends on: the same for every variant of a family."""

    init: Callable
    step: Callable
    gait: Callable
    privileged: bool


class Controller(NamedTuple):
    """A walking controller: pure functions, its settings and their defaults.

    Attributes:
        name: registry name (a variant shares the family's functions).
        make_config: ``make_config(**settings) -> config`` on the host; ``ValueError`` names a bad value.
        init: ``init(config, env_params, key) -> state``.
        step: ``step(config, state, observation) -> (state, mjx_coman.env.Command, Telemetry)``.
        gait: ``gait(config) -> Gait`` (host).
        settings: every keyword of ``make_config``, with this variant's defaults.
        privileged: reads the simulator's ground truth (``observation.truth``).
        description: one line.
        tune_default: the tunable settings ``coman-sweep tune`` tunes unless told (``()``: every tunable).
    """

    name: str
    make_config: Callable[..., Any]
    init: Callable[[Any, Any, jax.Array], Any]
    step: Callable[[Any, Any, Observation], tuple[Any, Any, Telemetry]]
    gait: Callable[[Any], Gait]
    settings: tuple[Setting, ...]
    privileged: bool = False
    description: str = ""
    tune_default: tuple[str, ...] = ()

    def defaults(self) -> dict[str, Any]:
        """``{setting: default}`` of this variant."""
        return {s.name: s.default for s in self.settings}

    def tunables(self) -> tuple[str, ...]:
        """Names of the settings that are array leaves of the config."""
        return tuple(s.name for s in self.settings if s.tunable)

    def variant(self, name: str, description: str = "", **defaults) -> "Controller":
        """The same functions under another name with other defaults (a registered configuration).

        Raises:
            ValueError: a default for a name that is not a setting.
        """
        known = self.defaults()
        bad = [k for k in defaults if k not in known]
        if bad:
            raise ValueError(f"{name}: unknown setting {bad[0]!r} of {self.name}; known: {', '.join(known)}")
        settings = tuple(s._replace(default=defaults.get(s.name, s.default)) for s in self.settings)
        return self._replace(name=name, settings=settings, description=description or self.description)

    def core(self) -> Core:
        """What a compiled rollout depends on: the same for every variant of a family."""
        return Core(self.init, self.step, self.gait, self.privileged)
