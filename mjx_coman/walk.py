"""Command line: one walk of the simulated COMAN, optionally pushed.

``python -m mjx_coman.walk --speed 0.1 --seconds 10 [--push-ns 4 --push-phase 0.5
--push-dir forward] [--push-step 5] [--controller closed-loop] [--seed 0]
[--plot FILE.png] [--json]``

Runs the seed 000 walking pipeline (3LP gait, foot lift, time-projection
footstep adjustment, IK, position control; :func:`mjx_coman.walking.rollout.walk`)
for ``--seconds`` and prints whether it fell, its mean speed, the number of
steps and, with a push, the steps it took to recover. The push is a force of
``--push-duration`` seconds (0.1 s by default) on the upper torso whose
impulse is ``--push-ns`` N s, starting at phase ``--push-phase`` (0 to 1) of
walking step ``--push-step`` (0 is the first step after the start-up phase). ``--controller closed-loop`` is the seed's
time projection; ``open-loop`` disables the footstep adjustment,
``no-deadzone`` drops the dead-zones of eq. 27, ``dlqr`` adjusts once per
step at the phase start. ``--plot`` draws the pelvis path and the footsteps.

Every argument is checked before anything is built: a bad one exits with
status 2 and one line on stderr naming it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from pathlib import Path

import jaxlp  # noqa: F401  (sets the XLA CPU flags before JAX starts)

CONTROLLERS = {
    "closed-loop": "time-projection",
    "time-projection": "time-projection",
    "open-loop": "open-loop",
    "no-deadzone": "no-deadzone",
    "dlqr": "dlqr",
}
DIRECTIONS = {"forward": (1.0, 0.0), "backward": (-1.0, 0.0), "left": (0.0, 1.0), "right": (0.0, -1.0)}
STEP_TIME_S = 0.4
STARTUP_PHASES = 1  # the controller's start-up phase before walking step 0 (controller.init: step -1)
MAX_SPEED_MPS = 0.3  # the stance knee reaches full extension near 0.3 m/s (open_loop docstring)
MAX_SECONDS = 600.0
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit status 2
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m mjx_coman.walk", description=__doc__.splitlines()[0])
    p.add_argument("--speed", type=float, default=0.0, help="commanded walking speed, m/s (default 0: in place)")
    p.add_argument("--seconds", type=float, default=10.0, help="duration of the walk, s")
    p.add_argument("--controller", default="closed-loop", metavar="{" + ",".join(CONTROLLERS) + "}",
                   help="footstep controller (closed-loop = time projection)")
    p.add_argument("--push-ns", type=float, default=0.0, help="push impulse, N s (0: no push)")
    p.add_argument("--push-phase", type=float, default=0.5, help="phase of the step where the push starts, [0, 1)")
    p.add_argument("--push-dir", default="forward", metavar="{" + ",".join(DIRECTIONS) + "}",
                   help="push direction")
    p.add_argument("--push-step", type=int, default=5, help="index of the step (0 = first) that is pushed")
    p.add_argument("--push-duration", type=float, default=0.1, help="push duration, s")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the sensor noise")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="draw pelvis and footstep trajectories")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def validate(args: argparse.Namespace) -> None:
    """Check every argument before anything is built.

    Raises:
        ValueError: with a one-line message naming the bad value.
    """
    def finite(name, v):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v}")

    finite("--speed", args.speed)
    if abs(args.speed) > MAX_SPEED_MPS:
        raise ValueError(f"--speed must lie in [-{MAX_SPEED_MPS}, {MAX_SPEED_MPS}] m/s, got {args.speed}")
    finite("--seconds", args.seconds)
    if not 0.0 < args.seconds <= MAX_SECONDS:
        raise ValueError(f"--seconds must lie in (0, {MAX_SECONDS:g}], got {args.seconds}")
    if args.controller not in CONTROLLERS:
        raise ValueError(f"--controller must be one of {', '.join(CONTROLLERS)}, got {args.controller!r}")
    if args.push_dir not in DIRECTIONS:
        raise ValueError(f"--push-dir must be one of {', '.join(DIRECTIONS)}, got {args.push_dir!r}")
    finite("--push-ns", args.push_ns)
    if args.push_ns < 0:
        raise ValueError(f"--push-ns must be non-negative (use --push-dir for the direction), got {args.push_ns}")
    finite("--push-phase", args.push_phase)
    if not 0.0 <= args.push_phase < 1.0:
        raise ValueError(f"--push-phase must lie in [0, 1), got {args.push_phase}")
    finite("--push-duration", args.push_duration)
    if not 0.0 < args.push_duration <= 1.0:
        raise ValueError(f"--push-duration must lie in (0, 1] s, got {args.push_duration}")
    if args.push_step < 0:
        raise ValueError(f"--push-step must be non-negative, got {args.push_step}")
    if args.push_ns > 0:
        end = push_start_s(args.push_step, args.push_phase) + args.push_duration
        if end > args.seconds:
            raise ValueError(f"--push-step {args.push_step} at --push-phase {args.push_phase} ends at {end:g} s, "
                             f"after the walk (--seconds {args.seconds:g})")
    if args.seed < 0:
        raise ValueError(f"--seed must be non-negative, got {args.seed}")
    if args.plot is not None:
        path = Path(args.plot)
        if path.suffix.lower() not in PLOT_SUFFIXES:
            raise ValueError(f"--plot must end in one of {', '.join(PLOT_SUFFIXES)}, got {args.plot!r}")
        if not path.resolve().parent.is_dir():
            raise ValueError(f"--plot directory does not exist: {str(path.resolve().parent)!r}")


def push_force_n(impulse_ns: float, duration_s: float, direction: str) -> tuple[float, float, float]:
    """Constant world-frame torso force of a push of ``impulse_ns`` over ``duration_s`` in ``direction``."""
    ux, uy = DIRECTIONS[direction]
    f = impulse_ns / duration_s
    return (f * ux, f * uy, 0.0)


def push_start_s(push_step: int, push_phase: float, step_time_s: float = STEP_TIME_S) -> float:
    """Start time of a push at phase ``push_phase`` of walking step ``push_step``, s.

    The walk begins with one start-up phase from the crouched stance
    (``mjx_coman.walking.controller.init``: step -1), so walking step ``k``
    starts at ``(k + 1) T``.
    """
    return (STARTUP_PHASES + push_step + push_phase) * step_time_s


def run(args: argparse.Namespace) -> tuple[dict, object]:
    """Build the environment, controller and push; run the walk; return the JSON summary and the result."""
    import jax
    import numpy as np

    # mujoco.mjx prints "Failed to import warp" on stdout when Warp is absent: keep stdout for the JSON.
    with contextlib.redirect_stdout(sys.stderr):
        from mjx_coman.walking.controller import make_controller_params
        from mjx_coman.walking.rollout import WalkSpec, jit_walk, make_push, no_push, walking_env_params

    env_params = walking_env_params()
    ctrl_params = make_controller_params(env_params, speed_mps=args.speed)
    spec = WalkSpec(controller=CONTROLLERS[args.controller], seconds=args.seconds, step_time_s=STEP_TIME_S)
    if args.push_ns > 0:
        start = push_start_s(args.push_step, args.push_phase)
        push = make_push(start, args.push_duration, push_force_n(args.push_ns, args.push_duration, args.push_dir))
    else:
        start = None
        push = no_push()
    t0 = time.perf_counter()
    res = jit_walk(env_params, ctrl_params, push, spec, jax.random.PRNGKey(args.seed))
    res = jax.tree_util.tree_map(np.asarray, res)
    wall = time.perf_counter() - t0
    fell = bool(res.fell)
    s2r = int(res.steps_to_recover)
    summary = {
        "fell": fell,
        "fall_time_s": float(res.fall_time_s) if fell else None,
        "nan": bool(res.nan),
        "mean_speed_mps": float(res.mean_speed_mps),
        "steps": int(res.steps),
        "steps_to_recover": (s2r if s2r >= 0 else None) if args.push_ns > 0 else None,
        "max_abs_footstep_adjustment_m": float(res.max_abs_footstep_adjustment_m),
        "controller": args.controller,
        "speed_mps": args.speed,
        "seconds": args.seconds,
        "push": None if args.push_ns <= 0 else {
            "impulse_ns": args.push_ns, "direction": args.push_dir, "step": args.push_step,
            "phase": args.push_phase, "duration_s": args.push_duration, "start_s": float(start),
            "force_n": list(push_force_n(args.push_ns, args.push_duration, args.push_dir)),
        },
        "seed": args.seed,
        "wall_s": round(wall, 2),
    }
    return summary, res


def plot(res, path: str, title: str) -> None:
    """Pelvis path and footsteps seen from above, and pelvis x over time (matplotlib, Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    pel = np.asarray(res.pelvis_m)
    t = np.asarray(res.time_s)
    steps = np.asarray(res.footsteps_m)[: int(res.steps) + 1]  # stance foot of phase k: right if k even
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    a.plot(pel[:, 0], pel[:, 1], "-", color="0.3", lw=1, label="pelvis")
    for side, k0, color in (("right", 0, "tab:red"), ("left", 1, "tab:blue")):
        a.plot(steps[k0::2, 0], steps[k0::2, 1], "s", color=color, ms=5, label=f"{side} footsteps")
    for k, (x, y) in enumerate(steps[:, :2]):
        if np.isfinite(x):
            a.annotate(str(k), (x, y), fontsize=6, xytext=(2, 2), textcoords="offset points")
    a.set_xlabel("x (m)")
    a.set_ylabel("y (m)")
    a.set_aspect("equal", adjustable="datalim")
    a.legend(loc="best", fontsize=8)
    a.set_title("top view")
    b.plot(t, pel[:, 0], label="pelvis x")
    b.plot(t, pel[:, 1], label="pelvis y")
    b.set_xlabel("time (s)")
    b.set_ylabel("position (m)")
    b.legend(loc="best", fontsize=8)
    b.set_title("pelvis over time")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        validate(args)
    except ValueError as exc:
        sys.stderr.write(f"python -m mjx_coman.walk: error: {exc}\n")
        return 2
    summary, res = run(args)
    if args.plot:
        push = summary["push"]
        extra = f", push {push['impulse_ns']:g} N s {push['direction']}" if push else ""
        plot(res, args.plot, f"{args.controller}, {args.speed:g} m/s{extra}: "
                             f"{'fell' if summary['fell'] else 'walked'} {summary['steps']} steps")
        summary["plot"] = str(args.plot)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for k, v in summary.items():
            print(f"{k:32s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
