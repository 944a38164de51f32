"""The walking experiments of seed 000 on the simulated COMAN, each printing JSON.

``python -m mjx_coman.seed000 {push-table,drag,scatter,speeds,ten,ablate,identify} [--set KEY=VALUE ...] [options] [--json]``

* ``push-table``: 0.1 s pushes on the torso, forward and backward, starting
  at 8 phases of one step of the in-place gait, over a grid of impulses, for
  ``time-projection`` (the closed loop) and ``open-loop`` (no footstep
  adjustment): recovered (no fall in the ``--steps-after`` steps that follow)
  or fell, settled (the ground truth's ``steps_to_recover >= 0``, see
  :mod:`mjx_coman.ground_truth`) and steps to recover (seed "Intermittent Push
  Recovery", Figures 16-17). The claim checked: at every phase the closed
  loop recovers an impulse at least twice the largest that the open loop
  recovers at every phase. ``--supply-v`` and ``--friction-scale`` switch
  two limits of the plant (:func:`~mjx_coman.seed000.common.plant`).
* ``drag``: a constant forward or backward force on the torso for the whole
  walk on the open-loop in-place gait (seed Figure 18): drift speed, no fall.
  The default forces are +-1 N (and 0 N for reference): on the simulated
  robot 2 N and more topple the open loop within 10 s.
* ``scatter``: in-place walking for 10 s (25 steps) open loop, closed loop,
  and closed loop without dead-zones; the landing foot relative to the pelvis
  at every touchdown (seed Figure 14) and its spread.
* ``speeds``: closed-loop walking at 0.1 and 0.2 m/s (seed Figure 19): mean speed.
* ``ten``: ``scatter``, ``drag`` and ``speeds`` in one batch (one compilation).
* ``ablate``: one block switched at a time (dead-zones, attack-angle share,
  filter, stance ankle, footstep gain): in-place drift over 20 s and steps
  to recover from forward and backward pushes, ground truth.
* ``identify``: dead-zone thresholds and knee deflections from the open-loop
  in-place walk (seed Figures 7 and 9;
  :mod:`mjx_coman.controllers.time_projection.identification`).

The variants are the registered configurations of the time-projection family
(``time-projection``, ``open-loop``, ``no-deadzone``), so every variant of a
table is one batch of one compiled walk (``batched_walk`` over configs,
pushes, keys and joysticks). Each function returns a dict of plain numbers
(and the batch's results under ``"raw"``, left out of the JSON).
"""

from __future__ import annotations

from mjx_coman.seed000.common import (DIRECTIONS, FAMILY, MARGIN_NS, PUSH_DURATION_S, PUSH_TABLE_IMPULSES_NS,
                                     STEP_TIME_S, SUPPLY_V, VARIANTS, config, largest_recovered,
                                     median_steps_to_recover, plant, push_start_s, run_batch)
from mjx_coman.seed000.push_table import impulse_grid, push_table
from mjx_coman.seed000.walks import (SWITCHES, ablate, footstep_spread_m, identify, open_loop_walk, relative_footsteps,
                                    ten_second_walks)

__all__ = ["DIRECTIONS", "FAMILY", "MARGIN_NS", "PUSH_DURATION_S", "PUSH_TABLE_IMPULSES_NS", "STEP_TIME_S", "SUPPLY_V", "SWITCHES",
           "VARIANTS", "ablate", "config", "footstep_spread_m", "identify", "impulse_grid", "largest_recovered",
           "median_steps_to_recover", "open_loop_walk", "plant", "push_start_s", "push_table", "relative_footsteps", "run_batch",
           "ten_second_walks"]
