"""Scenarios of a rollout (seed 001's experiments, seed 004's stairs): payload, slope, terrain, noise, delay.

:class:`Scenario` holds them as plain values; :func:`scenario_env_params`
and :func:`batched_env_params` apply them to an ``EnvParams`` (batchable:
payload, slope, noise, delay), the fall judge of the terrain is
:func:`mjx_coman.ground_truth.judge_on`, and :mod:`mjx_coman.scenarios.terrain` builds the terrain scene
variants (static: one compilation each). See :mod:`mjx_coman.scenarios.scenario`.
"""

from mjx_coman.scenarios.scenario import (  # noqa: F401
    BATCH_MODEL_FIELDS,
    NAMES,
    PAYLOAD_FIELDS,
    Scenario,
    add_point_mass,
    apply_payload,
    batched_env_params,
    check_delay,
    extra_delay_ticks,
    needs_scene,
    nominal_delay_ticks,
    scenario_batch_axes,
    scenario_env_params,
    select,
    slope_gravity,
)
from mjx_coman.scenarios.terrain import Terrain, parse_terrain, scene_model, terrain_height_m  # noqa: F401
