"""Command line ``coman-sweep`` (also ``python -m sweeps``): push-recovery basin maps.

    coman-sweep map                       # the built-in default: full 3LP map (+ small MJX map)
    coman-sweep map --preset gpu          # thousands of MJX rollouts
    coman-sweep map [--model 3lp|mjx] [--controller time-projection] [--phases 16] [--impulses 0:20:41]
                    [--direction forward] [--noise X] [--bias X] [--randomize PCT] [--constants tuned.json] [--seed 0]
                    [--chunk 256] [--out sweep-map] [--resume] [--force]
    coman-sweep compare [--controllers time-projection,dlqr,open-loop] [same grid options] [--out sweep-compare]

``map`` pushes the walking robot during step ``--push-step`` at each phase
and impulse and writes results.npz, results.csv, basin.png and summary.json
to ``--out``. With no grid option (or with ``--preset``) it runs a preset,
one subfolder per run. ``compare`` runs the same grid for several controllers
(one subfolder each) and adds compare.png and compare.json.
Several hosts: ``--distributed`` (or ``--coordinator``) starts
``jax.distributed`` first; see the README. A bad argument exits with
status 2 and one line on stderr.

Other modules add subcommands with :func:`register_command`.
"""

from __future__ import annotations

import jaxlp  # noqa: F401  (first: appends the XLA CPU scheduler flag to XLA_FLAGS before JAX starts)

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Callable, NamedTuple

from sweeps.grid import (CONTROLLERS, DIRECTIONS_RAD, MODEL_CONTROLLERS, GridError, SweepConfig, parse_impulses,
                         parse_phases)
from sweeps.presets import PRESETS


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit status 2
        sys.stderr.write(f"{self.prog}: error: {' '.join(str(message).split())}\n")
        sys.exit(2)


class Command(NamedTuple):
    """An extra subcommand: ``add_arguments(parser)`` then ``run(args, parser) -> exit status``."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, argparse.ArgumentParser], int]


COMMANDS: dict[str, Command] = {}


def register_command(name: str, help: str, add_arguments: Callable, run: Callable) -> None:
    """Add a subcommand ``coman-sweep NAME`` (e.g. ``tune`` and ``region`` from their modules)."""
    COMMANDS[name] = Command(help, add_arguments, run)


def _register_tuning_commands() -> None:
    """``coman-sweep tune`` and ``coman-sweep region`` (parsers and run functions live in their modules)."""
    from sweeps import region_cli, tune

    register_command("tune", tune.HELP, tune.add_arguments, tune.run)
    register_command("region", region_cli.HELP, region_cli.add_arguments, region_cli.run)


_register_tuning_commands()


def _arg(parse):
    def conv(text):
        try:
            return parse(text)
        except GridError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    conv.__name__ = parse.__name__
    return conv


def _controllers(text: str) -> tuple[str, ...]:
    vals = tuple(v.strip() for v in text.split(",") if v.strip())
    if not vals:
        raise argparse.ArgumentTypeError("--controllers is empty")
    bad = [v for v in vals if v not in CONTROLLERS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown controller {bad[0]!r}; choose from {', '.join(CONTROLLERS)}")
    return vals


def _number(name, kind=float, minimum=None, strict=False):
    def conv(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if minimum is not None and (not v > minimum if strict else not v >= minimum):
            raise argparse.ArgumentTypeError(f"{name} must be {'>' if strict else '>='} {minimum}, got {text!r}")
        return v
    return conv


# option -> SweepConfig field, per model (None: the option does not apply to that model)
_MODEL_FIELDS = {
    "noise": {"3lp": "noise_std_m", "mjx": "sensor_noise_scale"},
    "bias": {"3lp": "bias_m", "mjx": "encoder_offset_std_rad"},
    "randomize_leg": {"3lp": "randomize_leg_pct"},
    "randomize_spring": {"mjx": "randomize_spring_pct"},
    "randomize_delay": {"mjx": "randomize_delay_ticks"},
}
_FIELDS = dict(model="model", robot="robot", phases="phases", impulses="impulses_ns", direction="direction",
               push_step="push_step", push_duration="push_duration_s", speed="speed_mps",
               step_time="step_time_s", n_steps="n_steps", randomize="randomize_mass_pct", seed="seed",
               chunk="chunk")


def _grid_options(p: argparse.ArgumentParser) -> None:
    a = p.add_argument
    a("--model", help="rollout model: 3lp (default) or mjx (COMAN in MuJoCo MJX)")
    a("--robot", help="3LP parameter preset (default coman)")
    a("--phases", type=_arg(parse_phases),
      help="push start in the step: a count N (N phases in [0, 1)) or a list 0,0.25 (default 16)")
    a("--impulses", type=_arg(parse_impulses), help="impulses in N s: start:stop:num or a list (default 0:20:41)")
    a("--direction", choices=tuple(DIRECTIONS_RAD), help="push direction (default forward)")
    a("--push-step", type=_number("--push-step", int, 0), help="step during which the push starts (default 2; mjx: walking step, after its start-up phase)")
    a("--push-duration", type=_number("--push-duration", float, 0, True), help="push duration, s (default 0.1)")
    a("--speed", type=float, help="walking speed, m/s (default 0: in place)")
    a("--step-time", type=_number("--step-time", float, 0, True), help="step duration, s (default 0.4)")
    a("--n-steps", type=_number("--n-steps", int, 0, True), help="steps simulated per rollout (default 10; mjx: plus its start-up phase)")
    a("--noise", type=_number("--noise", float, 0),
      help="3lp: sensor noise std on relative positions, m (turns the jaxlp filters on); "
           "mjx: IMU/gyro/F-T noise as a multiple of COMAN's nominal noise (default 0)")
    a("--bias", type=float, help="3lp: sagittal pelvis position bias, m (filters on); "
                                 "mjx: std of constant per-joint encoder offsets, rad (default 0)")
    a("--randomize", type=_number("--randomize", float, 0),
      help="per-rollout uniform +-%% on the body masses (default 0)")
    a("--randomize-leg", type=_number("--randomize-leg", float, 0),
      help="3lp: per-rollout uniform +-%% on the leg length (default 0)")
    a("--randomize-spring", type=_number("--randomize-spring", float, 0),
      help="mjx: per-rollout uniform +-%% on the SEA spring stiffness (default 0)")
    a("--randomize-delay", type=_number("--randomize-delay", int, 0),
      help="mjx: per-rollout uniform +-ticks (2 ms) on the 20 ms transport delay (default 0)")
    a("--constants", type=Path,
      help="mjx: the controller's dead-zones, zeta and velocity window from a tuned.json of coman-sweep tune "
           "(its tuned constants) or a flat JSON of them (default: the controller's)")
    a("--seed", type=int, help="PRNG seed (default 0)")
    a("--chunk", type=_number("--chunk", int, 0, True), help="rollouts per jitted call (default 256)")
    a("--x64", action="store_true", default=None, help="simulate in 64-bit floats")


def _run_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--resume", action="store_true", help="keep finished chunks of the same sweep in --out")
    p.add_argument("--force", action="store_true", help="overwrite a different sweep in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--distributed", action="store_true",
                   help="call jax.distributed.initialize() first (cluster auto-detection or JAX_COORDINATOR_ADDRESS)")
    p.add_argument("--coordinator", help="jax.distributed coordinator HOST:PORT (with --num-processes, --process-id)")
    p.add_argument("--num-processes", type=_number("--num-processes", int, 0, True))
    p.add_argument("--process-id", type=_number("--process-id", int, 0))


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="coman-sweep", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    m = sub.add_parser("map", help="basin map of one controller (no options: the built-in default)")
    _grid_options(m)
    m.add_argument("--controller", choices=CONTROLLERS, help="controller (default time-projection)")
    m.add_argument("--preset", choices=tuple(PRESETS),
                   help="a built-in sweep (default: 'default' when no grid option is given)")
    m.add_argument("--out", type=Path, default=Path("sweep-map"), help="output folder (default sweep-map)")
    _run_options(m)
    c = sub.add_parser("compare", help="the same map for several controllers, side by side")
    _grid_options(c)
    c.add_argument("--controllers", type=_controllers, help="comma-separated (default: every controller of the model)")
    c.add_argument("--out", type=Path, default=Path("sweep-compare"), help="output folder (default sweep-compare)")
    _run_options(c)
    for name, cmd in COMMANDS.items():
        cmd.add_arguments(sub.add_parser(name, help=cmd.help))
    return parser


def _overrides(args, model: str, strict: bool) -> dict:
    """SweepConfig fields given on the command line for a run of ``model``.

    Raises:
        GridError: (``strict``) an option that does not apply to ``model``.
    """
    out = {field: getattr(args, opt) for opt, field in _FIELDS.items() if getattr(args, opt, None) is not None}
    if getattr(args, "x64", None):
        out["x64"] = True
    if getattr(args, "constants", None) is not None:
        if model == "mjx":
            from sweeps.holdout_mjx import load_constants

            try:
                out.update(load_constants(args.constants))
            except ValueError as e:
                raise GridError(f"--constants: {e}") from None
        elif strict:
            raise GridError("--constants applies to --model mjx only")
    for opt, per_model in _MODEL_FIELDS.items():
        val = getattr(args, opt, None)
        if val is None:
            continue
        if model in per_model:
            out[per_model[model]] = val
        elif strict:
            raise GridError(f"--{opt.replace('_', '-')} applies to --model {', '.join(per_model)} only")
    return out


def _given(args) -> bool:
    """Whether any grid or controller option was given."""
    opts = (*_FIELDS, *_MODEL_FIELDS, "x64", "controller", "controllers", "constants")
    return any(getattr(args, o, None) is not None for o in opts)


def plan_runs(args) -> list[tuple[Path, SweepConfig, bool, str]]:
    """``(out folder, config, optional, note)`` per run of the parsed arguments (raises :class:`GridError`)."""
    out = Path(args.out)
    preset = getattr(args, "preset", None)
    if args.command == "map" and (preset or not _given(args)):
        runs = PRESETS[preset or "default"]
        plans = []
        for run in runs:
            fields = dict(run.fields)
            fields.update(_overrides(args, fields["model"], strict=False))
            if args.controller:
                fields["controller"] = args.controller
            plans.append((out / run.name, SweepConfig(**fields).validate(), run.optional, run.note))
        models = {p[1].model for p in plans}
        if getattr(args, "constants", None) is not None and "mjx" not in models:
            raise GridError("--constants applies to --model mjx only")
        for opt, per_model in _MODEL_FIELDS.items():  # an option that applies to none of the runs
            if getattr(args, opt, None) is not None and not models & set(per_model):
                raise GridError(f"--{opt.replace('_', '-')} applies to --model {', '.join(per_model)} only")
        return plans
    model = args.model or "3lp"
    if model not in MODEL_CONTROLLERS:
        raise GridError(f"unknown model {model!r}; choose one of {', '.join(MODEL_CONTROLLERS)}")
    base = dataclasses.replace(SweepConfig(), **_overrides(args, model, strict=True))
    if args.command == "map":
        return [(out, dataclasses.replace(base, controller=args.controller or base.controller).validate(), False, "")]
    ctrls = args.controllers or MODEL_CONTROLLERS[model]
    return [(out / c, dataclasses.replace(base, controller=c).validate(), False, "") for c in ctrls]


def _describe(summary: dict, out: Path) -> str:
    per = summary["per_phase"]
    best = ", ".join(f"{r['phase']:.2f}: " + ("-" if r["max_recovered_impulse_ns"] is None
                                              else f"{r['max_recovered_impulse_ns']:g}") for r in per)
    rate = summary["rollouts_per_s"]
    known = [(r["max_recovered_impulse_ns"] or 0.0, r["phase"]) for r in per]
    if any(r["max_recovered_impulse_ns"] is None for r in per):
        verdict = "some phase recovers no push of the grid, not even the smallest"
    else:
        dur = summary["push_duration_s"]
        (lo, lo_ph), (hi, hi_ph) = min(known, key=lambda t: t[0]), max(known, key=lambda t: t[0])
        verdict = (f"weakest phase {lo_ph:.2f} recovers {lo:g} N s ({lo / dur:g} N), "
                   f"strongest phase {hi_ph:.2f} recovers {hi:g} N s ({hi / dur:g} N)")
    return (
        f"{summary['model']} / {summary['controller']}: {summary['direction']} {summary['push_duration_s']:g} s pushes "
        f"during step {summary['push_step']}: {summary['recovery_rate']:.1%} of {summary['rollouts']} rollouts recovered "
        f"({summary['fell']} fell, {summary['nan']} NaN)\n"
        f"largest recovered impulse (N s) per phase of the step: {best}\n"
        f"{verdict}\n"
        f"{summary['rollouts_run']} rollouts run in {summary['wall_s']:.1f} s (first chunk, with compilation, "
        f"{summary['first_chunk_s']:.1f} s"
        + (f"; {rate:.3g} rollouts/s, {summary['env_steps_per_s']:.3g} env steps/s"
           + (" incl. compilation" if summary["rate_includes_compile"] else "") if rate else "")
        + f") on {summary['device_count']} {summary['backend']} device(s); {summary['rollouts_resumed']} resumed\n"
        f"wrote {out}/results.npz, results.csv, basin.png, summary.json"
    )


def _start_distributed(args) -> None:
    """``jax.distributed.initialize`` from the options (before any other JAX call)."""
    if not (args.distributed or args.coordinator):
        return
    import jax

    if args.coordinator:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    else:
        jax.distributed.initialize()


def _sweep(args, parser) -> int:
    try:
        plans = plan_runs(args)
    except GridError as e:
        parser.error(str(e))
    _start_distributed(args)  # before anything creates a JAX array (importing jaxlp.simulate does)
    import jax

    from sweeps import report
    from sweeps.models import ModelUnavailable, get_model
    from sweeps.runner import SweepConflict, run_sweep, save_text_atomic

    try:
        runnable = []
        for out, cfg, optional, note in plans:
            try:
                get_model(cfg.model)
                runnable.append((out, cfg, note))
            except ModelUnavailable as e:
                if not optional:
                    raise
                print(f"skipped {out}: {e}", file=sys.stderr)
    except (GridError, ValueError, RuntimeError) as e:
        parser.error(str(e))
    main_process = jax.process_index() == 0
    runs = []
    try:
        for out, cfg, note in runnable:
            if note and main_process:
                print(f"{out}: {note}", flush=True)
            run = run_sweep(cfg, out, resume=args.resume, force=args.force, progress=not args.no_progress,
                            desc=f"{cfg.model}/{cfg.controller}")
            runs.append(run)
            if run.results is not None:
                summary = report.write_outputs(out, run)
                print(_describe(summary, out), flush=True)
    except (SweepConflict, GridError) as e:
        parser.error(str(e))
    if args.command == "compare" and main_process:
        out = Path(args.out)
        table = report.compare_table(runs)
        report.save_basin_png(out / "compare.png", runs)
        save_text_atomic(out / "compare.json", json.dumps(table, indent=1))
        print(report.format_compare_table(table))
        print(f"wrote {out}/compare.png, compare.json")
    return 0


def main(argv=None) -> int:
    """Entry point; returns the exit status (2 for a bad argument)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command in COMMANDS:
        return COMMANDS[args.command].run(args, parser)
    return _sweep(args, parser)


if __name__ == "__main__":
    sys.exit(main())
