"""``coman-sweep tune``: gradient tuning of a controller's constants with optax, on either model.

    coman-sweep tune [--plant 3lp|mjx] [--controller time-projection] [--set KEY=VALUE ...] [--tune deadzone,zeta]
                     [--steps 60] [--lr 0.05] [--optimizer adam] [--batch 64] [--seed 0] [--n-steps 7]
                     [--impulse-max 12] [--noise-min 0.0005] [--noise-max 0.0015] [--bias 0.002] [--tune-weights]
                     [--holdout | --no-holdout] [--holdout-model mjx] [--out tune-out] [--no-progress] [--x64]

The model (:mod:`sweeps.models`) poses the problem (:class:`sweeps.models.TuneProblem`: unconstrained
coordinates, a loss and its gradient on fixed training and held-out scenarios); this module only
runs the optimiser on it: an optax chain (NaN gradients zeroed, then Adam by default), keeping the
iterate with the fewest training falls and, among those, the lowest training loss (a walk frozen by a fall
can sway less than one that recovers, so the loss alone once kept constants that made both footstep-MPC
training pushes fall). Writes to ``--out`` (each file atomically): ``tuned.json`` (the
constants and the controller overrides before and after, training and held-out loss before and after,
the history, the command) and ``loss.png``; with ``--holdout`` (default) it then runs held-out sweeps
of the seed's and the tuned overrides (:mod:`sweeps.holdout`) on the same model, or on
``--holdout-model``.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import math
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from jaxlp.cliutil import check_no_overwrite, check_output_dir

PLANTS = ("3lp", "mjx")
OPTIMIZERS = ("adam", "adamw", "sgd")


@dataclasses.dataclass(frozen=True)
class TuneConfig:
    """Everything that decides a tuning run (plain values).

    Attributes:
        plant: the model tuned on (``"3lp"``: exact gradients through the 3LP plant and its sensor model;
            ``"mjx"``: forward mode through the contact-rich walk).
        robot: 3LP parameter preset (3lp).
        controller: the controller whose constants are tuned (a name of the model).
        controller_overrides: ``((setting, value), ...)``: its other settings (mjx).
        tunables: the settings tuned (mjx; default: the controller's ``tune_default``).
        steps: optimiser steps.
        learning_rate: optimiser step size in the unconstrained coordinates.
        optimizer: ``adam``, ``adamw`` or ``sgd`` (momentum 0.9).
        batch: training scenarios (a fixed sample; mjx: at most 2 pushes).
        seed: PRNG seed of the training scenarios (held-out: ``seed + 1``).
        n_steps: phases per training rollout (3lp; pushes in step 2).
        push_step: walking step pushed (mjx).
        speed_mps: commanded speed (mjx).
        impulse_max_ns: training impulses up to this, N s.
        noise_min_m, noise_max_m: white sensor noise std range, m (3lp).
        bias_std_m: per-rollout systematic sagittal bias std, m (3lp).
        tune_weights: also tune the DLQR weight scales (3lp).
        x64: 64-bit floats.
    """

    plant: str = "3lp"
    robot: str = "coman"
    controller: str = "time-projection"
    controller_overrides: tuple = ()
    tunables: tuple = ()
    steps: int = 60
    learning_rate: float = 0.05
    optimizer: str = "adam"
    batch: int = 64
    seed: int = 0
    n_steps: int = 7
    push_step: int = 1
    speed_mps: float = 0.0
    impulse_max_ns: float = 12.0
    noise_min_m: float = 0.5e-3
    noise_max_m: float = 1.5e-3
    bias_std_m: float = 2e-3
    tune_weights: bool = False
    x64: bool = False

    def validate(self) -> "TuneConfig":
        """Raise ``ValueError`` naming the first bad value; return ``self``."""
        if self.plant not in PLANTS:
            raise ValueError(f"unknown plant {self.plant!r}; choose one of {', '.join(PLANTS)}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {self.optimizer!r}; choose one of {', '.join(OPTIMIZERS)}")
        for name, most in (("steps", 100_000), ("batch", 100_000)):
            if not 1 <= getattr(self, name) <= most:
                raise ValueError(f"{name} must lie in [1, {most}], got {getattr(self, name)}")
        if not 0 <= self.seed < 2**32 - 1:  # the held-out sets use seed + 1
            raise ValueError(f"seed must lie in [0, 2**32 - 1), got {self.seed}")
        if not 4 <= self.n_steps <= 100:
            raise ValueError(f"n_steps must lie in [4, 100] (pushes come in step 2), got {self.n_steps}")
        if not 0 <= self.push_step <= 20:
            raise ValueError(f"push_step must lie in [0, 20], got {self.push_step}")
        for name in ("learning_rate", "impulse_max_ns", "noise_min_m", "noise_max_m", "bias_std_m", "speed_mps"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        for name in ("impulse_max_ns", "noise_min_m", "bias_std_m"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not self.noise_max_m >= self.noise_min_m:
            raise ValueError(f"noise_max_m={self.noise_max_m} must be >= noise_min_m={self.noise_min_m}")
        if self.plant == "3lp" and self.controller not in ("time-projection", "dlqr"):
            raise ValueError(f"controller {self.controller!r} has no constants to tune on 3lp; "
                             "use time-projection or dlqr")
        if self.plant == "3lp" and (self.controller_overrides or self.tunables):
            raise ValueError("--set and --tune apply to --plant mjx (3lp tunes the dead-zones, zeta and the window)")
        return self


def _optimizer(config: TuneConfig):
    import optax

    base = {"adam": lambda: optax.adam(config.learning_rate),
            "adamw": lambda: optax.adamw(config.learning_rate, weight_decay=1e-3),
            "sgd": lambda: optax.sgd(config.learning_rate, momentum=0.9)}[config.optimizer]()
    return optax.chain(optax.zero_nans(), base)  # a rollout that went numerically bad must not move the constants


def tune(config: TuneConfig, progress: bool = True) -> dict:
    """Run the optimisation on the model's problem; return a JSON-ready record (no files written).

    Raises:
        ValueError: a bad configuration (naming the bad value).
    """
    import jax
    import optax

    from sweeps.models import get_model

    config.validate()
    model = get_model(config.plant)
    t_start = time.perf_counter()
    with jax.enable_x64(config.x64):
        problem = model.tune_problem(config)
        raw = raw0 = problem.raw0
        opt = _optimizer(config)
        state = opt.init(raw)
        history = dict(loss=[], fell_rate=[], grad_norm=[], step_s=[])
        best = ((np.inf, np.inf), raw, -1)  # (training falls, loss): a walk frozen by a fall can sway less
        bar = _bar(config.steps, progress)
        for step in range(config.steps + 1):  # the last pass only evaluates the final iterate
            t0 = time.perf_counter()
            (loss, terms), grad = problem.value_and_grad(raw, "train")
            loss = float(loss)
            history["loss"].append(loss)
            history["fell_rate"].append(float(np.mean(terms["fell"])))
            for k, v in terms.items():
                if k != "fell":
                    history.setdefault(k, []).append(float(np.mean(v)))
            history["grad_norm"].append(float(optax.tree.norm(grad)))
            rank = (history["fell_rate"][-1], loss)
            if np.isfinite(loss) and rank < best[0]:
                best = (rank, raw, step)
            if step == config.steps:
                break
            updates, state = opt.update(grad, state, raw)
            raw = optax.apply_updates(raw, updates)
            history["step_s"].append(time.perf_counter() - t0)
            bar.set_postfix(loss=f"{loss:.4f}", fell=f"{history['fell_rate'][-1]:.0%}")
            bar.update(1)
        bar.close()
        tuned = best[1]
        held_before, held_terms_before = problem.value(raw0, "held")
        held_after, held_terms_after = problem.value(tuned, "held")
        before, after = problem.constants(raw0), problem.constants(tuned)
        overrides_before, overrides_after = problem.overrides(raw0), problem.overrides(tuned)
    return dict(
        plant=config.plant, controller=config.controller, config=_jsonable(dataclasses.asdict(config)),
        constants_before=before, constants_after=after,
        overrides_before=_jsonable(overrides_before), overrides_after=_jsonable(overrides_after),
        loss_before=history["loss"][0], loss_after=float(best[0][1]), best_step=int(best[2]),
        fell_rate_before=history["fell_rate"][0], fell_rate_after=history["fell_rate"][best[2]],
        heldout_loss_before=float(held_before), heldout_loss_after=float(held_after),
        heldout_fell_rate_before=float(np.mean(held_terms_before["fell"])),
        heldout_fell_rate_after=float(np.mean(held_terms_after["fell"])),
        history=history, wall_s=time.perf_counter() - t_start, **_jsonable(problem.info),
    )


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x


def _bar(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="step", file=sys.stderr, disable=not enabled, desc="tune", dynamic_ncols=True,
                mininterval=0.5)


def loss_png(record: dict) -> bytes:
    """The loss curve (training loss and its terms, the share of training rollouts that fell)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = record["history"]
    steps = np.arange(len(h["loss"]))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax.plot(steps, h["loss"], "k-", label="training loss")
    if "fall" in h:
        ax.plot(steps, h["fall"], "C3--", label="fall term (smooth)")
    if "error" in h:
        w = record.get("error_weight", 1.0)
        ax.plot(steps, np.asarray(h["error"]) * w, "C0:", label=f"footstep-error term (x{w:g})")
    ax.plot([0, steps[-1]], [record["heldout_loss_before"], record["heldout_loss_after"]], "s", color="0.4",
            label="held-out loss (seed, tuned)")
    ax.axvline(record["best_step"], color="C2", lw=0.8, label="kept iterate")
    ax.set_xlabel(f"{record['config']['optimizer']} step")
    ax.set_ylabel("loss")
    ax.legend(fontsize=7)
    ax.set_title(f"{record['plant']} / {record['controller']}: tuning")
    ax2.plot(steps, 100 * np.asarray(h["fell_rate"]), "C3-")
    ax2.set_xlabel(f"{record['config']['optimizer']} step")
    ax2.set_ylabel("training rollouts that fell, %")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def write_outputs(out: Path, record: dict) -> None:
    """``tuned.json`` and ``loss.png`` in ``out``, each written atomically (strict JSON)."""
    from jaxlp.files import save_bytes_atomic, save_text_atomic, strict_json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_text_atomic(out / "tuned.json", strict_json(record))
    save_bytes_atomic(out / "loss.png", loss_png(record))


HELP = "tune a controller's constants by gradient (optax) on 3lp or mjx"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``coman-sweep tune`` (registered by :mod:`sweeps.cli`)."""
    d = TuneConfig()
    p.add_argument("--plant", choices=PLANTS, default=None,
                   help="3lp (exact gradients) or mjx (forward mode); default 3lp for time-projection and dlqr "
                        "without --set or --tune, else mjx")
    p.add_argument("--robot", default=d.robot, help="3LP parameter preset (3lp)")
    p.add_argument("--controller", default=d.controller, help="the controller tuned (a name of the plant)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="its other settings (mjx)")
    p.add_argument("--tune", default=None,
                   help="comma-separated tunable settings (mjx; default: the controller's own choice, "
                        "coman-sweep controllers lists them)")
    p.add_argument("--steps", type=int, default=d.steps, help=f"optimiser steps (default {d.steps})")
    p.add_argument("--lr", type=float, default=d.learning_rate, help="learning rate in unconstrained coordinates")
    p.add_argument("--optimizer", choices=OPTIMIZERS, default=d.optimizer)
    p.add_argument("--batch", type=int, default=d.batch, help="training scenarios (fixed sample)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--n-steps", type=int, default=d.n_steps, help="steps per training rollout (3lp)")
    p.add_argument("--push-step", type=int, default=d.push_step, help="walking step pushed (mjx)")
    p.add_argument("--impulse-max", type=float, default=d.impulse_max_ns, help="largest training impulse, N s")
    p.add_argument("--noise-min", type=float, default=d.noise_min_m, help="sensor noise std range, m (3lp)")
    p.add_argument("--noise-max", type=float, default=d.noise_max_m)
    p.add_argument("--bias", type=float, default=d.bias_std_m, help="std of the per-rollout sensor bias, m (3lp)")
    p.add_argument("--tune-weights", action="store_true", help="also tune the DLQR weight scales (3lp)")
    p.add_argument("--holdout", action=argparse.BooleanOptionalAction, default=True,
                   help="validate on held-out sweeps (default on)")
    p.add_argument("--holdout-model", choices=PLANTS, default=None,
                   help="the model of the held-out sweeps (default: the plant)")
    p.add_argument("--out", type=Path, default=Path("tune-out"), help="output folder (default tune-out)")
    p.add_argument("--force", action="store_true", help="replace a finished tuning run in --out")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--x64", action="store_true", help="64-bit floats")


def default_plant(controller: str, overrides: bool) -> str:
    """``3lp`` for the controllers the 3LP model has (without MJX-only options), else ``mjx``."""
    return "3lp" if controller in ("time-projection", "dlqr") and not overrides else "mjx"


def config_from_args(args) -> TuneConfig:
    from sweeps.grid import freeze_overrides

    if args.plant is None:
        args.plant = default_plant(args.controller, bool(args.set or args.tune))
    overrides = ()
    if args.set:
        from mjx_coman import controllers

        if args.plant != "mjx":
            raise ValueError("--set applies to --plant mjx")
        overrides = freeze_overrides(controllers.parse_overrides(controllers.get(args.controller), args.set))
    tunables = tuple(v.strip() for v in args.tune.split(",") if v.strip()) if args.tune else ()
    if args.tune is not None and not tunables:
        raise ValueError("--tune is empty")
    if args.plant == "mjx":
        from mjx_coman import controllers

        controllers.get(args.controller)  # ValueError listing the known names
    return TuneConfig(plant=args.plant, robot=args.robot, controller=args.controller,
                      controller_overrides=overrides, tunables=tunables, steps=args.steps,
                      learning_rate=args.lr, optimizer=args.optimizer, batch=args.batch, seed=args.seed,
                      n_steps=args.n_steps, push_step=args.push_step, impulse_max_ns=args.impulse_max,
                      noise_min_m=args.noise_min, noise_max_m=args.noise_max, bias_std_m=args.bias,
                      tune_weights=args.tune_weights, x64=args.x64).validate()


def run(args, parser) -> int:
    """Run ``coman-sweep tune``; bad arguments exit 2 with one line (``parser.error``)."""
    try:
        config = config_from_args(args)
        check_output_dir("--out", args.out)
        check_no_overwrite("--out", args.out, ("tuned.json",), args.force)
        if config.plant == "3lp":
            from jaxlp.presets import get_params

            get_params(config.robot)
    except (ValueError, RuntimeError) as e:
        parser.error(" ".join(str(e).split()))
    try:
        record = tune(config, progress=not args.no_progress)
    except ValueError as e:
        parser.error(" ".join(str(e).split()))
    record["command"] = "coman-sweep " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    write_outputs(args.out, record)
    c0, c1 = record["constants_before"], record["constants_after"]
    print(f"{config.plant}/{config.controller}: loss {record['loss_before']:.4f} -> {record['loss_after']:.4f} "
          f"(step {record['best_step']}); held-out {record['heldout_loss_before']:.4f} -> "
          f"{record['heldout_loss_after']:.4f}; training falls {record['fell_rate_before']:.0%} -> "
          f"{record['fell_rate_after']:.0%}; {record['wall_s']:.1f} s")
    for k in c0:
        print(f"  {k:30s} {c0[k]:10.4g} -> {c1[k]:10.4g}")
    print(f"wrote {args.out}/tuned.json, loss.png")
    if args.holdout:
        from sweeps import holdout

        table = holdout.run_holdout(record, args.out, model=args.holdout_model or config.plant,
                                    progress=not args.no_progress)["table"]
        print(holdout.format_table(table))
        print(f"wrote {args.out}/holdout.json, holdout.npz, holdout.png and the sweeps in {args.out}/holdout/")
    return 0
