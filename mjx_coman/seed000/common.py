"""What every seed 000 experiment shares: the variants, push timing and one batched, compiled walk."""

from __future__ import annotations

import dataclasses
import functools
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from mjx_coman import controllers
from mjx_coman import rollout as ro
from mjx_coman.actuators import SUPPLY_V
from mjx_coman.controllers.base import joystick

STEP_TIME_S = 0.4
PUSH_DURATION_S = 0.1
PUSH_TABLE_IMPULSES_NS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)  # default grid, 1 N s apart
MARGIN_NS = 0.5  # the margin over twice the open loop's impulse that the push table counts per phase
DIRECTIONS = ("forward", "backward", "left", "right")


FAMILY = "time-projection"
VARIANTS = ("time-projection", "open-loop", "no-deadzone")


def _stack(items):
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *items)


def config(name: str = FAMILY, **overrides):
    """The config of a registered time-projection variant (``time-projection``, ``open-loop``, ``no-deadzone``, ``dlqr``)."""
    ctrl, cfg = controllers.load(name, overrides)
    if ctrl.core() != controllers.get(FAMILY).core():
        raise ValueError(f"{name!r} is not a time-projection variant")
    return cfg


def plant(supply_v: float = SUPPLY_V, friction_scale: float = 1.0):
    """The walking environment with two of its limits switched: the motor supply voltage and the ground friction.

    ``friction_scale`` multiplies the sliding friction of every geom (MuJoCo combines a contact's pair by
    the larger, so the floor's friction scales with it).

    Raises:
        ValueError: a non-finite or non-positive value, named.
    """
    for name, v in (("supply_v", supply_v), ("friction_scale", friction_scale)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}={v} must be finite and positive")
    env = ro.walking_env_params(supply_v=supply_v)
    if friction_scale != 1.0:
        mu = env.model.geom_friction
        env = dataclasses.replace(env, model=env.model.replace(geom_friction=mu.at[:, 0].multiply(friction_scale)))
    return env


def push_start_s(push_step, push_phase, cfg=None) -> float:
    """Start of a push at phase ``push_phase`` of walking step ``push_step`` (after the start-up phase), s."""
    gait = controllers.get(FAMILY).gait(config() if cfg is None else cfg)
    return gait.first_step_s + (np.asarray(push_step) + push_phase) * gait.step_time_s


@functools.lru_cache(maxsize=None)
def _walker(spec, save, truth_estimate: bool = False):
    ctrl = controllers.get(FAMILY)
    if truth_estimate:  # the same controller, given the simulator's state: it estimates from the truth
        ctrl = ctrl._replace(privileged=True)
    return ro.batched_walk(ctrl, spec, save, config_axes=0, joystick_axes=0, privileged_ok=truth_estimate)


def run_batch(env_params, configs, pushes, spec, seed: int = 0, chunk: int = 64, speeds=None, save=None,
              truth_estimate: bool = False):
    """Walk every (config, push, speed) of the lists, in chunks of one compiled vmap.

    ``truth_estimate``: the controller reads the true relative positions instead of its sensors' (a switch
    of the estimate; privileged, for measuring what estimation costs).

    Returns:
        The :class:`~mjx_coman.rollout.WalkResult` with a leading batch axis, as NumPy arrays.
    """
    n = len(configs)
    if n != len(pushes) or n == 0:
        raise ValueError(f"need as many pushes as configs (> 0), got {len(pushes)} and {n}")
    speeds = [0.0] * n if speeds is None else list(speeds)
    size = min(chunk, n)
    fn = _walker(spec, save, truth_estimate)
    keys = jax.random.split(jax.random.PRNGKey(seed), n)
    outs = []
    bar = tqdm(total=n, unit="walk", file=sys.stderr, disable=None, desc="seed000", dynamic_ncols=True)  # off without a TTY
    for i in range(0, n, size):
        idx = list(range(i, min(i + size, n)))
        idx += [idx[-1]] * (size - len(idx))  # pad the last chunk: one compiled batch size
        joy = _stack([joystick(speeds[j]) for j in idx])
        res = fn(_stack([configs[j] for j in idx]), env_params, _stack([pushes[j] for j in idx]),
                 keys[np.array(idx)], joy)
        outs.append(jax.tree_util.tree_map(np.asarray, res))
        bar.update(min(size, n - i))
    bar.close()
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs)[:n], *outs)


def largest_recovered(impulses, recovered) -> np.ndarray:
    """Largest impulse below which every impulse of the grid was recovered (0 if the smallest fell).

    Args:
        impulses: (m,) increasing grid.
        recovered: (..., m) bool.
    """
    rec = np.asarray(recovered, bool)
    ok = np.cumprod(rec, axis=-1).astype(bool)
    grid = np.concatenate([[0.0], np.asarray(impulses, float)])
    return grid[ok.sum(axis=-1)]


def median_steps_to_recover(steps_to_recover) -> float | None:
    """Median ground-truth steps to recover over the settled pushes (``> 0``) of an array (None if none)."""
    s2r = np.asarray(steps_to_recover)
    settled = s2r[s2r > 0]
    return float(np.median(settled)) if settled.size else None
