"""Built-in sweeps: what ``coman-sweep map`` runs with no options, and ``--preset gpu``.

A preset is a list of named runs, each a set of :class:`sweeps.grid.SweepConfig`
fields; each run writes to ``OUT/<name>/``. Options given on the command line
override the preset's fields (model-specific ones only in runs of that model).
A run whose model cannot run yet (``mjx`` before the MJX walking controller
exists) is skipped in ``default`` with a note, and refused in ``gpu``.
"""

from __future__ import annotations

from typing import NamedTuple

from sweeps.grid import parse_directions, parse_impulses, parse_phases


class PresetRun(NamedTuple):
    """One run of a preset.

    Attributes:
        name: subfolder of ``--out``.
        fields: :class:`sweeps.grid.SweepConfig` fields.
        optional: skip (with a note) rather than fail when the model is unavailable.
        note: what the run shows, printed before it.
    """

    name: str
    fields: dict
    optional: bool = False
    note: str = ""


# The full 3LP map: 32 phases x 41 impulses (0-20 N s, 0.5 N s apart) = 1,312 rollouts of 10 steps
# (2,000 ticks of 2 ms): about 2.6 M closed-loop ticks, well under a minute on 2 CPU cores.
_3LP_FULL = dict(model="3lp", controller="time-projection", phases=parse_phases("32"),
                 impulses_ns=parse_impulses("0:20:41"), n_steps=10, push_step=2, chunk=512)

# A small MJX map: 4 phases x 5 impulses (0-8 N s) = 20 walks of 3.6 s (start-up phase + 8 steps,
# 1,800 ticks of 2 ms) on COMAN with nominal sensor noise: a few minutes on 2 CPU cores, compilation included.
_MJX_SMALL = dict(model="mjx", controller="time-projection", phases=(0.0, 0.25, 0.5, 0.75),
                  impulses_ns=parse_impulses("0:8:5"), n_steps=8, push_step=2, chunk=20,
                  sensor_noise_scale=1.0)

# Thousands of MJX rollouts for a GPU: 32 phases x 128 impulses = 4,096 walks of 4.4 s, one chunk,
# with robot randomisation (masses +-5 %, springs +-10 %, delay +-2 ticks) and nominal sensor noise.
_MJX_GPU = dict(model="mjx", controller="time-projection", phases=parse_phases("32"),
                impulses_ns=parse_impulses("0:12.7:128"), n_steps=10, push_step=2, chunk=4096,
                sensor_noise_scale=1.0, randomize_mass_pct=5.0, randomize_spring_pct=10.0,
                randomize_delay_ticks=2)

PRESETS: dict[str, tuple[PresetRun, ...]] = {
    "default": (
        PresetRun("3lp", _3LP_FULL, note="3LP model of COMAN, time projection, full phase x impulse map"),
        PresetRun("mjx", _MJX_SMALL, optional=True,
                  note="MJX COMAN (springs, delay, 12-bit encoders, IMU noise), time projection, small map"),
    ),
    "gpu": (
        PresetRun("mjx", _MJX_GPU, note="MJX COMAN, time projection, 4,096 randomised rollouts in one chunk"),
    ),
}

# What ``coman-sweep compare --model mjx`` runs for each controller unless an option says otherwise: 8 push
# directions x 2 impulses (3 and 6 N s) at mid-step of walking step 1, twice (two draws of sensor noise: the
# scorecard's bootstrap intervals) = 32 walks of 6 steps at 0.1 m/s with COMAN's nominal sensor noise, in one
# chunk. Sized so that every walking controller runs in under 15 minutes on 2 CPU cores (two sweeps at once,
# sweeps.parallel): compilation is about a third of it.
COMPARE_DEFAULTS: dict[str, dict] = {
    "mjx": dict(directions=parse_directions("8"), phases=(0.5,), impulses_ns=(3.0, 6.0), repeats=2,
                n_steps=6, push_step=1, speed_mps=0.1, sensor_noise_scale=1.0, chunk=32),
}
