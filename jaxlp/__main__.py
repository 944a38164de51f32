"""Command line: ``python -m jaxlp info --robot coman --step-time 0.4 --speed 0.1 [--json]``.

Prints the 3LP report of a robot: its parameters, the eigenvalues of the
sagittal step-to-step error map without and with the DLQR correction, the
fixed-width gait, and the time-projection footstep gains over the phase.
A bad argument exits with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import sys

import jax

from jaxlp.cliutil import Parser, refuse
from jaxlp.files import strict_json
from jaxlp.presets import robot_names


def _phases(text: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--phases must be comma-separated numbers, got {text!r}") from None
    if not vals or any(not 0.0 <= v < 1.0 for v in vals):
        raise argparse.ArgumentTypeError(f"--phases must lie in [0, 1), got {text!r}")
    return vals


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="python -m jaxlp", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    info = sub.add_parser("info", help="3LP report of a robot")
    info.add_argument("--robot", choices=robot_names(), default="coman")
    info.add_argument("--height", type=float, default=1.75, help="stature for --robot human, m")
    info.add_argument("--mass", type=float, default=70.0, help="body mass for --robot human, kg")
    info.add_argument("--step-time", type=float, default=0.4, help="step time, s")
    info.add_argument("--speed", type=float, default=0.1, help="walking speed, m/s")
    info.add_argument("--step-width", type=float, default=None, help="step width, m (default 2*pw)")
    info.add_argument("--phases", type=_phases, default=[round(0.1 * i, 1) for i in range(10)],
                      help="phases of the footstep gains, comma-separated in [0, 1)")
    info.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from jaxlp.report import format_table, info_report

    try:
        with jax.enable_x64(True):  # 64-bit for the report only: a caller in the same process keeps its width
            report = info_report(
                robot=args.robot, step_time_s=args.step_time, speed_mps=args.speed,
                step_width_m=args.step_width, phases=args.phases, height_m=args.height, mass_kg=args.mass,
            )
    except ValueError as exc:
        return refuse("python -m jaxlp", exc)
    print(strict_json(report, indent=2) if args.json else format_table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
