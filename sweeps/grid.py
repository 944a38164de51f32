"""Sweep configuration and the push grid (phase x impulse, one direction or several, optionally x scenarios).

A sweep is a frozen :class:`SweepConfig` (plain Python values, hashable, so it
keys the jit cache and the results directory) and the rollouts it implies:
row ``i = phase_index * n_impulses + impulse_index``. With several push
directions (``SweepConfig.directions``) that grid repeats per direction,
direction-major: rows ``d * block .. (d + 1) * block`` are direction ``d``'s
(``block`` the rows of one direction). With ``repeats`` K > 1 the whole
grid (every direction) runs K times, repeat-major, each rollout with its
own randomness (sensor noise, randomised robot). With scenario axes
(``SweepConfig.scenario``: payload, slope, noise, delay, terrain of
:mod:`mjx_coman.scenarios`) every cell of that grid runs once per scenario,
scenario-minor: row ``i = cell * n_scenarios + scenario_index`` (so rows
``s::n_scenarios`` are scenario ``s``'s grid, in the order above). Every
rollout draws its randomness from ``fold_in(PRNGKey(seed), i)``, so results
do not depend on the chunk size, the number of devices or the order chunks run in.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
from typing import NamedTuple

import numpy as np

from sweeps.axes import (DIRECTIONS_RAD, MAX_AXIS, GridError, arg_type, direction_rad, parse_directions,  # noqa: F401
                         parse_impulses, parse_phases)

RESULTS_VERSION = 4  # in every hash: 2 judges MJX walks on ground truth (steps to recover, falls), as 1 did not;
# 3 adds the MJX walks' knee torques and cost of transport; 4 records a controller's failed solve as such
# (``solve_failed``), where 3 called it non-finite when the solve's diagnostics were infinite


# scenario axes (mjx_coman.scenarios.Scenario fields) a sweep may vary; terrain is one value per config
ENGINES = ("mjx", "native")  # mjx_coman.engines.ENGINES (checked without importing mjx_coman)
SCENARIO_AXES = ("actuator", "delay_ms", "imu_noise_deg", "joint_noise_deg", "payload_kg", "slope_deg", "terrain")
TEXT_AXES = ("actuator", "terrain")  # axes whose values are words
MJX_CONTROL_PERIOD_S = 0.002
MAX_N_STEPS = 200  # 80 s of 0.4 s steps; a billion steps was an out-of-memory traceback
MAX_ROLLOUTS = 10_000_000  # per sweep: its results alone take about RESULT_BYTES each in memory
RESULT_BYTES = 160  # per rollout in results.npz and in memory (about 16 columns of 4-8 bytes, plus the csv row)


@dataclasses.dataclass(frozen=True)
class SweepConfig:
    """Everything that decides a sweep's results (plain values, hashable).

    Attributes:
        model: rollout model name (``"3lp"`` or ``"mjx"``; see :mod:`sweeps.models`).
        controller: a controller name of the model (``mjx``: :func:`mjx_coman.controllers.names`).
        controller_overrides: ``((setting, value), ...)`` sorted: the controller's settings changed from its
            defaults (``--set KEY=VALUE``; part of the sweep's identity).
        robot: 3LP parameter preset (:func:`jaxlp.presets.get_params`).
        phases: push start times as fractions of the step, in [0, 1).
        impulses_ns: push impulses, N s (force = impulse / duration).
        direction: ``forward``, ``backward``, ``left``, ``right`` or degrees from forward (``"45"``).
        directions: several push directions, each a whole grid (direction-major rows); ``()``: ``direction``
            alone.
        repeats: runs of the whole grid, each rollout with its own draw of noise and robot (repeat-major rows).
        push_step: index of the step during which the push starts.
        push_duration_s: push duration, s.
        speed_mps: commanded walking speed (0: in place).
        step_time_s: phase duration, s.
        n_steps: phases simulated per rollout.
        noise_std_m: 3LP: sensor noise std on relative positions, m (sensing on if > 0 or bias).
        bias_m: 3LP: constant sagittal pelvis position bias, m.
        bias_std_m: 3LP: std of a per-rollout sagittal bias of the swing and pelvis positions, m (sensing on).
        recover_tol: 3LP: dimensionless landing error under which a step counts as recovered.
        sensor_noise_scale: MJX: IMU, gyro and F/T noise as a multiple of COMAN's nominal
            levels (:func:`mjx_coman.sensors.make_sensor_params`); 0: noise-free (12-bit encoders stay).
        encoder_offset_std_rad: MJX: std of constant per-joint link encoder offsets, drawn per rollout, rad.
        randomize_mass_pct: per-rollout uniform +-% on the body masses (3LP: ``m1``, ``m2``; MJX: every
            body, inertia alike) (0: off).
        randomize_leg_pct: 3LP: per-rollout uniform +-% on the leg length ``h1`` (``h2``, ``I2`` follow).
        randomize_spring_pct: MJX: per-rollout uniform +-% on the SEA spring stiffness (one factor per joint).
        randomize_delay_ticks: MJX: per-rollout uniform integer offset in [-k, k] control ticks on the
            transport delay (nominal 10 ticks = 20 ms).
        scenario: MJX: ``((axis, (value, ...)), ...)`` sorted by axis (:data:`SCENARIO_AXES`): every grid cell
            runs under each combination (``freeze_scenario``; ``terrain`` takes one value, a scene); ``()``: none.
        seed: PRNG seed.
        chunk: rollouts per chunk (one jitted call; also the resume unit).
        x64: simulate in 64-bit floats.
        engine: MJX: the physics engine, ``mjx`` (MuJoCo MJX, differentiable) or ``native`` (MuJoCo C over
            the CPU's threads, :mod:`mjx_coman.engines`).
    """

    model: str = "3lp"
    controller: str = "time-projection"
    controller_overrides: tuple = ()
    robot: str = "coman"
    phases: tuple[float, ...] = tuple(k / 16 for k in range(16))
    impulses_ns: tuple[float, ...] = tuple(float(v) for v in np.linspace(0.0, 20.0, 41))
    direction: str = "forward"
    directions: tuple[str, ...] = ()
    repeats: int = 1
    push_step: int = 2
    push_duration_s: float = 0.1
    speed_mps: float = 0.0
    step_time_s: float = 0.4
    n_steps: int = 10
    noise_std_m: float = 0.0
    bias_m: float = 0.0
    bias_std_m: float = 0.0
    recover_tol: float = 0.02
    randomize_mass_pct: float = 0.0
    randomize_leg_pct: float = 0.0
    sensor_noise_scale: float = 0.0
    encoder_offset_std_rad: float = 0.0
    randomize_spring_pct: float = 0.0
    randomize_delay_ticks: int = 0
    scenario: tuple = ()
    seed: int = 0
    chunk: int = 256
    x64: bool = False
    engine: str = "mjx"

    def validate(self) -> "SweepConfig":
        """Raise :class:`GridError` naming the first bad value; return ``self``.

        The model, the controller name and its overrides are the model's to check (:func:`sweeps.models.check`).
        """
        if not isinstance(self.controller_overrides, tuple) or any(
                not (isinstance(kv, tuple) and len(kv) == 2 and isinstance(kv[0], str)) for kv in self.controller_overrides):
            raise GridError(f"controller_overrides must be ((setting, value), ...), got {self.controller_overrides!r}")
        if list(self.controller_overrides) != sorted(self.controller_overrides, key=lambda kv: kv[0]):
            raise GridError("controller_overrides must be sorted by setting (use with_overrides)")
        for d in (self.direction, *self.directions):
            direction_rad(d)
        if not isinstance(self.directions, tuple):
            raise GridError(f"directions must be a tuple, got {self.directions!r}")
        if not isinstance(self.repeats, int) or not 1 <= self.repeats <= MAX_AXIS:
            raise GridError(f"repeats must be a whole number in [1, {MAX_AXIS}], got {self.repeats!r}")
        if not self.phases or not self.impulses_ns:
            raise GridError("the grid is empty (no phases or no impulses)")
        if any(v < 0 or not math.isfinite(v) for v in self.impulses_ns):
            raise GridError(f"impulses must be finite and non-negative, got {list(self.impulses_ns)}")
        if any(not (0.0 <= v < 1.0) for v in self.phases):
            raise GridError(f"phases must lie in [0, 1), got {list(self.phases)}")
        for name in ("push_duration_s", "step_time_s", "recover_tol"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise GridError(f"{name} must be finite and positive, got {v}")
        for name in ("speed_mps", "bias_m"):
            if not math.isfinite(getattr(self, name)):
                raise GridError(f"{name} must be finite, got {getattr(self, name)}")
        for name in ("noise_std_m", "bias_std_m", "sensor_noise_scale", "encoder_offset_std_rad", "randomize_mass_pct",
                     "randomize_leg_pct", "randomize_spring_pct", "randomize_delay_ticks"):
            if not getattr(self, name) >= 0 or not math.isfinite(getattr(self, name)):
                raise GridError(f"{name} must be finite and non-negative, got {getattr(self, name)}")
        for name in ("randomize_mass_pct", "randomize_leg_pct", "randomize_spring_pct"):
            if getattr(self, name) >= 50:
                raise GridError(f"{name} must stay below 50 %, got {getattr(self, name)}")
        only = {"3lp": ("noise_std_m", "bias_m", "bias_std_m", "randomize_leg_pct"),
                "mjx": ("sensor_noise_scale", "encoder_offset_std_rad", "randomize_spring_pct",
                        "randomize_delay_ticks")}
        for model, names in only.items():
            for name in names:
                if self.model != model and getattr(self, name) != 0:
                    raise GridError(f"{name} applies to --model {model} only, got {getattr(self, name)} "
                                    f"with --model {self.model}")
        if self.engine not in ENGINES:
            raise GridError(f"engine must be one of {', '.join(ENGINES)}, got {self.engine!r}")
        if self.model != "mjx" and self.engine != "mjx":
            raise GridError(f"engine applies to --model mjx only, got {self.engine!r} with --model {self.model}")
        if self.model != "3lp" and self.recover_tol != SweepConfig.recover_tol:
            raise GridError(f"recover_tol applies to --model 3lp only (mjx walks are judged on ground truth)")
        if self.model != "3lp" and self.robot != SweepConfig.robot:
            raise GridError(f"robot applies to --model 3lp only (the mjx model is COMAN), got {self.robot!r} "
                            f"with --model {self.model}")
        if self.n_steps > MAX_N_STEPS:
            raise GridError(f"n_steps must be at most {MAX_N_STEPS} (each rollout records every step), "
                            f"got {self.n_steps}")
        if self.n_steps < 1 or self.push_step < 0 or self.push_step >= self.n_steps:
            raise GridError(f"push_step must lie in [0, n_steps={self.n_steps}), got {self.push_step}")
        if not 0 <= self.seed < 2**32:
            raise GridError(f"seed must lie in [0, 2**32), got {self.seed}")
        if self.chunk < 1:
            raise GridError(f"chunk must be >= 1, got {self.chunk}")
        self._validate_scenario()
        if self.n_rollouts > MAX_ROLLOUTS:
            raise GridError(f"the grid has {self.n_rollouts} rollouts (about {self.n_rollouts * RESULT_BYTES / 1e9:.1f} "
                            f"GB of results), more than {MAX_ROLLOUTS}; use fewer phases, impulses or scenario values")
        return self

    def _validate_scenario(self) -> None:
        if not self.scenario:
            return
        sc = self.scenario
        if not isinstance(sc, tuple) or any(not (isinstance(a, tuple) and len(a) == 2 and isinstance(a[1], tuple))
                                            for a in sc):
            raise GridError(f"scenario must be ((axis, (value, ...)), ...), got {sc!r} (use freeze_scenario)")
        names = [a for a, _ in sc]
        for a in names:
            if a not in SCENARIO_AXES:
                raise GridError(f"unknown scenario axis {a!r}; choose from {', '.join(SCENARIO_AXES)}")
        if names != sorted(set(names)):
            raise GridError(f"scenario axes must be sorted and distinct, got {names} (use freeze_scenario)")
        if self.model != "mjx":
            raise GridError(f"scenario axis {names[0]} applies to --model mjx only, got --model {self.model}")
        from mjx_coman.scenarios import Scenario, check_delay, nominal_delay_ticks

        for a, values in sc:
            if not values:
                raise GridError(f"scenario axis {a} has no values")
            if a == "terrain" and len(values) > 1:
                raise GridError(f"terrain takes one value per sweep, got {list(values)} (each terrain is a scene "
                                "and its own run)")
            for v in values:
                try:
                    canonical = Scenario(**{a: v}).validate()
                    if a == "terrain" and canonical.terrain != v:
                        raise ValueError(f"terrain {v!r} must be written {canonical.terrain!r}")
                    if a == "delay_ms":  # on the MJX plant's 2 ms control tick (rechecked on the built env)
                        check_delay(v, nominal_delay_ticks(MJX_CONTROL_PERIOD_S), MJX_CONTROL_PERIOD_S)
                except ValueError as e:
                    raise GridError(f"scenario axis {a}: {e}") from None
            if len(set(values)) != len(values):
                raise GridError(f"scenario axis {a} repeats a value: {list(values)}")

    @property
    def n_scenarios(self) -> int:
        """Scenario combinations per grid cell (1 without scenario axes)."""
        return math.prod(len(v) for _, v in self.scenario) if self.scenario else 1

    def scenarios(self) -> list[dict]:
        """``{axis: value}`` of each scenario, in row order (the last axis fastest); ``[{}]`` without axes."""
        names = [a for a, _ in self.scenario]
        return [dict(zip(names, combo)) for combo in itertools.product(*(v for _, v in self.scenario))]

    @property
    def terrain(self) -> str:
        """The sweep's terrain (``flat`` unless a terrain axis says otherwise)."""
        return dict(self.scenario).get("terrain", ("flat",))[0]

    def overrides(self) -> dict:
        """``controller_overrides`` as a dict."""
        return dict(self.controller_overrides)

    def with_overrides(self, overrides: dict) -> "SweepConfig":
        """A copy with these controller overrides (sorted, lists made tuples)."""
        return dataclasses.replace(self, controller_overrides=freeze_overrides(overrides))

    @property
    def sensing(self) -> bool:
        return self.noise_std_m > 0 or self.bias_m != 0

    @property
    def direction_list(self) -> tuple[str, ...]:
        """The push directions, in row order."""
        return self.directions or (self.direction,)

    @property
    def n_per_direction(self) -> int:
        """Rows of one direction (phases x impulses x scenarios)."""
        return len(self.phases) * len(self.impulses_ns) * self.n_scenarios

    @property
    def n_per_repeat(self) -> int:
        """Rows of one run of the grid (every direction)."""
        return self.n_per_direction * len(self.direction_list)

    @property
    def n_rollouts(self) -> int:
        return self.n_per_repeat * self.repeats

    def for_direction(self, d: int) -> "SweepConfig":
        """The single-direction configuration of direction ``d`` (for reports on its rows, every repeat)."""
        return dataclasses.replace(self, direction=self.direction_list[d], directions=())

    def for_repeat(self) -> "SweepConfig":
        """The configuration of one repeat's rows."""
        return dataclasses.replace(self, repeats=1)

    def compiled_part(self) -> "SweepConfig":
        """The configuration without what reaches the rollouts as inputs (seed, grid, directions, chunk).

        Models see only this, so sweeps that differ in seed or grid share compiled code. The scenario
        axes stay (a rollout finds its scenario from its index: ``index % n_scenarios``).
        """
        return dataclasses.replace(self, seed=0, phases=(0.0,), impulses_ns=(0.0,), chunk=1, direction="forward",
                                   directions=(), repeats=1)

    def to_dict(self) -> dict:
        """Every field as JSON values (the overrides as a dict) and the results version."""
        d = dataclasses.asdict(self)
        d["phases"], d["impulses_ns"] = list(self.phases), list(self.impulses_ns)
        d["controller_overrides"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.controller_overrides}
        if self.scenario:
            d["scenario"] = {a: list(v) for a, v in self.scenario}
        else:
            del d["scenario"]  # absent, so that sweeps without scenarios keep their hashes
        if self.directions:
            d["directions"] = list(self.directions)
        else:
            del d["directions"]  # likewise
        if self.repeats == 1:
            del d["repeats"]  # likewise
        if self.engine == "mjx":
            del d["engine"]  # likewise
        d["results_version"] = RESULTS_VERSION
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SweepConfig":
        """The inverse of :meth:`to_dict` (``results_version`` dropped)."""
        d = {k: v for k, v in d.items() if k != "results_version"}
        d["phases"], d["impulses_ns"] = tuple(d["phases"]), tuple(d["impulses_ns"])
        d["controller_overrides"] = freeze_overrides(d.get("controller_overrides") or {})
        d["scenario"] = freeze_scenario(d.get("scenario") or {})
        d["directions"] = tuple(d.get("directions") or ())
        return cls(**d)

    def hash(self) -> str:
        """A short digest of every field (the results directory's identity)."""
        blob = json.dumps(self.to_dict(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def _freeze(v):
    return tuple(_freeze(x) for x in v) if isinstance(v, (list, tuple)) else v


def freeze_overrides(overrides: dict) -> tuple:
    """``{setting: value}`` as the hashable, sorted ``controller_overrides`` of a config."""
    return tuple(sorted((str(k), _freeze(v)) for k, v in dict(overrides).items()))


def freeze_scenario(axes: dict) -> tuple:
    """``{axis: values}`` as the hashable, sorted ``scenario`` of a config (numbers as floats, words as text)."""
    out = []
    for a, values in sorted(dict(axes).items()):
        vals = values if isinstance(values, (list, tuple)) else (values,)
        out.append((str(a), tuple(str(v) if a in TEXT_AXES else float(v) for v in vals)))
    return tuple(out)


class GridInputs(NamedTuple):
    """Per-rollout inputs, each of shape (n,).

    Attributes:
        index: global rollout index (also the PRNG stream).
        phase: push start as a fraction of the step.
        impulse_ns: push impulse, N s.
        direction_rad: push heading, rad.
        scenario_index: the row's scenario (``index % n_scenarios``; 0 without scenario axes).
    """

    index: np.ndarray
    phase: np.ndarray
    impulse_ns: np.ndarray
    direction_rad: np.ndarray
    scenario_index: np.ndarray | None = None


def grid_inputs(config: SweepConfig) -> GridInputs:
    """All rollouts of a sweep: repeat-major, then direction, phase, impulse, scenario-minor."""
    ph, imp = np.meshgrid(np.asarray(config.phases, float), np.asarray(config.impulses_ns, float), indexing="ij")
    k = config.n_scenarios
    dirs = config.direction_list
    n = config.n_rollouts
    index = np.arange(n, dtype=np.int32)
    return GridInputs(
        index=index,
        phase=np.tile(np.repeat(ph.ravel(), k), len(dirs) * config.repeats),
        impulse_ns=np.tile(np.repeat(imp.ravel(), k), len(dirs) * config.repeats),
        direction_rad=np.tile(np.repeat([direction_rad(d) for d in dirs], config.n_per_direction), config.repeats),
        scenario_index=index % k,
    )


def scenario_columns(config: SweepConfig, scenario_index: np.ndarray) -> dict:
    """Per-row scenario values ``{axis: (n,) array}`` (floats; terrain as text) of rows with these scenario indices."""
    rows = config.scenarios()
    return {a: np.asarray([rows[i][a] for i in range(len(rows))])[np.asarray(scenario_index)]
            for a, _ in config.scenario}
