"""Command line ``coman-sweep`` (also ``python -m sweeps``): push-recovery basin maps.

    coman-sweep map [--phases 16] [--impulses 0:20:41] [--direction forward] [--controller time-projection]
                    [--model 3lp] [--noise 0.001] [--bias 0.005] [--randomize 10] [--seed 0]
                    [--chunk 256] [--out sweep-map] [--resume] [--force]
    coman-sweep compare [--controllers time-projection,dlqr,open-loop] [same grid options] [--out sweep-compare]

``map`` pushes the walking 3LP model of COMAN during step ``--push-step`` at
each phase and impulse and writes results.npz, results.csv, basin.png and
summary.json to ``--out``. ``compare`` runs the same grid for several
controllers (one subfolder each) and adds compare.png and compare.json.
A bad argument exits with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from sweeps.grid import CONTROLLERS, DIRECTIONS_RAD, GridError, SweepConfig, parse_impulses, parse_phases

_EIGEN_FLAG = "--xla_cpu_multi_thread_eigen=false"


def _set_xla_flags() -> None:
    """Single-threaded Eigen on the CPU (the multi-threaded pool can hang small machines)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if _EIGEN_FLAG not in flags:
        os.environ["XLA_FLAGS"] = (flags + " " + _EIGEN_FLAG).strip()


def pin_to_one_cpu() -> None:
    """Run every thread of this process on one CPU (set ``COMAN_SWEEP_ALL_CPUS=1`` to skip).

    On the 2-core development machine the jitted 3LP rollout (LAPACK calls inside
    XLA's CPU runtime) was seen to wait forever at random with its threads spread
    over both cores, even with single-threaded Eigen; on one core it never did.
    Applied to the threads that exist now; threads started later inherit it.
    """
    if os.environ.get("COMAN_SWEEP_ALL_CPUS") == "1" or not hasattr(os, "sched_setaffinity"):
        return
    cpu = min(os.sched_getaffinity(0))
    tids = os.listdir("/proc/self/task") if os.path.isdir("/proc/self/task") else ["0"]
    for tid in tids:
        try:
            os.sched_setaffinity(int(tid), {cpu})
        except OSError:
            pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit status 2
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


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


def _nonneg(name):
    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not v >= 0:
            raise argparse.ArgumentTypeError(f"{name} must be non-negative, got {text!r}")
        return v
    return conv


def _positive(name, kind=float):
    def conv(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a positive number, got {text!r}") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"{name} must be positive, got {text!r}")
        return v
    return conv


def _grid_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default="3lp", help="rollout model: 3lp (mjx: not available yet)")
    p.add_argument("--robot", default="coman", help="3LP parameter preset (default coman)")
    p.add_argument("--phases", type=_arg(parse_phases), default=parse_phases("16"),
                   help="push start in the step: a count N (N phases in [0, 1)) or a list 0,0.25 (default 16)")
    p.add_argument("--impulses", type=_arg(parse_impulses), default=parse_impulses("0:20:41"),
                   help="impulses in N s: start:stop:num or a list (default 0:20:41)")
    p.add_argument("--direction", choices=tuple(DIRECTIONS_RAD), default="forward")
    p.add_argument("--push-step", type=int, default=2, help="step during which the push starts (default 2)")
    p.add_argument("--push-duration", type=_positive("--push-duration"), default=0.1, help="push duration, s")
    p.add_argument("--speed", type=float, default=0.0, help="walking speed, m/s (0: in place)")
    p.add_argument("--step-time", type=_positive("--step-time"), default=0.4, help="step duration, s")
    p.add_argument("--n-steps", type=_positive("--n-steps", int), default=10, help="steps simulated per rollout")
    p.add_argument("--noise", type=_nonneg("--noise"), default=0.0,
                   help="sensor noise std on relative positions, m (turns the jaxlp filters on)")
    p.add_argument("--bias", type=float, default=0.0, help="sagittal pelvis position bias, m (filters on)")
    p.add_argument("--randomize", type=_nonneg("--randomize"), default=0.0,
                   help="per-rollout uniform +-%% on the torso and leg masses m1, m2")
    p.add_argument("--randomize-leg", type=_nonneg("--randomize-leg"), default=None,
                   help="per-rollout uniform +-%% on the leg length (default: --randomize)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--chunk", type=_positive("--chunk", int), default=256, help="rollouts per jitted call")
    p.add_argument("--x64", action="store_true", help="simulate in 64-bit floats")
    p.add_argument("--resume", action="store_true", help="keep finished chunks of the same sweep in --out")
    p.add_argument("--force", action="store_true", help="overwrite a different sweep in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="coman-sweep", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    m = sub.add_parser("map", help="basin map of one controller")
    _grid_options(m)
    m.add_argument("--controller", choices=CONTROLLERS, default="time-projection")
    m.add_argument("--out", type=Path, default=Path("sweep-map"), help="output folder (default sweep-map)")
    c = sub.add_parser("compare", help="the same map for several controllers, side by side")
    _grid_options(c)
    c.add_argument("--controllers", type=_controllers, default=CONTROLLERS,
                   help="comma-separated (default time-projection,dlqr,open-loop)")
    c.add_argument("--out", type=Path, default=Path("sweep-compare"), help="output folder (default sweep-compare)")
    return parser


def config_from_args(args, controller: str) -> SweepConfig:
    """The :class:`SweepConfig` of parsed arguments (raises :class:`GridError`)."""
    leg = args.randomize if args.randomize_leg is None else args.randomize_leg
    return SweepConfig(
        model=args.model, controller=controller, robot=args.robot, phases=tuple(args.phases),
        impulses_ns=tuple(args.impulses), direction=args.direction, push_step=args.push_step,
        push_duration_s=args.push_duration, speed_mps=args.speed, step_time_s=args.step_time,
        n_steps=args.n_steps, noise_std_m=args.noise, bias_m=args.bias, randomize_mass_pct=args.randomize,
        randomize_leg_pct=leg, seed=args.seed, chunk=args.chunk, x64=args.x64,
    ).validate()


def _check_model(name: str) -> None:
    from sweeps.models import get_model

    get_model(name)


def _describe(summary: dict, out: Path) -> str:
    per = summary["per_phase"]
    best = ", ".join(f"{r['phase']:.2f}: " + ("-" if r["max_recovered_impulse_ns"] is None
                                              else f"{r['max_recovered_impulse_ns']:g}") for r in per)
    rate = summary["rollouts_per_s"]
    return (
        f"{summary['model']} / {summary['controller']}: {summary['direction']} {summary['push_duration_s']:g} s pushes "
        f"during step {summary['push_step']}: {summary['recovery_rate']:.1%} of {summary['rollouts']} rollouts recovered "
        f"({summary['fell']} fell, {summary['nan']} NaN)\n"
        f"largest recovered impulse (N s) per phase of the step: {best}\n"
        f"{summary['rollouts_run']} rollouts run in {summary['wall_s']:.1f} s (compile {summary['compile_s']:.1f} s"
        + (f", {rate:.0f} rollouts/s, {summary['env_steps_per_s']:.3g} env steps/s" if rate else "")
        + f") on {summary['device_count']} device(s); {summary['rollouts_resumed']} resumed\n"
        f"wrote {out}/results.npz, results.csv, basin.png, summary.json"
    )


def main(argv=None) -> int:
    """Entry point; returns the exit status (2 for a bad argument)."""
    _set_xla_flags()
    pin_to_one_cpu()
    parser = build_parser()
    args = parser.parse_args(argv)
    controllers = (args.controller,) if args.command == "map" else args.controllers
    try:
        configs = [config_from_args(args, c) for c in controllers]
        _check_model(args.model)
    except (GridError, ValueError, RuntimeError) as e:
        parser.error(str(e))
    from sweeps import report
    from sweeps.runner import SweepConflict, run_sweep

    out = Path(args.out)
    runs = []
    try:
        for cfg in configs:
            sub = out if args.command == "map" else out / cfg.controller
            run = run_sweep(cfg, sub, resume=args.resume, force=args.force, progress=not args.no_progress,
                            desc=cfg.controller)
            summary = report.write_outputs(sub, run)
            runs.append(run)
            print(_describe(summary, sub), flush=True)
    except (SweepConflict, GridError) as e:
        parser.error(str(e))
    if args.command == "compare":
        table = report.compare_table(runs)
        report.save_basin_png(out / "compare.png", runs)
        (out / "compare.json").write_text(json.dumps(table, indent=1))
        print(report.format_compare_table(table))
        print(f"wrote {out}/compare.png, compare.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
