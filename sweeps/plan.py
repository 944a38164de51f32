"""The runs of a parsed ``coman-sweep map`` or ``compare`` command line: ``(out folder, config, optional, note)``
each, from its options, presets (:mod:`sweeps.presets`) and scenario axes (:mod:`sweeps.scenario_args`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from sweeps import scenario_args
from sweeps.grid import GridError, SweepConfig
from sweeps.presets import COMPARE_DEFAULTS, PRESETS

# option -> SweepConfig field, per model (None: the option does not apply to that model)
MODELFIELDS = {
    "noise": {"3lp": "noise_std_m", "mjx": "sensor_noise_scale"},
    "bias": {"3lp": "bias_m", "mjx": "encoder_offset_std_rad"},
    "randomize_leg": {"3lp": "randomize_leg_pct"},
    "randomize_spring": {"mjx": "randomize_spring_pct"},
    "randomize_delay": {"mjx": "randomize_delay_ticks"},
    "engine": {"mjx": "engine"},
}
FIELDS = dict(model="model", robot="robot", phases="phases", impulses="impulses_ns", direction="direction",
               directions="directions", repeats="repeats",
               push_step="push_step", push_duration="push_duration_s", speed="speed_mps",
               step_time="step_time_s", n_steps="n_steps", randomize="randomize_mass_pct", seed="seed",
               chunk="chunk")



def _overrides(args, model: str, strict: bool) -> dict:
    """SweepConfig fields given on the command line for a run of ``model`` (``controller_overrides`` too).

    Raises:
        GridError: (``strict``) an option that does not apply to ``model``.
    """
    out = {field: getattr(args, opt) for opt, field in FIELDS.items() if getattr(args, opt, None) is not None}
    if getattr(args, "x64", None):
        out["x64"] = True
    for opt, per_model in MODELFIELDS.items():
        val = getattr(args, opt, None)
        if val is None:
            continue
        if model in per_model:
            out[per_model[model]] = val
        elif strict:
            raise GridError(f"--{opt.replace('_', '-')} applies to --model {', '.join(per_model)} only")
    return out


def _controller_overrides(args, model: str, controller: str) -> dict:
    """``--constants`` then ``--set`` as the controller's overrides, typed by its settings (GridError naming a bad one)."""
    from sweeps.models import get_model

    settings = get_model(model).settings(controller)
    ov = {}
    if getattr(args, "constants", None) is not None:
        from sweeps.holdout import load_overrides, transfer_overrides

        try:
            ov.update(transfer_overrides(load_overrides(args.constants), settings))
        except ValueError as e:
            raise GridError(f"--constants: {e}") from None
    if getattr(args, "set", None):
        from mjx_coman import controllers

        shim = controllers.Controller(controller, None, None, None, None, tuple(settings))
        try:
            ov.update(controllers.parse_overrides(shim, args.set))
        except ValueError as e:
            raise GridError(str(e).replace(f"controller {controller}", f"controller {controller} (model {model})"))
    return ov


def _given(args) -> bool:
    """Whether any grid or controller option was given."""
    opts = (*FIELDS, *MODELFIELDS, "x64", "controller", "controllers", "constants", "set")
    return any(getattr(args, o, None) is not None for o in opts) or scenario_args.given(args)


def _config(fields: dict, args, controller: str) -> SweepConfig:
    """The run's config; fields the controller fixes itself (mjx: its step time) unless given."""
    from sweeps.models import check, get_model

    cfg = SweepConfig(**dict(fields, controller=controller))
    cfg = check(cfg.with_overrides(_controller_overrides(args, cfg.model, controller)), build=False)
    own = {k: v for k, v in get_model(cfg.model).own_fields(cfg).items() if k not in fields}
    return dataclasses.replace(cfg, **own) if own else cfg


def plan_runs(args) -> list[tuple[Path, SweepConfig, bool, str]]:
    """``(out folder, config, optional, note)`` per run of the parsed arguments (raises :class:`GridError`)."""
    from sweeps.models import get_model

    out = Path(args.out)
    preset = getattr(args, "preset", None)
    if args.command == "map" and (preset or not _given(args)):
        if scenario_args.given(args):
            raise GridError("scenario options (--axis, --payload-kg, ...) apply to an explicit --model mjx grid, "
                            "not to --preset")
        runs = PRESETS[preset or "default"]
        plans = []
        for run in runs:
            fields = dict(run.fields)
            fields.update(_overrides(args, fields["model"], strict=False))
            ctrl = args.controller or fields.pop("controller", "time-projection")
            fields.pop("controller", None)
            plans.append((out / run.name, _config(fields, args, ctrl), run.optional, run.note))
        models = {p[1].model for p in plans}
        for opt, per_model in MODELFIELDS.items():  # an option that applies to none of the runs
            if getattr(args, opt, None) is not None and not models & set(per_model):
                raise GridError(f"--{opt.replace('_', '-')} applies to --model {', '.join(per_model)} only")
        return plans
    model = args.model or "3lp"
    m = get_model(model)  # GridError listing the models
    base = dict(_overrides(args, model, strict=True), model=model)
    if args.command == "compare":
        defaults = dict(COMPARE_DEFAULTS.get(model, {}))
        if "direction" in base:  # one direction asked: not the default directions
            defaults.pop("directions", None)
        base = dict(defaults, **base)
    runs = scenario_args.variants(args)  # one per terrain: a scene (and a compilation) each
    if args.command == "map":
        return [(out / sub, _config(dict(base, scenario=sc), args, args.controller or "time-projection"), False, "")
                for sub, sc in runs]
    ctrls = args.controllers or m.compare_default()
    known = m.controllers()
    bad = [c for c in ctrls if c not in known]
    if bad:
        raise GridError(f"unknown controller {bad[0]!r} for model {model}; choose from {', '.join(known)}")
    return [(out / sub / c, _config(dict(base, scenario=sc), args, c), False, "") for sub, sc in runs for c in ctrls]
