"""Command line: one walk of the simulated COMAN under any registered controller, optionally pushed.

``python -m mjx_coman.walk [--controller time-projection] [--set KEY=VALUE ...] --speed 0.1 [--turn-rate 0.3]
--seconds 10 [--push-ns 4 --push-phase 0.5 --push-dir forward|DEG] [--push-step 5] [--seed 0] [--plot FILE.png] [--json]
[--payload-kg 1 --payload-body DWYTorso --payload-com-m -0.01,0,0] [--slope-deg 5] [--terrain rough:2|stairs:5|flat]
[--imu-noise-deg 3] [--joint-noise-deg 1] [--delay-ms 10] [--video FILE.gif|FILE.mp4]``

Runs the controller (:mod:`mjx_coman.controllers`; ``--set`` changes any of
its settings) in the generic rollout (:func:`mjx_coman.rollout.walk`) for
``--seconds`` and prints whether it fell, its mean speed, its touchdowns and,
with a push, the steps it took to recover, and the pelvis's heading change,
all measured on the simulator's ground truth (:mod:`mjx_coman.ground_truth`).
``--turn-rate`` commands a steering rate (rad/s, + to the left) to a
controller that steers. The push is a force of
``--push-duration`` seconds (0.1 s by default) on the upper torso whose
impulse is ``--push-ns`` N s (``--push-dir``: a name or an angle in degrees,
counterclockwise from forward, world frame), starting at phase ``--push-phase`` (0 to 1) of
walking step ``--push-step`` (0 is the controller's first walking step, after
any start-up). ``--plot`` draws the pelvis path and the footsteps;
``--video`` animates the robot's simulated poses and the push
(:mod:`mjx_coman.render`: MuJoCo's renderer where OpenGL is configured,
matplotlib otherwise).

The scenario options (:mod:`mjx_coman.scenarios`: seed 001's payload,
slope, rough ground, sensor noise and delay; stairs) change the robot and
its world, never the controller, which stays blind to them; the JSON output
records the scenario.

Every argument is checked before anything is built: a bad one exits with
status 2 and one line on stderr naming it.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time

from jaxlp.cliutil import Parser, check_output_file, interrupted, refuse
from jaxlp.files import strict_json
from mjx_coman import controllers
from mjx_coman.studies.metrics import heading_change_rad

DIRECTIONS = {"forward": (1.0, 0.0), "backward": (-1.0, 0.0), "left": (0.0, 1.0), "right": (0.0, -1.0)}
MAX_SECONDS = 600.0
PLOT_SUFFIXES = (".png", ".pdf", ".svg")
ALIASES = {"closed-loop": "time-projection"}  # the seed's name of the time-projection controller


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m mjx_coman.walk", description=__doc__.splitlines()[0])
    p.add_argument("--controller", default="time-projection", metavar="{" + ",".join(controllers.names()) + "}",
                   help="registered controller (default time-projection; closed-loop is an alias)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the controller (repeatable; see coman-sweep controllers)")
    p.add_argument("--speed", type=float, default=0.0, help="commanded walking speed, m/s (default 0: in place)")
    p.add_argument("--turn-rate", type=float, default=0.0, help="commanded steering rate, rad/s (+ left)")
    p.add_argument("--seconds", type=float, default=10.0, help="duration of the walk, s")
    p.add_argument("--push-ns", type=float, default=0.0, help="push impulse, N s (0: no push)")
    p.add_argument("--push-phase", type=float, default=0.5, help="phase of the step where the push starts, [0, 1)")
    p.add_argument("--push-dir", default="forward", metavar="{" + ",".join(DIRECTIONS) + "}|DEG",
                   help="push direction")
    p.add_argument("--push-step", type=int, default=5, help="index of the step (0 = first) that is pushed")
    p.add_argument("--push-duration", type=float, default=0.1, help="push duration, s")
    p.add_argument("--privileged", action="store_true", help="allow a controller that reads ground truth")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the sensor noise")
    p.add_argument("--plot", default=None, metavar="FILE.png", help="draw pelvis and footstep trajectories")
    p.add_argument("--video", default=None, metavar="FILE.gif",
                   help="animate the walk (.gif; .mp4 where ffmpeg is present) with the push as an arrow")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    g = p.add_argument_group("scenario (mjx_coman.scenarios; the controller is not told)")
    g.add_argument("--payload-kg", type=float, default=0.0, help="mass added to --payload-body, kg (seed 001: 1)")
    g.add_argument("--payload-body", default="DWYTorso", help="the body carrying the payload (default DWYTorso)")
    g.add_argument("--payload-com-m", default="0,0,0", metavar="X,Y,Z",
                   help="payload CoM from the body's CoM, body frame, m (seed 001: -0.01,0,0, 1 cm back)")
    g.add_argument("--slope-deg", type=float, default=0.0, help="floor slope, + uphill in the walking direction, deg")
    g.add_argument("--terrain", default="flat", metavar="flat|rough:CM[:SEED]|stairs:CM",
                   help="ground: flat, rough (+-CM cm height field) or stairs (CM cm risers, up in +x; -CM: down)")
    g.add_argument("--imu-noise-deg", type=float, default=None, help="std of the IMU orientation noise, deg "
                                                                     "(default: COMAN's nominal 0.11)")
    g.add_argument("--joint-noise-deg", type=float, default=None, help="std of the link encoder noise, deg (default 0)")
    g.add_argument("--delay-ms", type=float, default=0.0,
                   help="extra controller-to-robot delay, ms, on the plant's own (position 20, torque-sea 10, torque-ideal 0)")
    return p


def scenario_from_args(args: argparse.Namespace, control_period_s: float):
    """The :class:`mjx_coman.scenarios.Scenario` of the options (nothing built).

    Raises:
        ValueError: one line naming the option and its bad value.
    """
    from mjx_coman.scenarios import NAMES, Scenario, check_delay, nominal_delay_ticks

    try:
        com = tuple(float(v) for v in str(args.payload_com_m).split(","))
    except ValueError:
        raise ValueError(f"--payload-com-m must be X,Y,Z in m, got {args.payload_com_m!r}") from None
    try:
        sc = Scenario(payload_kg=args.payload_kg, payload_body=args.payload_body, payload_com_m=com,
                      slope_deg=args.slope_deg, terrain=args.terrain, imu_noise_deg=args.imu_noise_deg,
                      joint_noise_deg=args.joint_noise_deg, delay_ms=args.delay_ms).validate()
        check_delay(sc.delay_ms, nominal_delay_ticks(control_period_s), control_period_s)
    except ValueError as e:
        msg = str(e)
        name = next((n for n in NAMES if msg.startswith(n)), None)
        raise ValueError(f"--{name.replace('_', '-')}: {msg}" if name else msg) from None
    return sc


def validate(args: argparse.Namespace) -> None:
    """Check every argument before anything is built (the controller's config included).

    Sets ``args.controller_name``, ``args.overrides``, ``args.gait``.

    Raises:
        ValueError: with a one-line message naming the bad value.
    """
    def finite(name, v):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v}")

    name = ALIASES.get(args.controller, args.controller)
    ctrl = controllers.get(name)  # ValueError lists the known names
    args.controller_name = name
    args.overrides = controllers.parse_overrides(ctrl, args.set)
    if "terrain" in ctrl.defaults() and "terrain" not in args.overrides and args.terrain != "flat":
        args.overrides["terrain"] = args.terrain  # a controller that plans on a known terrain is told the scene's
    finite("--speed", args.speed)
    finite("--seconds", args.seconds)
    if not 0.0 < args.seconds <= MAX_SECONDS:
        raise ValueError(f"--seconds must lie in (0, {MAX_SECONDS:g}], got {args.seconds}")
    push_unit(args.push_dir)
    finite("--turn-rate", args.turn_rate)
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
    if not 0 <= args.seed < 2**32:
        raise ValueError(f"--seed must lie in [0, 2**32), got {args.seed}")
    check_output_file("--plot", args.plot, PLOT_SUFFIXES)
    if args.video is not None:
        from mjx_coman import render

        render.check_path(args.video)
        check_output_file("--video", args.video, render.SUFFIXES)
    if ctrl.privileged and not args.privileged:
        raise ValueError(f"--controller {name} reads the simulator's ground truth; add --privileged to run it")
    with contextlib.redirect_stdout(sys.stderr):
        _, config = controllers.load(name, args.overrides)  # ValueError names a bad --set value
    gait = ctrl.gait(config)
    try:
        gait.check_joystick(args.speed)
    except ValueError:
        raise ValueError(f"--speed {args.speed:g} is beyond {name}'s +-{gait.max_forward_mps:g} m/s") from None
    try:
        gait.check_joystick(0.0, 0.0, args.turn_rate)
    except ValueError:
        raise ValueError(f"--turn-rate {args.turn_rate:g} is beyond {name}'s +-{gait.max_turn_rad_per_s:g} rad/s "
                         f"(0 for a controller that does not steer)") from None
    args.gait = gait
    args.scenario = scenario_from_args(args, gait.control_period_s)
    if args.push_ns > 0:
        end = push_start_s(gait, args.push_step, args.push_phase) + args.push_duration
        if end > args.seconds:
            raise ValueError(f"--push-step {args.push_step} at --push-phase {args.push_phase} ends at {end:g} s, "
                             f"after the walk (--seconds {args.seconds:g})")


def push_unit(direction: str) -> tuple[float, float]:
    """The world-frame unit vector of ``--push-dir``: a name of :data:`DIRECTIONS` (exact) or degrees from
    forward (+ left).

    Raises:
        ValueError: neither a name nor a finite number.
    """
    if direction in DIRECTIONS:
        return DIRECTIONS[direction]
    try:
        deg = float(direction)
    except ValueError:
        deg = math.nan
    if not math.isfinite(deg):
        raise ValueError(f"--push-dir must be one of {', '.join(DIRECTIONS)} or an angle in degrees, got {direction!r}")
    return math.cos(math.radians(deg)), math.sin(math.radians(deg))


def push_force_n(impulse_ns: float, duration_s: float, direction: str) -> tuple[float, float, float]:
    """Constant world-frame torso force of a push of ``impulse_ns`` over ``duration_s`` in ``direction``."""
    ux, uy = push_unit(direction)
    f = impulse_ns / duration_s
    return (f * ux, f * uy, 0.0)


def push_start_s(gait, push_step: int, push_phase: float) -> float:
    """Start of a push at phase ``push_phase`` of walking step ``push_step`` of the controller's gait, s."""
    return gait.first_step_s + (push_step + push_phase) * gait.step_time_s


def run(args: argparse.Namespace) -> tuple[dict, object]:
    """Build the environment, controller and push; run the walk; return the JSON summary and the result."""
    import jax
    import numpy as np

    from mjx_coman import rollout as ro
    from mjx_coman import ground_truth as gt
    from mjx_coman import scenarios
    from mjx_coman.studies.metrics import corner_positions_m, toe_off_fraction

    ctrl, config = controllers.load(args.controller_name, args.overrides)
    env_params = ro.plant_env_params(args.gait.plant)
    if args.scenario != scenarios.Scenario():
        env_params = scenarios.scenario_env_params(env_params, args.scenario)
    judge = gt.judge_on(args.scenario)
    if args.push_ns > 0:
        start = push_start_s(args.gait, args.push_step, args.push_phase)
        push = ro.make_push(start, args.push_duration, push_force_n(args.push_ns, args.push_duration, args.push_dir))
    else:
        start = None
        push = ro.no_push()
    save = ro.SaveAt(record, every=10)
    joystick = controllers.joystick(args.speed, turn_rad_per_s=args.turn_rate)
    t0 = time.perf_counter()
    fn = ro.jit_walk(ctrl, ro.WalkSpec(seconds=args.seconds, judge=judge), save, privileged_ok=args.privileged)
    res = fn(config, env_params, push, jax.random.PRNGKey(args.seed), joystick)
    res = jax.tree_util.tree_map(np.asarray, res)
    wall = time.perf_counter() - t0
    fell = bool(res.fell)
    s2r = int(res.steps_to_recover)
    summary = {
        "controller": args.controller_name,
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in args.overrides.items()},
        "fell": fell,
        "fall_time_s": float(res.fall_time_s) if fell else None,
        "nan": bool(res.nan),
        "solve_failed": bool(res.solve_failed),
        "mean_speed_mps": float(res.mean_speed_mps),
        "touchdowns": int(res.touchdowns),
        "steps_to_recover": (s2r if s2r >= 0 else None) if args.push_ns > 0 else None,
        "steps_to_recover_basis": (f"ground truth: touchdowns after the push until the CoM's touchdown-to-touchdown "
                                   f"velocity stays within {judge.recover_tol_mps:g} m/s of the limit cycle the walk "
                                   f"ends in ({judge.confirm_steps} steps in a row at least)"),
        "max_abs_footstep_adjustment_m": float(res.max_abs_footstep_adjustment_m),
        "heading_change_rad": heading_change_rad(res),
        **stance_metrics(res, args.gait.plant),
        **gait_metrics(res, args.gait.control_period_s * 10),
        "toe_off_fraction": toe_off_fraction(res, corner_positions_m(res.saved["qpos"]), args.scenario.terrain),
        "speed_mps": args.speed,
        "turn_rate_rad_per_s": args.turn_rate,
        "seconds": args.seconds,
        "push": None if args.push_ns <= 0 else {
            "impulse_ns": args.push_ns, "direction": args.push_dir, "step": args.push_step,
            "phase": args.push_phase, "duration_s": args.push_duration, "start_s": float(start),
            "force_n": list(push_force_n(args.push_ns, args.push_duration, args.push_dir)),
        },
        "scenario": args.scenario.to_dict(),
        "seed": args.seed,
        "wall_s": round(wall, 2),
    }
    return summary, res


def record(state) -> dict:
    """What a walk saves every 10 ticks: :func:`mjx_coman.rollout.pelvis_com_and_torque` and the simulated
    ``qpos`` (the poses ``--video`` draws; always recorded, so the video does not change the compiled walk)."""
    from mjx_coman import rollout as ro

    return dict(ro.pelvis_com_and_torque(state), qpos=state.env.data.qpos)


def video(res, args, path: str, title: str) -> dict:
    """Animate the walk's recorded poses in the scene it ran in, with its push (:mod:`mjx_coman.render`)."""
    import numpy as np

    from mjx_coman import render
    from mjx_coman.scenarios import scene_model

    push = None
    if args.push_ns > 0:
        push = render.PushDrawing(push_start_s(args.gait, args.push_step, args.push_phase), args.push_duration,
                                  push_force_n(args.push_ns, args.push_duration, args.push_dir))
    return render.write_video(path, scene_model(args.scenario.terrain), np.asarray(res.time_s),
                              np.asarray(res.saved["qpos"]), push, title)


def stance_metrics(res, plant: str) -> dict:
    """CoM drift (horizontal CoM displacement from the first record to the last, before any fall), CoM rise
    (its vertical displacement: the height climbed on stairs) and, for a
    torque-controlled plant, the torque-tracking error: RMS and largest |link torque - commanded torque| over
    the joints and the records (commanded before the transport delay, so the delay's lag counts as error)."""
    import numpy as np

    com = np.asarray(res.saved["com_m"])
    t = np.asarray(res.time_s)
    ok = t <= float(res.fall_time_s) if bool(res.fell) else np.ones(t.shape, bool)
    com = com[ok]
    out = {"plant": plant, "com_drift_m": float(np.linalg.norm(com[-1, :2] - com[0, :2])) if len(com) else None,
           "com_rise_m": float(com[-1, 2] - com[0, 2]) if len(com) else None}
    if plant != "position":
        err = (np.asarray(res.saved["link_torque_nm"]) - np.asarray(res.saved["command_nm"]))[ok]
        out["torque_tracking_rms_nm"] = float(np.sqrt(np.mean(err ** 2))) if err.size else None
        out["torque_tracking_max_nm"] = float(np.max(np.abs(err))) if err.size else None
        late = err[t[ok] > 1.0]  # past the start-up transient
        out["torque_tracking_rms_after_1s_nm"] = float(np.sqrt(np.mean(late ** 2))) if late.size else None
    return out


def gait_metrics(res, record_period_s: float) -> dict:
    """The knee metrics of :func:`mjx_coman.studies.metrics.knee_metrics` from the walk's recorded ``qpos`` and
    link torques (ground truth)."""
    import numpy as np

    from mjx_coman.actuators import JOINT_INDEX
    from mjx_coman.studies.metrics import knee_metrics

    knees = [JOINT_INDEX["RKneeSag"], JOINT_INDEX["LKneeSag"]]
    qpos, tau = np.asarray(res.saved["qpos"]), np.asarray(res.saved["link_torque_nm"])
    return knee_metrics(res, qpos[:, [7 + k for k in knees]], tau[:, knees], record_period_s)


def plot(res, path: str, title: str) -> None:
    """Pelvis path and footsteps (touchdowns) seen from above, and pelvis x over time (matplotlib, Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    pel = np.asarray(res.saved["pelvis_m"])
    t = np.asarray(res.time_s)
    k = int(res.touchdowns)
    steps, foot = np.asarray(res.log.foot_m)[:k], np.asarray(res.log.foot)[:k]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    a.plot(pel[:, 0], pel[:, 1], "-", color="0.3", lw=1, label="pelvis")
    for side, code, color in (("left", 0, "tab:blue"), ("right", 1, "tab:red")):
        a.plot(steps[foot == code, 0], steps[foot == code, 1], "s", color=color, ms=5, label=f"{side} touchdowns")
    for i, (x, y) in enumerate(steps[:, :2]):
        a.annotate(str(i + 1), (x, y), fontsize=6, xytext=(2, 2), textcoords="offset points")
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
        return refuse("python -m mjx_coman.walk", exc)
    try:
        summary, res = run(args)
    except KeyboardInterrupt:
        return interrupted("python -m mjx_coman.walk")
    push = summary["push"]
    extra = f", push {push['impulse_ns']:g} N s {push['direction']}" if push else ""
    title = f"{args.controller_name}, {args.speed:g} m/s{extra}"
    if args.plot:
        plot(res, args.plot, f"{title}: {'fell' if summary['fell'] else 'walked'}, {summary['touchdowns']} touchdowns")
        summary["plot"] = str(args.plot)
    if args.video:
        summary["video"] = video(res, args, args.video, title)
    if args.json:
        print(strict_json(summary, indent=2))
    else:
        for k, v in summary.items():
            print(f"{k:32s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
