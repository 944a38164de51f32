"""``coman-sweep engines``: the same pushes on MuJoCo MJX and MuJoCo C, and the pelvis of an unpushed walk.

    coman-sweep engines [--controllers time-projection,dlqr] [--phases 8] [--impulses 0:12:16]
                        [--directions forward,backward,left,right] [--n-steps 6] [--speed 0] [--chunk 64]
                        [--seconds 10] [--out engines-out] [--force] [--no-progress] [--json]

Per controller, the grid runs as two sweeps (``OUT/<controller>/mjx`` and ``OUT/<controller>/native``, each
with the outputs of ``coman-sweep map`` and resumable as any sweep), then
:func:`sweeps.cross_engine.outcome_agreement` and :func:`sweeps.cross_engine.pelvis_distance`; all of it in
``OUT/engines.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from jaxlp.cliutil import check_output_dir
from sweeps.grid import DIRECTIONS_RAD, GridError, SweepConfig, arg_type, parse_impulses, parse_phases

HELP = "the same pushes on both physics engines (mjx, native): agreement of outcomes and pelvis trajectories"


def _list(text: str) -> tuple[str, ...]:
    vals = tuple(v.strip() for v in text.split(",") if v.strip())
    if not vals:
        raise argparse.ArgumentTypeError("empty list")
    return vals


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``coman-sweep engines`` (registered by :mod:`sweeps.cli`)."""
    a = p.add_argument
    a("--controllers", type=_list, default=("time-projection",), help="controllers (default time-projection)")
    a("--phases", type=arg_type(parse_phases), default=parse_phases("8"), help="push phases (default 8)")
    a("--impulses", type=arg_type(parse_impulses), default=parse_impulses("0:12:16"),
      help="impulses, N s (default 0:12:16)")
    a("--directions", type=_list, default=("forward", "backward", "left", "right"),
      help=f"push directions among {', '.join(DIRECTIONS_RAD)} (default the four)")
    a("--n-steps", type=int, default=6, help="walking steps per rollout (default 6)")
    a("--push-step", type=int, default=2, help="walking step of the push (default 2)")
    a("--speed", type=float, default=0.0, help="walking speed, m/s (default 0)")
    a("--chunk", type=int, default=64, help="rollouts per jitted call (default 64)")
    a("--seconds", type=float, default=10.0, help="the unpushed walk of the pelvis comparison, s (default 10)")
    a("--out", type=Path, default=Path("engines-out"), help="output folder (default engines-out)")
    a("--force", action="store_true", help="overwrite different sweeps in --out")
    a("--no-progress", action="store_true")
    a("--json", action="store_true", help="print engines.json")


def configs(args) -> list[tuple[str, dict[str, SweepConfig]]]:
    """Per controller, its sweep on each engine (GridError naming a bad value)."""
    from sweeps.models import check, get_model

    bad = [d for d in args.directions if d not in DIRECTIONS_RAD]
    if bad:
        raise GridError(f"unknown direction {bad[0]!r}; choose from {', '.join(DIRECTIONS_RAD)}")
    out = []
    for name in args.controllers:
        base = SweepConfig(model="mjx", controller=name, phases=tuple(args.phases), impulses_ns=tuple(args.impulses),
                           directions=tuple(args.directions), n_steps=args.n_steps, push_step=args.push_step,
                           speed_mps=args.speed, chunk=args.chunk)
        base = check(base, build=False)
        base = dataclasses.replace(base, **get_model("mjx").own_fields(base))
        out.append((name, {e: check(dataclasses.replace(base, engine=e)) for e in ("mjx", "native")}))
    return out


def run(args, parser) -> int:
    """Run ``coman-sweep engines``; bad arguments exit 2 with one line (``parser.error``)."""
    try:
        check_output_dir("--out", args.out)
        if args.seconds <= 0:
            raise GridError(f"--seconds must be positive, got {args.seconds}")
        plans = configs(args)
    except (GridError, ValueError) as e:
        parser.error(str(e).splitlines()[0])
    from jaxlp.files import save_text_atomic, strict_json
    from sweeps import cross_engine, report
    from sweeps.runner import SweepConflict, run_sweep

    record = dict(controllers={})
    for name, by_engine in plans:
        runs = {}
        for engine, cfg in by_engine.items():
            out = args.out / name / engine
            try:
                runs[engine] = run_sweep(cfg, out, force=args.force, progress=not args.no_progress,
                                         desc=f"{name}/{engine}")
            except SweepConflict as e:
                parser.error(str(e))
            report.write_outputs(out, runs[engine])
        row = dict(agreement=cross_engine.outcome_agreement(runs["mjx"].results, runs["native"].results),
                   pelvis=cross_engine.pelvis_distance(name, args.seconds, args.speed),
                   env_steps_per_s={e: r.timing["env_steps_per_s"] for e, r in runs.items()})
        record["controllers"][name] = row
        a, p = row["agreement"], row["pelvis"]
        print(f"{name}: {a['identical']}/{a['rollouts']} identical outcomes ({100 * a['identical_fraction']:.1f} %), "
              f"pelvis RMS {1000 * (p['rms_m'] or float('nan')):.2f} mm over {args.seconds:g} s", file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    save_text_atomic(args.out / "engines.json", strict_json(record))
    if args.json:
        print(json.dumps(json.loads(strict_json(record)), indent=1))
    else:
        print(f"wrote {args.out}/engines.json")
    return 0
