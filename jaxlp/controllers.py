"""Walking controllers of the 3LP model as ``init``/``step`` pairs of pure functions.

A controller is ``init(plan) -> state`` and ``step(plan, state, measurement)
-> (state, command)``, with its state a NamedTuple, as optax builds optimisers
from ``init``/``update`` pairs. The command is the hip-torque correction
``dU = [du_c (N m), du_r (N m/s)]`` per axis, applied as ``du_c + t du_r`` from
now on (``t`` the time since the phase start).

* ``open-loop``: no correction: the nominal gait's torques only.
* ``dlqr``: the DLQR correction ``-K E[k]`` decided from the error at the phase
  start and held for the whole phase (seed 000, "Discrete LQR Control").
* ``time-projection``: at every tick the error is projected back to the phase
  start (seed 000, eq. 16-18), through the tabulated gains.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

CONTROLLERS = ("open-loop", "dlqr", "time-projection")


class Measurement(NamedTuple):
    """What a 3LP controller sees at a tick.

    Attributes:
        tick: control tick within the phase (0 at the phase start).
        error: (2, 4) filtered error per axis (sagittal, lateral), in the
            frame of the ``d = +1`` gait (the lateral axis mirrored back).
    """

    tick: jax.Array
    error: jax.Array


class ControllerPlan(NamedTuple):
    """Gains a controller needs, per axis: ``K`` (2, 2, 4), ``projection`` (ticks, 2, 2, 4)."""

    K: jax.Array
    projection: jax.Array


class Controller(NamedTuple):
    init: Callable
    step: Callable


class OpenLoopState(NamedTuple):
    pass


def _open_init(plan: ControllerPlan) -> OpenLoopState:
    return OpenLoopState()


def _open_step(plan: ControllerPlan, state: OpenLoopState, meas: Measurement):
    return state, jnp.zeros((2, 2), meas.error.dtype)


class DLQRState(NamedTuple):
    """The correction decided at the last phase start, (2, 2)."""

    correction: jax.Array


def _dlqr_init(plan: ControllerPlan) -> DLQRState:
    return DLQRState(correction=jnp.zeros((2, 2), plan.K.dtype))


def _dlqr_step(plan: ControllerPlan, state: DLQRState, meas: Measurement):
    fresh = -jnp.einsum("aij,aj->ai", plan.K, meas.error)
    corr = jnp.where(meas.tick == 0, fresh, state.correction)
    return DLQRState(correction=corr), corr


class TimeProjectionState(NamedTuple):
    pass


def _tp_init(plan: ControllerPlan) -> TimeProjectionState:
    return TimeProjectionState()


def _tp_step(plan: ControllerPlan, state: TimeProjectionState, meas: Measurement):
    G = plan.projection[meas.tick]  # (2 axes, 2, 4)
    return state, jnp.einsum("aij,aj->ai", G, meas.error)


def get_controller(name: str) -> Controller:
    """The ``init``/``step`` pair of a named controller.

    Raises:
        ValueError: an unknown name.
    """
    table = {
        "open-loop": Controller(_open_init, _open_step),
        "dlqr": Controller(_dlqr_init, _dlqr_step),
        "time-projection": Controller(_tp_init, _tp_step),
    }
    if name not in table:
        raise ValueError(f"unknown controller {name!r}; choose one of {', '.join(CONTROLLERS)}")
    return table[name]
