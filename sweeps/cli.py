"""Command line ``coman-sweep`` (also ``python -m sweeps``): push-recovery basin maps.

    coman-sweep map                       # the built-in default: full 3LP map (+ small MJX map)
    coman-sweep map --preset gpu          # thousands of MJX rollouts
    coman-sweep map [--model 3lp|mjx] [--controller time-projection] [--set KEY=VALUE ...] [--phases 16]
                    [--impulses 0:20:41] [--direction forward|45] [--directions 8|forward,left] [--noise X]
                    [--bias X] [--randomize PCT]
                    [--constants tuned.json] [--seed 0] [--chunk 256] [--out sweep-map] [--resume] [--force]
    coman-sweep compare [--controllers time-projection,dlqr,open-loop] [same grid options] [--out sweep-compare]
    coman-sweep controllers [--json]      # every controller of each model, with its settings

``map`` pushes the walking robot during step ``--push-step`` at each phase
and impulse and writes results.npz, results.csv, basin.png and summary.json
to ``--out``. With no grid option (or with ``--preset``) it runs a preset,
one subfolder per run. ``compare`` runs the same grid for several controllers
(one subfolder each) and adds compare.png and compare.json (per terrain) and
scorecard.json and scorecard.md (:mod:`sweeps.scorecard`); on ``--model mjx``
its grid defaults to 8 push directions x 2 impulses at mid-step, twice (two draws of
sensor noise: 32 walks of 6 steps per controller, :data:`sweeps.presets.COMPARE_DEFAULTS`), and on a
CPU it runs one sweep per core at once (``--jobs``, :mod:`sweeps.parallel`).
Several hosts: ``--distributed`` (or ``--coordinator``) starts
``jax.distributed`` first; see the README. A bad argument exits with
status 2 and one line on stderr.

Other modules add subcommands with :func:`register_command`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, NamedTuple

from jaxlp.cliutil import Parser, check_output_dir, interrupted
from sweeps import scenario_args
from sweeps.grid import (DIRECTIONS_RAD, ENGINES, GridError, arg_type, direction_rad, parse_directions,
                         parse_impulses, parse_phases)
from sweeps.plan import plan_runs
from sweeps.presets import PRESETS


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
    """``coman-sweep tune``, ``region`` and ``engines`` (parsers and run functions live in their modules)."""
    from sweeps import engines_cli, region_cli, tune

    register_command("tune", tune.HELP, tune.add_arguments, tune.run)
    register_command("region", region_cli.HELP, region_cli.add_arguments, region_cli.run)
    register_command("engines", engines_cli.HELP, engines_cli.add_arguments, engines_cli.run)


_register_tuning_commands()


def _one_direction(text: str) -> str:
    """A name or degrees (``"45"``: a heading, not a count as in ``--directions``)."""
    if "," in text:
        raise GridError(f"--direction takes one direction, got {text!r} (use --directions for several)")
    text = text.strip()
    direction_rad(text)  # GridError naming it
    return text if text in DIRECTIONS_RAD else f"{float(text):g}"


def _controllers(text: str) -> tuple[str, ...]:
    vals = tuple(v.strip() for v in text.split(",") if v.strip())
    if not vals:
        raise argparse.ArgumentTypeError("--controllers is empty")
    return vals  # checked against the model's controllers when the runs are planned


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


def _grid_options(p: argparse.ArgumentParser) -> None:
    a = p.add_argument
    a("--model", help="rollout model: 3lp (default) or mjx (COMAN in MuJoCo MJX)")
    a("--robot", help="3LP parameter preset (default coman)")
    a("--phases", type=arg_type(parse_phases),
      help="push start in the step: a count N (N phases in [0, 1)) or a list 0,0.25 (default 16)")
    a("--impulses", type=arg_type(parse_impulses), help="impulses in N s: start:stop:num or a list (default 0:20:41)")
    a("--direction", type=arg_type(_one_direction),
      help=f"push direction: {', '.join(DIRECTIONS_RAD)} or degrees from forward, + left (default forward)")
    a("--directions", type=arg_type(parse_directions),
      help="several push directions, each a whole grid: a count N (N headings from forward) or a list "
           "forward,45,left (compare --model mjx: 8)")
    a("--repeats", type=_number("--repeats", int, 1),
      help="runs of the whole grid, each push with its own draw of sensor noise and robot (default 1; the "
           "scorecard's bootstrap intervals need 2 or more)")
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
    a("--set", action="append", default=None, metavar="KEY=VALUE",
      help="a setting of the controller (repeatable; see coman-sweep controllers); part of the sweep's identity")
    a("--constants", type=Path,
      help="the controller settings of a tuned.json of coman-sweep tune (its tuned overrides) or a flat JSON "
           "of settings; --set applies on top")
    a("--seed", type=int, help="PRNG seed (default 0)")
    a("--chunk", type=_number("--chunk", int, 0, True), help="rollouts per jitted call (default 256)")
    a("--x64", action="store_true", default=None, help="simulate in 64-bit floats")
    a("--engine", choices=ENGINES, help="mjx: the physics engine, mjx (MuJoCo MJX, default) or native (MuJoCo C "
                                        "on every CPU core; no gradients); part of the sweep's identity")
    scenario_args.add_arguments(p)


def _run_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--resume", action="store_true", help="keep finished chunks of the same sweep in --out (always done; kept for old scripts)")
    p.add_argument("--force", action="store_true", help="overwrite a different sweep in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--jobs", type=_number("--jobs", int, 0, True),
                   help="sweeps run at once, one process each (default: one per CPU core on a CPU, else 1)")
    p.add_argument("--distributed", action="store_true",
                   help="call jax.distributed.initialize() first (cluster auto-detection or JAX_COORDINATOR_ADDRESS)")
    p.add_argument("--coordinator", help="jax.distributed coordinator HOST:PORT (with --num-processes, --process-id)")
    p.add_argument("--num-processes", type=_number("--num-processes", int, 0, True))
    p.add_argument("--process-id", type=_number("--process-id", int, 0))


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="coman-sweep", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    m = sub.add_parser("map", help="basin map of one controller (no options: the built-in default)")
    _grid_options(m)
    m.add_argument("--controller", help="a controller of the model (see coman-sweep controllers; "
                                        "default time-projection)")
    m.add_argument("--preset", choices=tuple(PRESETS),
                   help="a built-in sweep (default: 'default' when no grid option is given)")
    m.add_argument("--out", type=Path, default=Path("sweep-map"), help="output folder (default sweep-map)")
    _run_options(m)
    c = sub.add_parser("compare", help="the same map for several controllers, side by side")
    _grid_options(c)
    c.add_argument("--controllers", type=_controllers,
                   help="comma-separated (default: every walking controller of the model)")
    c.add_argument("--out", type=Path, default=Path("sweep-compare"), help="output folder (default sweep-compare)")
    _run_options(c)
    k = sub.add_parser("controllers", help="every controller of each model, with its settings and defaults")
    k.add_argument("--model", help="one model only (3lp or mjx)")
    k.add_argument("--json", action="store_true", help="print JSON")
    for name, cmd in COMMANDS.items():
        cmd.add_arguments(sub.add_parser(name, help=cmd.help))
    return parser


def controllers_table(model: str | None = None) -> dict:
    """``{model: [{name, description, settings: [...]}, ...]}`` of every model's controllers (JSON-ready)."""
    from sweeps.models import get_model, model_names

    out = {}
    for name in ([model] if model else model_names()):
        m = get_model(name)
        rows = []
        for c in m.controllers():
            if name == "mjx":
                from mjx_coman import controllers

                rows.append(controllers.describe(c))
            else:
                rows.append(dict(name=c, description=f"jaxlp.controllers {c!r} on the 3LP plant", privileged=False,
                                 walking=True, settings=[dict(name=s.name, default=list(s.default)
                                                              if isinstance(s.default, tuple) else s.default,
                                                              tunable=s.tunable, help=s.help)
                                                         for s in m.settings(c)]))
        out[name] = rows
    return out


def _list_controllers(args, parser) -> int:
    try:
        table = controllers_table(args.model)
    except (GridError, ValueError) as e:
        parser.error(str(e))
    if args.json:
        from jaxlp.files import strict_json

        print(strict_json(table))
        return 0
    for model, rows in table.items():
        print(f"model {model}:")
        for r in rows:
            print(f"  {r['name']:18s} {r['description']}")
            tun = [s for s in r["settings"] if s["tunable"]]
            print(f"  {'':18s} tunable: " + ", ".join(f"{s['name']}={s['default']}" for s in tun))
            fixed = [s for s in r["settings"] if not s["tunable"]]
            if fixed:
                print(f"  {'':18s} static: " + ", ".join(f"{s['name']}={s['default']}" for s in fixed))
    return 0


def _describe(summary: dict, out: Path) -> str:
    from sweeps.report import percent

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
        f"during step {summary['push_step']}: {percent(summary['recovery_rate'])} of {summary['rollouts']} rollouts "
        f"recovered ({summary['fell']} fell, {summary.get('solve_failed', 0)} failed solves, {summary['nan']} NaN, "
        f"left out of the rate)\n"
        f"largest recovered impulse (N s) per phase of the step"
        + (" (recovered in every scenario; each scenario below)" if summary.get("per_scenario") else "")
        + f": {best}\n{verdict}\n"
        f"{summary['rollouts_run']} rollouts run in {summary['wall_s']:.1f} s (first chunk, with compilation, "
        f"{summary['first_chunk_s']:.1f} s"
        + (f"; {rate:.3g} rollouts/s, {summary['env_steps_per_s']:.3g} env steps/s"
           + (" incl. compilation" if summary["rate_includes_compile"] else "") if rate else "")
        + f") on {summary['device_count']} {summary['backend']} device(s); {summary['rollouts_resumed']} resumed\n"
        + (f"{scenario_args.describe(summary)}\n" if summary.get("per_scenario") else "")
        + f"wrote {out}/results.npz, results.csv, basin.png, summary.json"
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
    # jax.distributed first: planning imports the models, and importing jaxlp.simulate creates JAX arrays. Every
    # process gets the same arguments, so a bad one still exits 2 on each, after they have met.
    _start_distributed(args)
    try:
        plans = plan_runs(args)
        check_output_dir("--out", args.out)
    except (GridError, ValueError) as e:
        parser.error(str(e))
    import jax

    from sweeps import report
    from sweeps.models import ModelUnavailable, check, get_model
    from jaxlp.files import save_text_atomic, strict_json
    from sweeps.parallel import SweepJob, default_workers, run_sweeps
    from sweeps.runner import SweepConflict

    try:
        runnable = []
        for out, cfg, optional, note in plans:
            try:
                check(cfg)  # the values too (builds the controllers' configs): after jax.distributed
                runnable.append((out, cfg, note))
            except ModelUnavailable as e:
                if not optional:
                    raise
                print(f"skipped {out}: {e}", file=sys.stderr)
    except (GridError, ValueError, RuntimeError) as e:
        parser.error(str(e))
    main_process = jax.process_index() == 0
    native = any(c.engine == "native" for _, c, _ in runnable)  # its physics already uses every core
    workers = args.jobs or (1 if native else default_workers(len(runnable)))
    if workers > 1 and jax.process_count() > 1:
        parser.error(f"--jobs {workers} runs sweeps in local processes; with jax.distributed give --jobs 1")
    if jax.process_count() > 1 and native:
        parser.error("--engine native steps the physics on one host's threads; with jax.distributed use --engine mjx")

    def done(i, run):
        out = runnable[i][0]
        if run.results is not None:
            summary = report.write_outputs(out, run)
            print(_describe(summary, out), flush=True)

    if main_process:
        for out, _, note in runnable:
            if note:
                print(f"{out}: {note}", flush=True)
        if workers > 1:
            print(f"{len(runnable)} sweeps, {workers} at once (one process each; --jobs)", flush=True)
    try:
        runs = run_sweeps([SweepJob(cfg, out, f"{cfg.model}/{cfg.controller}") for out, cfg, _ in runnable],
                          workers=workers, resume=args.resume, force=args.force, progress=not args.no_progress,
                          on_done=done, cost=[get_model(c.model).ticks_per_rollout(c) * c.n_rollouts
                                              for _, c, _ in runnable])
    except (SweepConflict, GridError) as e:
        parser.error(str(e))
    if args.command == "compare" and main_process:
        from sweeps import scorecard

        for out, idx in scenario_args.compare_groups([(o, c) for o, c, _ in runnable]).items():
            table = report.compare_table([runs[i] for i in idx])
            report.save_basin_png(out / "compare.png", [runs[i] for i in idx], row_per_run=True)
            save_text_atomic(out / "compare.json", strict_json(table))
            print(report.format_compare_table(table))
            print(f"wrote {out}/compare.png, compare.json")
        card = scorecard.scorecard(runs)
        save_text_atomic(args.out / "scorecard.json", strict_json(card))
        save_text_atomic(args.out / "scorecard.md", scorecard.markdown(card))
        print(scorecard.markdown(card), end="")
        print(f"wrote {args.out}/scorecard.json, scorecard.md")
    return 0


def main(argv=None) -> int:
    """Entry point; returns the exit status (2 for a bad argument, 130 after Ctrl-C, with one line)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from sweeps.runner import SweepInterrupted

    try:
        if args.command in COMMANDS:
            return COMMANDS[args.command].run(args, parser)
        if args.command == "controllers":
            return _list_controllers(args, parser)
        return _sweep(args, parser)
    except SweepInterrupted as e:
        return interrupted(parser.prog, str(e))
    except KeyboardInterrupt:
        return interrupted(parser.prog)


if __name__ == "__main__":
    sys.exit(main())
