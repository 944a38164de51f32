"""Command line: ``python -m mjx_coman.studies NAME [--controller footstep-mpc] [--set KEY=VALUE ...] [--size full|small]
[--seed 0] [--json] [--plot F.png] [--out F.json]``.

Runs one of seed 001's or seed 004's experiments (:mod:`mjx_coman.studies.seed001`, :mod:`~mjx_coman.studies.seed004`) for a registered walking controller and
prints its result (JSON with ``--json``); ``--plot`` draws its figure, ``--out`` writes the JSON atomically.
Every argument is checked before anything is built: a bad one exits with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from jaxlp.cliutil import Parser, check_no_overwrite, check_output_file, interrupted, refuse
from jaxlp.files import save_text_atomic, strict_json

PROG = "python -m mjx_coman.studies"
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def build_parser() -> argparse.ArgumentParser:
    from mjx_coman.studies import SIZES, names

    p = Parser(prog=PROG, description=__doc__.splitlines()[0])
    p.add_argument("experiment", metavar="{" + ",".join(names()) + "}")
    p.add_argument("--controller", default="footstep-mpc", help="registered walking controller")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the controller for every walk (repeatable)")
    p.add_argument("--size", default="full", choices=SIZES, help="full: the paper's experiment; small: two short rows")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the sensor noise")
    p.add_argument("--batch", type=int, default=8, help="rows per compiled call")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", default=None, help="draw the experiment's figure to this .png/.pdf/.svg")
    p.add_argument("--out", default=None, help="also write the JSON result to this file (atomically)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def validate(args) -> None:
    """Check every argument (the plan is built, nothing compiled).

    Raises:
        ValueError: naming the bad value.
    """
    from mjx_coman import studies

    if not 1 <= args.batch <= 1024:
        raise ValueError(f"--batch must lie in [1, 1024], got {args.batch}")
    check_output_file("--plot", args.plot, PLOT_SUFFIXES)
    check_output_file("--out", args.out)
    if args.out is not None:
        check_no_overwrite("--out", Path(args.out).parent, (Path(args.out).name,), args.force)
    from mjx_coman import controllers

    args.overrides = controllers.parse_overrides(controllers.get(args.controller), args.set)
    studies.plan(args.experiment, args.controller, args.size, args.seed, args.overrides)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        validate(args)
    except ValueError as exc:
        return refuse(PROG, exc)
    from mjx_coman import studies

    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=None, desc=f"{args.experiment} ({args.controller})", unit="walk", file=sys.stderr)

    def progress(done, total):
        bar.total = total
        bar.update(done - bar.n)

    try:
        result, rows = studies.run(args.experiment, args.controller, args.size, args.seed, args.overrides,
                                   batch=args.batch, progress=None if bar is None else progress)
    except KeyboardInterrupt:
        return interrupted(PROG)
    finally:
        if bar is not None:
            bar.close()
    if args.plot:
        from mjx_coman.studies import plots

        plots.save(result, rows, args.plot)
        result["plot"] = str(args.plot)
    text = strict_json(result)
    if args.out:
        save_text_atomic(Path(args.out), text + "\n")
    if args.json:
        print(text)
    else:
        for k, v in result.items():
            if k != "rows":
                print(f"{k:40s} {v}")
    return 0
