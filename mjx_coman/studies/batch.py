"""Batched walks of one controller over rows of commands, pushes, scenarios and actuator settings.

    rows = [Row(forward_mps=v) for v in (0.0, 0.2)]
    out = run_rows("footstep-mpc", rows, seconds=20.0)   # one dict of ground-truth figures per row

Rows are grouped by terrain (a scene: one compilation each) and run in chunks of ``batch`` rows (the last
padded by repeating its first row, so every chunk has one shape and one compilation). The joystick, push,
scenario (payload, slope, noise, delay), actuator values and PRNG key are per row; the controller's
configuration is shared. Every figure is the simulator's ground truth (:mod:`mjx_coman.ground_truth`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Callable, NamedTuple

import jax
import numpy as np

from mjx_coman import controllers
from mjx_coman import ground_truth as gt
from mjx_coman import rollout as ro
from mjx_coman import scenarios as sc
from mjx_coman.actuators import JOINT_INDEX
from mjx_coman.floating_base import corner_site_ids
from mjx_coman.studies import metrics

RECORD_EVERY = 10  # control ticks between records (0.02 s at 500 Hz)


class Row(NamedTuple):
    """One walk: joystick, push, scenario, actuator overrides and seed (plain, hashable values).

    Attributes:
        forward_mps: commanded forward speed, m/s.
        turn_rad_per_s: commanded steering rate, rad/s (+ left).
        scenario: the robot's and world's :class:`mjx_coman.scenarios.Scenario`.
        push_ns: impulse of the torso push, N s (0: none).
        push_dir_rad: its world-frame direction, counterclockwise from forward, rad.
        push_start_s: its start, s.
        push_duration_s: its duration, s.
        actuator: ``((name, value), ...)`` overrides of :func:`mjx_coman.actuators.make_actuator_params` on the
            controller's plant (e.g. ``(("torque_loop", "sea"), ("torque_bandwidth_hz", 5.0))``).
        seed: PRNG seed (sensor noise).
    """

    forward_mps: float = 0.0
    turn_rad_per_s: float = 0.0
    scenario: sc.Scenario = sc.Scenario()
    push_ns: float = 0.0
    push_dir_rad: float = 0.0
    push_start_s: float = 0.0
    push_duration_s: float = 0.3
    actuator: tuple = ()
    seed: int = 0


def _env(plant: str, rows: list[Row]):
    """``(params, in_axes)``: each row's scenario on its plant with its actuator overrides, stacked."""
    base = ro.plant_env_params(plant)
    params, axes = sc.batched_env_params(base, [r.scenario for r in rows], scene=True)
    period = float(base.control_period_s)
    acts = []
    for r in rows:
        own = ro.plant_env_params(plant, **dict(r.actuator)).actuator if r.actuator else base.actuator
        ticks = sc.check_delay(r.scenario.delay_ms, int(np.asarray(own.delay_ticks)), period)
        acts.append(dataclasses.replace(own, delay_ticks=np.asarray(ticks, np.asarray(own.delay_ticks).dtype)))
    return dataclasses.replace(params, actuator=_stack(acts)), axes


KNEES = (JOINT_INDEX["RKneeSag"], JOINT_INDEX["LKneeSag"])


def _record(state: ro.RolloutState) -> dict:
    """What each walk saves every ``RECORD_EVERY`` ticks: pelvis, CoM, pelvis yaw, the knees' angles and link
    torques, the sole corners (no telemetry)."""
    full = ro.pelvis_and_com(state)
    d = state.env.data
    knees = {"knee_rad": d.qpos[7 + np.asarray(KNEES)], "knee_torque_nm": d.ctrl[np.asarray(KNEES)],
             "corners_m": d.site_xpos[corner_site_ids()]}
    return {**{k: full[k] for k in ("pelvis_m", "com_m", "pelvis_yaw_rad")}, **knees}


@functools.lru_cache(maxsize=16)
def _walker(core, spec: ro.WalkSpec, plant: str, terrain: str):
    """The jitted, vmapped walk of a controller core and spec on a plant and terrain (the env's in_axes are
    those of any batch of rows there)."""
    axes = _env(plant, [Row(scenario=sc.Scenario(terrain=terrain))])[1]

    def one(config, env_params, push, key, joystick):
        return ro.walk(core, config, env_params, push, key, spec, joystick, ro.SaveAt(_record, every=RECORD_EVERY))

    return jax.jit(jax.vmap(one, in_axes=(None, axes, 0, 0, 0)))



def _stack(xs):
    return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *xs)


def _push(r: Row) -> ro.Push:
    if r.push_ns <= 0:
        return ro.no_push()
    return ro.make_push(r.push_start_s, r.push_duration_s, impulse_ns=r.push_ns, direction_rad=r.push_dir_rad)


def check_rows(name: str, rows: list[Row], seconds: float, overrides: dict | None = None) -> None:
    """Check rows against the controller before anything is built.

    Raises:
        ValueError: no rows, a bad duration, a joystick beyond the controller's range, a bad scenario, a push
            that ends after the walk; naming the value.
    """
    if not rows:
        raise ValueError("no rows to run")
    if not (math.isfinite(seconds) and 0 < seconds <= 600):
        raise ValueError(f"seconds={seconds!r} must lie in (0, 600]")
    ctrl, config = controllers.load(name, overrides or {})
    gait = ctrl.gait(config)
    for r in rows:
        gait.check_joystick(r.forward_mps, 0.0, r.turn_rad_per_s)
        r.scenario.validate()
        if r.push_ns > 0 and r.push_start_s + r.push_duration_s > seconds:
            raise ValueError(f"a push ending at {r.push_start_s + r.push_duration_s:g} s is after the walk "
                             f"({seconds:g} s)")


def run_rows(name: str, rows: list[Row], seconds: float, overrides: dict | None = None, *, batch: int = 8,
             progress: Callable[[int], None] | None = None) -> list[dict]:
    """Every row walked by the controller ``name`` for ``seconds``; one dict of figures per row, in order.

    Args:
        name: a registered controller.
        rows: the walks.
        seconds: duration of each walk, s.
        overrides: settings of the controller (shared by every row). A controller that plans on a known terrain
            (a ``terrain`` setting) is told each row's unless ``overrides`` sets it.
        batch: rows per compiled call (the compilation's batch size; a rough terrain with fewer rows: their number).
        progress: called with the number of rows finished after each chunk.

    Returns:
        Per row :func:`mjx_coman.studies.metrics.summary` (fell, fall time, mean speed, heading change,
        steps to recover, CoM-speed cycle, ...).

    Raises:
        ValueError: see :func:`check_rows`.
    """
    check_rows(name, rows, seconds, overrides)
    ctrl, config = controllers.load(name, overrides or {})
    plant = ctrl.gait(config).plant
    out: list[dict | None] = [None] * len(rows)
    by_terrain: dict[str, list[int]] = {}
    for i, r in enumerate(rows):
        by_terrain.setdefault(r.scenario.validate().terrain, []).append(i)
    done = 0
    for terrain, idx in by_terrain.items():
        spec = ro.WalkSpec(seconds=float(seconds), judge=gt.judge_on(terrain))
        if "terrain" in ctrl.defaults() and "terrain" not in (overrides or {}):
            config = controllers.load(name, {**(overrides or {}), "terrain": terrain})[1]
        size = batch if terrain == "flat" else min(batch, len(idx))  # flat: one shape for every experiment
        for lo in range(0, len(idx), size):
            part = idx[lo:lo + size]
            chunk = [rows[i] for i in part]
            chunk += [chunk[0]] * (size - len(chunk))
            env = _env(plant, chunk)[0]
            # flat: one cached compilation for every experiment; a terrain's walker is dropped after its rows (a
            # dozen stair scenes kept compiled exhausted a 23 GB machine)
            fn = (_walker if terrain == "flat" else _walker.__wrapped__)(ctrl.core(), spec, plant, terrain)
            pushes = _stack([_push(r) for r in chunk])
            keys = np.stack([np.asarray(jax.random.PRNGKey(r.seed)) for r in chunk])
            joy = _stack([controllers.joystick(r.forward_mps, turn_rad_per_s=r.turn_rad_per_s) for r in chunk])
            res = jax.tree_util.tree_map(np.asarray, fn(config, env, pushes, keys, joy))
            period = float(ctrl.gait(config).control_period_s)
            for j, i in enumerate(part):
                one = jax.tree_util.tree_map(lambda x: x[j], res)
                out[i] = metrics.summary(one, pushed=rows[i].push_ns > 0, record_period_s=period * RECORD_EVERY,
                                         terrain=terrain)
            done += len(part)
            if progress is not None:
                progress(done)
    return out
