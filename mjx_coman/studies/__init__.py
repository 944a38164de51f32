"""Studies: seed 001's experiments (speeds, steer, push, model error, slope, noise, delay, terrain, actuators) and
seed 004's (flat, mid-swing push) for any registered walking controller, judged on the simulator's ground truth.

    from mjx_coman import studies
    result, rows = studies.run("speeds", "footstep-mpc", size="small")  # JSON result, per-row figures

``python -m mjx_coman.studies NAME [--controller footstep-mpc] [--size full|small] --json [--plot F.png]``.
Modules: :mod:`.batch` (batched walks over rows), :mod:`.metrics` (ground-truth figures of a walk),
:mod:`.seed001` and :mod:`.seed004` (the experiments), :mod:`.plots` (their figures), :mod:`.cli`.
"""

from __future__ import annotations

from typing import Callable

SIZES = ("small", "full")


def experiments() -> dict:
    """``{name: Experiment}``: seed 001's (:mod:`.seed001`), then seed 004's (:mod:`.seed004`), each in its
    paper's order."""
    from mjx_coman.studies import seed001, seed004

    return {**seed001.EXPERIMENTS, **seed004.EXPERIMENTS}


def names() -> tuple[str, ...]:
    """The experiments, seed 001's then seed 004's."""
    return tuple(experiments())


def plan(experiment: str, controller: str = "footstep-mpc", size: str = "full", seed: int = 0,
         overrides: dict | None = None):
    """The :class:`~mjx_coman.studies.seed001.Plan` of an experiment: the rows it walks (nothing built or run).

    ``overrides``: settings of the controller for every row (the experiment's own, such as the steering ramp,
    take precedence).

    Raises:
        ValueError: an unknown experiment, controller or size (naming the known ones), a controller the
            experiment cannot run, a bad seed.
    """
    from mjx_coman import controllers

    EXPERIMENTS = experiments()
    if experiment not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {experiment!r}; choose one of {', '.join(EXPERIMENTS)}")
    if size not in SIZES:
        raise ValueError(f"size={size!r} must be one of {', '.join(SIZES)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 32:
        raise ValueError(f"seed={seed!r} must be a whole number in [0, 2**32)")
    ctrl, config = controllers.load(controller, overrides)  # ValueError names a bad setting
    if controller not in controllers.names(walking=True):
        raise ValueError(f"{controller} does not walk; choose one of {', '.join(controllers.names(walking=True))}")
    p = EXPERIMENTS[experiment].plan(controller, size, ctrl.gait(config))
    return p._replace(rows=[r._replace(seed=seed) for r in p.rows], overrides={**(overrides or {}), **p.overrides})


def run(experiment: str, controller: str = "footstep-mpc", size: str = "full", seed: int = 0,
        overrides: dict | None = None, *, batch: int = 8,
        progress: Callable[[int, int], None] | None = None) -> tuple[dict, list]:
    """Run an experiment: ``(result, rows)`` with the JSON result and each row's figures (with ``series``).

    Raises:
        ValueError: see :func:`plan`.
    """
    from mjx_coman.studies.batch import run_rows

    EXPERIMENTS = experiments()

    p = plan(experiment, controller, size, seed, overrides)
    n = len(p.rows)
    res = run_rows(controller, p.rows, p.seconds, p.overrides, batch=batch if size == "full" else n,
                   progress=None if progress is None else (lambda k: progress(k, n)))
    result = {"experiment": experiment, "controller": controller, "size": size, "seed": seed,
              "seconds": p.seconds, "settings": p.overrides, **EXPERIMENTS[experiment].reduce(p, res)}
    return result, [dict(r, label=lab) for r, lab in zip(res, p.labels)]
