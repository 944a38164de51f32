"""``python -m mjx_coman.seed000``: the command line of the seed 000 experiments (one line and exit 2 on bad input)."""

from __future__ import annotations

import argparse
import contextlib
import math
import sys


from jaxlp.cliutil import Parser, interrupted, refuse
from jaxlp.files import strict_json
from mjx_coman import controllers
from mjx_coman.seed000.common import DIRECTIONS, FAMILY, PUSH_TABLE_IMPULSES_NS, SUPPLY_V, VARIANTS, config
from mjx_coman.seed000.push_table import impulse_grid, push_table
from mjx_coman.seed000.walks import SWITCHES, ablate, identify, ten_second_walks


def _floats(text: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return vals


def _names(allowed):
    def parse(text: str) -> list[str]:
        vals = [v.strip() for v in text.split(",") if v.strip()]
        bad = [v for v in vals if v not in allowed]
        if not vals or bad or len(set(vals)) != len(vals):
            raise argparse.ArgumentTypeError(f"expected distinct names of {','.join(allowed)}, got {text!r}")
        return vals
    return parse


def _run(args):
    ov = controllers.parse_overrides(controllers.get(FAMILY), args.set)
    config(FAMILY, **ov)  # a bad value is a ValueError naming it, before anything walks
    if not 0 <= args.seed < 2**32:
        raise ValueError(f"--seed must lie in [0, 2**32), got {args.seed}")
    if args.experiment == "push-table":
        if args.phases < 1 or args.push_step < 0 or args.steps_after < 1 or min(args.impulses) <= 0:
            sys.stderr.write("python -m mjx_coman.seed000: error: --phases, --steps-after >= 1, "
                             "--push-step >= 0 and --impulses > 0 required\n")
            return None
        imp = args.impulses if args.impulse_step is None else impulse_grid(args.impulse_step, args.max_impulse)
        res = push_table(imp, args.phases, args.push_step, args.steps_after, tuple(args.directions),
                         tuple(args.variants), seed=args.seed, overrides=ov, supply_v=args.supply_v,
                         friction_scale=args.friction_scale, truth_estimate=args.truth_estimate,
                         phases=args.phase_list)
    elif args.experiment == "ablate":
        names = args.switches or list(SWITCHES)
        res = ablate({n: SWITCHES[n] for n in names}, args.seconds, args.impulse, seed=args.seed, overrides=ov)
    elif args.experiment == "identify":
        res = identify(args.seconds, args.settle, args.seed, overrides=ov)
    else:
        if not 0 < args.seconds <= 600:
            sys.stderr.write(f"python -m mjx_coman.seed000: error: --seconds must lie in (0, 600], "
                             f"got {args.seconds}\n")
            return None
        which = ("scatter", "drag", "speeds") if args.experiment == "ten" else (args.experiment,)
        res = ten_second_walks(args.seconds, tuple(args.drag_forces), tuple(args.speeds), args.seed, which, ov)
    return res


def main(argv=None) -> int:
    ap = Parser(prog="python -m mjx_coman.seed000", description="The walking experiments of seed 000 on the simulated COMAN, each printing JSON.")
    sub = ap.add_subparsers(dest="experiment", required=True, parser_class=Parser)
    pt = sub.add_parser("push-table")
    pt.add_argument("--impulses", type=_floats, default=list(PUSH_TABLE_IMPULSES_NS), help="N s")
    pt.add_argument("--phases", type=int, default=8)
    pt.add_argument("--phase-list", type=_floats, default=None,
                    help="comma-separated push phases in [0, 1) (instead of --phases evenly spaced)")
    pt.add_argument("--push-step", type=int, default=4)
    pt.add_argument("--steps-after", type=int, default=8)
    pt.add_argument("--impulse-step", type=float, default=None,
                    help="N s: the grid step, max-impulse/step, ..., max-impulse (instead of --impulses)")
    pt.add_argument("--max-impulse", type=float, default=10.0, help="N s, with --impulse-step")
    pt.add_argument("--directions", type=_names(DIRECTIONS), default=["forward", "backward"],
                    help=f"comma-separated, of {','.join(DIRECTIONS)}")
    pt.add_argument("--variants", type=_names(VARIANTS + ("dlqr",)), default=[FAMILY, "open-loop"],
                    help="comma-separated registered time-projection variants")
    pt.add_argument("--supply-v", type=float, default=SUPPLY_V, help="motor supply voltage, V (a limit switched)")
    pt.add_argument("--friction-scale", type=float, default=1.0, help="multiplier of the ground friction")
    pt.add_argument("--truth-estimate", action="store_true",
                    help="the controller estimates from the simulator's true relative positions (privileged)")
    for name in ("drag", "scatter", "speeds", "ten"):  # "ten": all three in one batch
        sp = sub.add_parser(name)
        sp.add_argument("--seconds", type=float, default=10.0)
        sp.add_argument("--drag-forces", type=_floats, default=[1.0, 0.0, -1.0], help="N (x; + forward)")
        sp.add_argument("--speeds", type=_floats, default=[0.1, 0.2], help="m/s")
    ab = sub.add_parser("ablate")
    ab.add_argument("--switches", type=_names(tuple(SWITCHES)), default=None,
                    help=f"comma-separated, of {','.join(SWITCHES)} (default: all)")
    ab.add_argument("--seconds", type=float, default=20.0)
    ab.add_argument("--impulse", type=float, default=4.5, help="N s, forward and backward")
    idp = sub.add_parser("identify")
    idp.add_argument("--seconds", type=float, default=10.0)
    idp.add_argument("--settle", type=float, default=2.0)
    for sp in sub.choices.values():
        sp.add_argument("--seed", type=int, default=0)
        sp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a setting of the time-projection family, changed in every variant of the experiment")
        sp.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    # mujoco.mjx prints "Failed to import warp" on stdout when Warp is absent: keep stdout for the JSON.
    try:
        with contextlib.redirect_stdout(sys.stderr):
            res = _run(args)
    except ValueError as e:
        return refuse("python -m mjx_coman.seed000", e)
    except KeyboardInterrupt:
        return interrupted("python -m mjx_coman.seed000")
    if res is None:
        return 2
    print(strict_json({k: v for k, v in res.items() if k != "raw"}, indent=2 if args.json else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
