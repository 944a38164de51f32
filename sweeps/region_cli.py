"""``coman-sweep region``: region boundaries by safeguarded Newton vs bisection, drawn over the basin map.

    coman-sweep region --model mjx --controller NAME [--phases 4] [--impulses 0:12:25] [--directions forward]
    coman-sweep region [--controller time-projection] [--controllers time-projection,dlqr,open-loop]
                       [--phases 32] [--impulses 0:20:81] [--directions forward,backward] [--n-steps 10]
                       [--constants tune-out/tuned.json] [--draws 4] [--tol TOL] [--no-map] [--out region-out]

Writes to ``--out``: ``boundary.png`` (per direction, the basin map of
``--controller`` from the sweep runner with the Newton boundary and the
bisection cells over it), ``regions.png`` (the Newton boundaries of every
controller of ``--controllers`` and, with ``--constants``, of the seed's and
the tuned filter constants under sensor noise and bias, in one figure) and
``region.json`` (boundaries, rollouts counted, wall times). The basin map
runs in ``OUT/map-<direction>/`` (resumable).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

from jaxlp.cliutil import check_no_overwrite, check_output_dir
from sweeps.grid import DIRECTIONS_RAD, GridError, arg_type, parse_impulses, parse_phases

HELP = "largest recoverable impulse per push timing: safeguarded Newton on the margin vs bisection"
CONTROLLERS_3LP = ("time-projection", "dlqr", "open-loop")  # the 3lp model's (sweeps.models.threelp.COMPARE)
SETTABLE = ("lqr_weight_scale",)  # --set: the filter constants of the sensing regions come from --constants


def _names(allowed, what):
    def conv(text):
        vals = tuple(v.strip() for v in text.split(",") if v.strip())
        if not vals:
            raise argparse.ArgumentTypeError(f"--{what} is empty")
        bad = [v for v in vals if v not in allowed]
        if bad:
            raise argparse.ArgumentTypeError(f"unknown {what[:-1]} {bad[0]!r}; choose from {', '.join(allowed)}")
        return vals
    conv.__name__ = what
    return conv


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``coman-sweep region`` (registered by :mod:`sweeps.cli`)."""
    p.add_argument("--model", choices=("3lp", "mjx"), default="3lp",
                   help="3lp (default) or mjx: any walking controller on the simulated robot, Newton on the "
                        "walk's ground-truth fall margin by forward mode (sweeps.region_mjx)")
    p.add_argument("--controller", default="time-projection",
                   help="controller of the boundary-over-basin-map figure (3lp: " + ", ".join(CONTROLLERS_3LP)
                        + "; mjx: any walking controller)")
    p.add_argument("--controllers", type=_names(CONTROLLERS_3LP, "controllers"), default=CONTROLLERS_3LP,
                   help="controllers of the regions figure (comma-separated)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the 3LP controllers: lqr_weight_scale=P,V,T (the DLQR weight multipliers)")
    p.add_argument("--phases", type=arg_type(parse_phases), default=None,
                   help="push timings: a count N or a list in [0, 1) (default 32; mjx 4)")
    p.add_argument("--impulses", type=arg_type(parse_impulses), default=None,
                   help="impulse grid, N s, of the map and the bisection (default 0:20:81; mjx 0:12:25)")
    p.add_argument("--directions", type=_names(tuple(DIRECTIONS_RAD), "directions"), default=("forward", "backward"))
    p.add_argument("--n-steps", type=int, default=None,
                   help="steps per rollout (default 10, push in step 2; mjx 6 walking steps, push in step 1)")
    p.add_argument("--constants", type=Path, default=None,
                   help="tuned.json of coman-sweep tune: add the seed's and the tuned constants' regions")
    p.add_argument("--draws", type=int, default=4, help="sensor draws (noise, bias) per direction with --constants")
    p.add_argument("--tol", type=float, default=None, help="Newton tolerance, N s (default: half the grid step)")
    p.add_argument("--no-map", action="store_true", help="skip the basin map (boundaries only)")
    p.add_argument("--out", type=Path, default=Path("region-out"), help="output folder (default region-out)")
    p.add_argument("--force", action="store_true", help="replace a finished region run in --out")
    p.add_argument("--no-progress", action="store_true")


def _check(args) -> dict | None:
    """Validate the arguments; return the tuned record (or ``None``). Raises ``ValueError``."""
    mjx = args.model == "mjx"
    for name, default in (("phases", parse_phases("4" if mjx else "32")),
                          ("impulses", parse_impulses("0:12:25" if mjx else "0:20:81")), ("n_steps", 6 if mjx else 10)):
        if getattr(args, name) is None:
            setattr(args, name, default)
    if mjx:
        from mjx_coman import controllers

        if args.controller not in controllers.names(walking=True):
            raise ValueError(f"unknown walking controller {args.controller!r} for --model mjx; choose from "
                             f"{', '.join(controllers.names(walking=True))}")
        if args.constants is not None or args.set:
            raise ValueError("--constants and --set apply to --model 3lp")
    elif args.controller not in CONTROLLERS_3LP:
        raise ValueError(f"unknown controller {args.controller!r} for --model 3lp; choose from "
                         f"{', '.join(CONTROLLERS_3LP)}")
    check_output_dir("--out", args.out)
    check_no_overwrite("--out", args.out, ("region.json",), args.force)
    imp = np.asarray(args.impulses, float)
    if imp.size < 3 or np.any(np.diff(imp) <= 0):
        raise ValueError(f"--impulses must be at least 3 increasing values, got {args.impulses}")
    if len(args.phases) > 1 and np.any(np.diff(np.asarray(args.phases)) <= 0):
        raise ValueError(f"--phases must increase, got {args.phases}")
    if args.n_steps < 4:
        raise ValueError(f"--n-steps must be >= 4 (pushes come in step 2), got {args.n_steps}")
    if args.draws < 1:
        raise ValueError(f"--draws must be >= 1, got {args.draws}")
    if args.tol is not None and not args.tol > 0:
        raise ValueError(f"--tol must be positive, got {args.tol}")
    from mjx_coman.controllers import Controller, parse_overrides
    from sweeps.models.threelp import SETTINGS

    args.overrides = parse_overrides(Controller("3lp", None, None, None, None, SETTINGS), args.set)
    for key in args.overrides:
        if key not in SETTABLE:
            raise ValueError(f"--set {key}: region takes {', '.join(SETTABLE)} (the filter constants come from "
                             "--constants)")
    ws = args.overrides.get("lqr_weight_scale", (1.0, 1.0, 1.0))
    if len(ws) != 3 or not all(np.isfinite(ws)) or min(ws) <= 0:
        raise ValueError(f"--set lqr_weight_scale={list(ws)} must be 3 positive numbers")
    if args.constants is None:
        return None
    try:
        record = json.loads(Path(args.constants).read_text())
        from sweeps.objective import constants_from_dict

        for key in ("constants_before", "constants_after"):
            constants_from_dict(record[key])
        record["lateral_deadzone"], record["config"]["bias_std_m"]  # noqa: B018
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"--constants {args.constants}: not a readable tuned.json ({e})") from None
    return record


def _boundaries(params, spec, lanes, phases, impulses, tol, constants=None, lateral=None, bisect=True) -> dict:
    from sweeps import region as R

    ev = R.make_evaluators(params, spec, constants, lateral) if spec.sensing else R.preset_evaluators("coman", spec)
    t0 = time.perf_counter()
    newton = R.newton_boundary(ev, lanes, phases, (impulses[0], impulses[-1]), tol_ns=tol)
    out = dict(newton=newton, compile_and_newton_s=time.perf_counter() - t0)
    if bisect:
        R.bisection_boundary(ev, lanes, phases, impulses)  # the first call compiles
        out["bisection"] = R.bisection_boundary(ev, lanes, phases, impulses)
        out["newton_again"] = R.newton_boundary(ev, lanes, phases, (impulses[0], impulses[-1]), tol_ns=tol)
    return out


def _plot_png(draw) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = draw(plt)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def _centers(phases) -> np.ndarray:
    ph = np.asarray(phases, float)
    d = np.diff(ph).mean() if ph.size > 1 else 1.0
    return ph + 0.5 * d


def boundary_figure(maps: dict, found: dict, directions, controller: str) -> bytes:
    """Per direction: the basin map (when run) with the Newton boundary and the bisection cells."""
    from sweeps import report

    def draw(plt):
        fig, axes = plt.subplots(1, len(directions), figsize=(6.0 * len(directions), 4.8), squeeze=False)
        for k, (ax, d) in enumerate(zip(axes[0], directions)):
            nb, bb = found["newton"], found["bisection"]
            x = _centers(nb.phases)
            if d in maps:
                report.plot_basin(ax, maps[d].config, maps[d].results, title=f"3lp / {controller}: {d} pushes")
            else:
                ax.set_title(f"3lp / {controller}: {d} pushes")
                ax.set_xlabel("push start, fraction of step 2")
                ax.set_ylabel("impulse, N s")
            ax.fill_between(x, bb.bracket_ns[k, :, 0], bb.bracket_ns[k, :, 1], step="mid", color="w", alpha=0.5,
                            label=f"bisection cell ({bb.rollouts // len(directions)} rollouts)")
            ax.plot(x, nb.impulse_ns[k], "k.-", lw=1.2,
                    label=f"safeguarded Newton ({int(nb.evaluations[k].sum())} rollouts)")
            ax.legend(loc="upper left", fontsize=7)
        fig.tight_layout()
        return fig

    return _plot_png(draw)


def regions_figure(controllers: dict, constants: dict | None, directions) -> bytes:
    """Newton boundaries of the controllers (left) and of the seed's vs the tuned constants (right)."""
    styles = ["-", "--", ":", "-."]

    def draw(plt):
        n = 2 if constants else 1
        fig, axes = plt.subplots(1, n, figsize=(6.2 * n, 4.6), squeeze=False)
        ax = axes[0, 0]
        for c, (name, found) in enumerate(controllers.items()):
            nb = found["newton"]
            for k, d in enumerate(directions):
                ax.plot(_centers(nb.phases), nb.impulse_ns[k], color=f"C{c}", ls=styles[k % 4], label=f"{name}, {d}")
        ax.set_title("3LP, exact sensing: recoverable region per controller")
        ax.set_xlabel("push start, fraction of step 2 (0.4 s)")
        ax.set_ylabel("largest recoverable impulse, N s (0.1 s push)")
        ax.legend(fontsize=7)
        if constants:
            ax = axes[0, 1]
            for c, (name, found) in enumerate(constants.items()):
                nb = found["newton"]
                draws = nb.impulse_ns.shape[0] // len(directions)
                for k, d in enumerate(directions):
                    rows = nb.impulse_ns[k * draws:(k + 1) * draws]
                    x = _centers(nb.phases)
                    ax.plot(x, np.median(rows, 0), color=f"C{c + 3}", ls=styles[k % 4],
                            label=f"{name} constants, {d} (median of {draws})")
                    ax.fill_between(x, rows.min(0), rows.max(0), color=f"C{c + 3}", alpha=0.15)
            ax.set_title("3LP time projection, noisy biased sensing: seed vs tuned")
            ax.set_xlabel("push start, fraction of step 2 (0.4 s)")
            ax.set_ylabel("largest recoverable impulse, N s")
            ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    return _plot_png(draw)


def _boundary_json(b) -> dict:
    return dict(phases=np.asarray(b.phases).tolist(), impulse_ns=np.round(b.impulse_ns, 4).tolist(),
                evaluations=b.evaluations.tolist(), rollouts=b.rollouts, calls=b.calls, wall_s=b.wall_s)


def run(args, parser) -> int:
    """Run ``coman-sweep region``; bad arguments exit 2 with one line (``parser.error``)."""
    try:
        record = _check(args)
    except ValueError as e:
        parser.error(str(e).splitlines()[0])
    if args.model == "mjx":
        return _run_mjx(args)
    import jax
    import jax.numpy as jnp

    from jaxlp.presets import get_params
    from sweeps import region as R
    from jaxlp.files import save_bytes_atomic, save_text_atomic, strict_json

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = get_params("coman")
    phases, impulses = np.asarray(args.phases, float), np.asarray(args.impulses, float)
    tol = args.tol or 0.5 * float(np.min(np.diff(impulses)))
    dirs = tuple(args.directions)
    lanes = R.make_lanes([DIRECTIONS_RAD[d] for d in dirs])
    spec = R.RegionSpec(controller=args.controller, n_steps=args.n_steps,
                        weight_scale=tuple(float(v) for v in args.overrides.get("lqr_weight_scale", (1.0, 1.0, 1.0))))
    main = _boundaries(params, spec, lanes, phases, impulses, tol)
    same = R.same_within_grid(main["newton"], main["bisection"])
    maps = {}
    if not args.no_map:
        from sweeps.grid import SweepConfig
        from sweeps.runner import run_sweep

        for d in dirs:
            cfg = SweepConfig(model="3lp", controller=args.controller, phases=tuple(phases),
                              impulses_ns=tuple(impulses), direction=d, n_steps=args.n_steps,
                              push_step=2).with_overrides(args.overrides)
            maps[d] = run_sweep(cfg, out / f"map-{d}", resume=True, force=True, progress=not args.no_progress,
                                desc=f"map {d}")
    save_bytes_atomic(out / "boundary.png", boundary_figure(maps, main, dirs, args.controller))
    ctrl = {c: (main if c == args.controller else
                _boundaries(params, spec._replace(controller=c), lanes, phases, impulses, tol, bisect=False))
            for c in args.controllers}
    consts = None
    if record is not None:
        from sweeps.objective import constants_from_dict

        cfg = record["config"]
        noise = 0.5 * (cfg["noise_min_m"] + cfg["noise_max_m"])
        s_lanes = R.make_lanes([DIRECTIONS_RAD[d] for d in dirs], noise, cfg["bias_std_m"], args.draws, seed=7)
        lateral = jnp.asarray(record["lateral_deadzone"])
        s_spec = spec._replace(controller=cfg["controller"], sensing=True)
        consts = {name: _boundaries(params, s_spec, s_lanes, phases, impulses, tol,
                                    constants_from_dict(record[key]), lateral, bisect=False)
                  for name, key in (("seed", "constants_before"), ("tuned", "constants_after"))}
    save_bytes_atomic(out / "regions.png", regions_figure(ctrl, consts, dirs))
    nb, bb = main["newton"], main["bisection"]
    summary = dict(
        controller=args.controller, directions=list(dirs), tol_ns=tol, grid_step_ns=float(np.min(np.diff(impulses))),
        newton=_boundary_json(nb), bisection=_boundary_json(bb),
        newton_rollouts=nb.rollouts, bisection_rollouts=bb.rollouts, full_map_rollouts=int(phases.size * impulses.size
                                                                                           * len(dirs)),
        rollout_ratio=bb.rollouts / max(nb.rollouts, 1), same_within_grid=bool(same.all()),
        newton_wall_s_after_compile=main["newton_again"].wall_s, bisection_wall_s_after_compile=bb.wall_s,
        regions={c: _boundary_json(f["newton"]) for c, f in ctrl.items()},
        constants=None if consts is None else {n: _boundary_json(f["newton"]) for n, f in consts.items()},
        command="coman-sweep " + " ".join(sys.argv[1:]), device_count=jax.device_count(),
    )
    save_text_atomic(out / "region.json", strict_json(summary))
    print(f"{args.controller}: Newton {nb.rollouts} rollouts vs bisection {bb.rollouts} "
          f"({summary['rollout_ratio']:.2f}x fewer; full map {summary['full_map_rollouts']}); same boundary "
          f"within the grid at {int(same.sum())}/{same.size} timings")
    print(f"wrote {out}/boundary.png, regions.png, region.json")
    return 0


def _run_mjx(args) -> int:
    """``--model mjx``: Newton against bisection on MJX walks (:mod:`sweeps.region_mjx`); region.json and
    boundary.png."""
    from jaxlp.files import save_bytes_atomic, save_text_atomic, strict_json
    from sweeps import region_mjx

    imp = np.asarray(args.impulses, float)
    tol = args.tol or 0.5 * float(np.min(np.diff(imp)))
    spec = region_mjx.Spec(controller=args.controller, n_steps=args.n_steps)
    out = region_mjx.run(spec, args.phases, imp, tuple(args.directions), tol)
    out["command"] = "coman-sweep " + " ".join(sys.argv[1:])
    Path(args.out).mkdir(parents=True, exist_ok=True)
    save_text_atomic(Path(args.out) / "region.json", strict_json(out))
    save_bytes_atomic(Path(args.out) / "boundary.png", _mjx_figure(out))
    print(f"mjx/{args.controller}: Newton {out['newton_rollouts']} rollouts vs bisection {out['bisection_rollouts']} "
          f"(full map {out['full_map_rollouts']}); same boundary within the grid step ({out['grid_step_ns']:g} N s) "
          f"at {out['same_within_grid']}/{out['lanes']} phase-direction lanes; compiled in {out['compile_s']:.0f} s")
    for d, nb, bb in zip(out["directions"], out["newton_ns"], out["bisection_ns"]):
        print(f"  {d:>8}: Newton " + " ".join(f"{v:5.2f}" for v in nb) + "  | bisection "
              + " ".join(f"{v:5.2f}" for v in bb) + "  (N s per phase)")
    print(f"wrote {args.out}/region.json, boundary.png")
    return 0


def _mjx_figure(out: dict) -> bytes:
    def draw(plt):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for k, d in enumerate(out["directions"]):
            ax.plot(out["phases"], out["newton_ns"][k], "o-", color=f"C{k}", label=f"{d}: Newton")
            ax.step(out["phases"], out["bisection_ns"][k], where="mid", color=f"C{k}", ls=":",
                    label=f"{d}: bisection (grid {out['grid_step_ns']:g} N s)")
        ax.set_xlabel("push start, fraction of walking step 1")
        ax.set_ylabel("largest recoverable impulse, N s (0.1 s push)")
        ax.set_title(f"MJX {out['controller']}: Newton {out['newton_rollouts']} vs bisection "
                     f"{out['bisection_rollouts']} rollouts")
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig

    return _plot_png(draw)

