"""The rollout registry: one pure function per model, ``rollout(config, inputs, aux) -> outputs``.

A rollout simulates one push on one robot and returns a few scalars
(:class:`RolloutOutputs`). The runner vmaps it over a chunk of rollouts, jits
it once per configuration and shards the chunk over the devices, so a model
only has to be a pure, jittable function of scalars. A model may also have a
``prepare(config, inputs) -> aux`` step, run on one device before the sharded
call, whose per-rollout outputs (leading axis = chunk rows) the rollout gets
as ``aux`` (``None`` without one): the 3LP model designs each randomised
robot's controller there, so that the batched LAPACK calls of that design stay
out of the sharded call (on a CPU with several host devices, LAPACK's nested
thread-pool parallelism inside concurrent device programs deadlocked).

Registered models (their modules are imported on first use):

* ``3lp``: the closed-loop 3LP simulation of :func:`jaxlp.simulate.simulate` (:mod:`sweeps.model_3lp`).
* ``mjx``: COMAN in MuJoCo MJX under the walking controller of
  :mod:`mjx_coman.walking` (:mod:`sweeps.model_mjx`); unavailable (exit 2 on
  the command line) while ``mjx_coman.walking.rollout.walk`` does not exist.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable, NamedTuple

import jax

from sweeps.grid import SweepConfig


class ModelUnavailable(RuntimeError):
    """A registered model that cannot run yet (the command line exits 2)."""


class RolloutInputs(NamedTuple):
    """One rollout's inputs (scalars; batched by the runner).

    Attributes:
        index: global rollout index.
        key: the rollout's PRNG key data, ``key_data(fold_in(PRNGKey(seed), index))``, uint32 (2,).
        phase: push start as a fraction of the step.
        impulse_ns: push impulse, N s.
        direction_rad: push heading, rad (0 forward, pi/2 left).
    """

    index: jax.Array
    key: jax.Array
    phase: jax.Array
    impulse_ns: jax.Array
    direction_rad: jax.Array


class RolloutOutputs(NamedTuple):
    """One rollout's outcome.

    Attributes:
        fell: left the model's valid range (or went non-finite).
        steps_to_recover: steps after the push until the error stays small (-1: never or fell).
        max_abs_footstep_adjustment_m: largest |sagittal footstep adjustment|, m.
        fall_time_s: when it fell (``inf``: never).
        nan: the rollout went numerically bad.
    """

    fell: jax.Array
    steps_to_recover: jax.Array
    max_abs_footstep_adjustment_m: jax.Array
    fall_time_s: jax.Array
    nan: jax.Array


class Model(NamedTuple):
    """A registered model.

    ``rollout`` and ``prepare`` get :meth:`SweepConfig.compiled_part` of the
    configuration: the seed and the grid reach them only through the inputs.

    Attributes:
        rollout: ``rollout(config, inputs, aux) -> RolloutOutputs`` (pure, jittable), or ``None``.
        ticks_per_rollout: ``ticks_per_rollout(config) -> int`` environment steps per rollout.
        unavailable: why the model cannot run yet ("" when it can).
        prepare: optional ``prepare(config, inputs) -> aux`` on a chunk's host arrays, run on one
            device; ``aux`` is a pytree of arrays with the chunk's rows on the leading axis.
        env_step_s: ``env_step_s(config) -> float``, the simulated time of one environment step.
    """

    rollout: Callable[[SweepConfig, RolloutInputs, Any], RolloutOutputs] | None
    ticks_per_rollout: Callable[[SweepConfig], int]
    unavailable: str = ""
    prepare: Callable[[SweepConfig, RolloutInputs], Any] | None = None
    env_step_s: Callable[[SweepConfig], float] | None = None


# name -> module whose ``load() -> Model`` builds the model (imported on first use)
_MODULES = {"3lp": "sweeps.model_3lp", "mjx": "sweeps.model_mjx"}
MODELS: dict[str, Model] = {}


def register_model(name: str, model: Model) -> None:
    """Add or replace a model in the registry."""
    MODELS[name] = model


def model_names() -> tuple[str, ...]:
    """Every model name the registry knows."""
    return tuple(dict.fromkeys((*_MODULES, *MODELS)))


def get_model(name: str) -> Model:
    """A runnable model.

    Raises:
        ValueError: an unknown name.
        ModelUnavailable: a registered model that cannot run yet.
    """
    if name not in MODELS:
        if name not in _MODULES:
            raise ValueError(f"unknown model {name!r}; choose one of {', '.join(model_names())}")
        MODELS[name] = importlib.import_module(_MODULES[name]).load()
    model = MODELS[name]
    if model.rollout is None:
        raise ModelUnavailable(model.unavailable or f"model {name!r} is not available")
    return model
