"""The model protocol: one interface for every plant a sweep or a tuning run can push, and their registry.

A model simulates one push on one robot under a named controller and returns
a few scalars (:class:`RolloutOutputs`). The runner vmaps ``rollout`` over a
chunk, jits it once per configuration and shards the chunk over the devices;
the tuner (:mod:`sweeps.tune`) asks the model for a :class:`TuneProblem`; the
held-out validation (:mod:`sweeps.holdout`) runs ordinary sweeps of it. A
model may also have a ``prepare(config, inputs) -> aux`` step, run on one
device before the sharded call, whose per-rollout outputs (leading axis =
chunk rows) the rollout gets as ``aux`` (``None`` without one): the 3LP model
designs each randomised robot's controller there, so that the batched LAPACK
calls of that design stay out of the sharded call (on a CPU with several host
devices, LAPACK's nested thread-pool parallelism inside concurrent device
programs deadlocked).

Registered models (their modules are imported on first use):

* ``3lp``: the closed-loop 3LP simulation of :func:`jaxlp.simulate.simulate`
  under jaxlp's controllers (:mod:`sweeps.models.threelp`).
* ``mjx``: COMAN in MuJoCo MJX under any controller of
  :mod:`mjx_coman.controllers`, judged on ground truth (:mod:`sweeps.models.mjx`).
"""

from __future__ import annotations

import importlib
from typing import Any, Callable, NamedTuple

import jax

from sweeps.grid import GridError, SweepConfig


class ModelUnavailable(RuntimeError):
    """A registered model that cannot run (the command line exits 2)."""


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
        steps_to_recover: steps after the push until it is back to its gait (-1: never or fell; 0: unpushed).
        max_abs_footstep_adjustment_m: largest footstep adjustment, m.
        fall_time_s: when it fell (``inf``: never).
        nan: the rollout went numerically bad.
        extra: further per-rollout scalars of the model (``{name: scalar}``), kept in the results.
    """

    fell: jax.Array
    steps_to_recover: jax.Array
    max_abs_footstep_adjustment_m: jax.Array
    fall_time_s: jax.Array
    nan: jax.Array
    extra: dict = {}


class TuneProblem(NamedTuple):
    """What the tuner needs of a model: an objective of unconstrained coordinates on fixed scenarios.

    Attributes:
        raw0: the starting point (a pytree of arrays; the optimiser moves it).
        value: ``(raw, split) -> (loss, terms)``, the loss alone (held-out checks, finite differences): MJX
            compiles it apart and so skips the forward-mode gradient; the 3LP reuses ``value_and_grad``'s
            one compilation, whose reverse-mode gradient costs little.
        value_and_grad: ``(raw, split) -> ((loss, terms), grad)`` with ``split`` ``"train"`` or ``"held"``;
            ``terms`` a dict of per-scenario arrays with at least ``"fell"``.
        constants: ``raw -> {name: float}`` the tuned constants in physical units (JSON).
        overrides: ``raw -> {setting: value}`` the controller overrides they stand for.
        info: extra JSON fields of the record (loss definition, scenarios, fixed constants).
    """

    raw0: Any
    value: Callable
    value_and_grad: Callable
    constants: Callable[[Any], dict]
    overrides: Callable[[Any], dict]
    info: dict


class Model(NamedTuple):
    """A registered model.

    ``rollout`` and ``prepare`` get :meth:`SweepConfig.compiled_part` of the
    configuration: the seed and the grid reach them only through the inputs.

    Attributes:
        rollout: ``rollout(config, inputs, aux) -> RolloutOutputs`` (pure, jittable), or ``None``.
        ticks_per_rollout: ``ticks_per_rollout(config) -> int`` environment steps per rollout.
        controllers: ``() -> tuple`` the controller names it runs (``compare``'s default first).
        compare_default: ``() -> tuple`` the controllers ``compare`` runs by default.
        settings: ``(controller) -> tuple[Setting, ...]`` a controller's settings (their defaults).
        check: ``(config, build=True) -> None``: raises ``GridError`` naming a bad controller, override or
            field (``build=False``: names only, no JAX).
        unavailable: why the model cannot run ("" when it can).
        prepare: optional ``prepare(config, inputs) -> aux`` on a chunk's host arrays, run on one device.
        env_step_s: ``env_step_s(config) -> float``, the simulated time of one environment step.
        tune_problem: optional ``(tune_config) -> TuneProblem``.
        holdout_grid: the default held-out grid (``SweepConfig`` fields and ``directions``) of a tuning record.
        own_fields: ``(config) -> dict``: ``SweepConfig`` fields the controller fixes itself (mjx: its gait's
            ``step_time_s``), taken where the command line does not give them.
    """

    rollout: Callable[[SweepConfig, RolloutInputs, Any], RolloutOutputs] | None
    ticks_per_rollout: Callable[[SweepConfig], int]
    controllers: Callable[[], tuple[str, ...]] = lambda: ()
    compare_default: Callable[[], tuple[str, ...]] = lambda: ()
    settings: Callable[[str], tuple] = lambda name: ()
    check: Callable[..., None] = lambda config, build=True: None
    unavailable: str = ""
    prepare: Callable[[SweepConfig, RolloutInputs], Any] | None = None
    env_step_s: Callable[[SweepConfig], float] | None = None
    tune_problem: Callable[[Any], TuneProblem] | None = None
    holdout_grid: Callable[[dict], dict] | None = None
    own_fields: Callable[[SweepConfig], dict] = lambda config: {}


# name -> module whose ``load() -> Model`` builds the model (imported on first use)
_MODULES = {"3lp": "sweeps.models.threelp", "mjx": "sweeps.models.mjx"}
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
        GridError: an unknown name (listing the known ones).
        ModelUnavailable: a registered model that cannot run.
    """
    if name not in MODELS:
        if name not in _MODULES:
            raise GridError(f"unknown model {name!r}; choose one of {', '.join(model_names())}")
        MODELS[name] = importlib.import_module(_MODULES[name]).load()
    model = MODELS[name]
    if model.rollout is None:
        raise ModelUnavailable(model.unavailable or f"model {name!r} is not available")
    return model


def check(config: SweepConfig, build: bool = True) -> SweepConfig:
    """``config`` validated: its fields (:meth:`SweepConfig.validate`), then its model, controller and overrides.

    ``build=False`` checks names only and starts no JAX backend (before ``jax.distributed.initialize``).

    Raises:
        GridError: naming the first bad value. ModelUnavailable: a model that cannot run.
    """
    config.validate()
    get_model(config.model).check(config, build)
    return config


def check_settings(model: str, controller: str, settings, overrides: dict) -> dict:
    """``overrides`` checked against a controller's settings: an unknown key is a ``GridError`` naming it."""
    known = {s.name for s in settings}
    for key in overrides:
        if key not in known:
            raise GridError(f"unknown setting {key!r} of controller {controller} (model {model}); "
                            f"known: {', '.join(sorted(known))}")
    return overrides
