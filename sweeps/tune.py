"""``coman-sweep tune``: gradient tuning of the dead-zone and filter constants with optax.

    coman-sweep tune [--plant 3lp] [--steps 60] [--lr 0.05] [--optimizer adam] [--batch 64] [--seed 0]
                     [--n-steps 7] [--impulse-max 12] [--noise-min 0.0005] [--noise-max 0.0015] [--bias 0.002]
                     [--tune-weights] [--holdout | --no-holdout] [--holdout-mjx] [--out tune-out] [--no-progress]
                     [--x64]

Starts from the seed's constants (zeta 0.1, a 30-sample velocity window and
the Figure 9 thresholds of the training sensors, :func:`sweeps.objective.seed_constants`)
and minimises :func:`sweeps.objective.objective` over a fixed sample of
``--batch`` scenarios with an optax optimiser (Adam by default) on the
unconstrained coordinates. Keeps the iterate of lowest training loss. Writes
to ``--out`` (each file atomically): ``tuned.json`` (constants before and
after, training and held-out loss before and after, the history, the
command) and ``loss.png``; with ``--holdout`` (default) it also runs held-out
push grids (:mod:`sweeps.holdout`) with the seed and the tuned constants and
adds ``holdout.json`` and ``holdout.png``. On ``--plant mjx`` (or with
``--holdout-mjx``) the held-out pushes are MJX sweeps of the seed and the tuned
constants (:mod:`sweeps.holdout_mjx`): ``holdout_mjx.json``, ``holdout_mjx.png``.
"""

from __future__ import annotations

import jaxlp  # noqa: F401  (XLA CPU flags before JAX starts)

import argparse
import dataclasses
import io
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

PLANTS = ("3lp", "mjx")
OPTIMIZERS = ("adam", "adamw", "sgd")


@dataclasses.dataclass(frozen=True)
class TuneConfig:
    """Everything that decides a tuning run (plain values).

    Attributes:
        plant: ``"3lp"`` (exact gradients through the 3LP plant and its sensor model) or ``"mjx"``.
        robot: 3LP parameter preset.
        controller: walking controller whose constants are tuned.
        steps: optimiser steps.
        learning_rate: optimiser step size in the unconstrained coordinates (log / logit).
        optimizer: ``adam``, ``adamw`` or ``sgd`` (momentum 0.9).
        batch: training scenarios (a fixed sample).
        seed: PRNG seed of the training scenarios (held-out: ``seed + 1``).
        n_steps: phases per training rollout (pushes in step 2).
        impulse_max_ns: training impulses uniform in [0, this].
        noise_min_m, noise_max_m: white sensor noise std range, m.
        bias_std_m: per-rollout systematic sagittal bias std, m.
        tune_weights: also tune the DLQR weight scales.
        x64: 64-bit floats.
    """

    plant: str = "3lp"
    robot: str = "coman"
    controller: str = "time-projection"
    steps: int = 60
    learning_rate: float = 0.05
    optimizer: str = "adam"
    batch: int = 64
    seed: int = 0
    n_steps: int = 7
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
        if self.controller not in ("time-projection", "dlqr"):
            raise ValueError(f"controller {self.controller!r} has no constants to tune; use time-projection or dlqr")
        for name in ("steps", "batch"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not self.n_steps >= 4:
            raise ValueError(f"n_steps must be >= 4 (pushes come in step 2), got {self.n_steps}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        for name in ("impulse_max_ns", "noise_min_m", "bias_std_m"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not self.noise_max_m >= self.noise_min_m:
            raise ValueError(f"noise_max_m={self.noise_max_m} must be >= noise_min_m={self.noise_min_m}")
        return self

    def objective_spec(self):
        from sweeps.objective import ObjectiveSpec

        return ObjectiveSpec(controller=self.controller, n_steps=self.n_steps, push_step=2,
                             tune_weights=self.tune_weights)

    def distribution(self):
        from sweeps.objective import ScenarioDistribution

        return ScenarioDistribution(impulse_max_ns=self.impulse_max_ns,
                                    noise_std_m=(self.noise_min_m, self.noise_max_m),
                                    bias_std_m=self.bias_std_m).validate()


def _optimizer(config: TuneConfig):
    import optax

    base = {"adam": lambda: optax.adam(config.learning_rate),
            "adamw": lambda: optax.adamw(config.learning_rate, weight_decay=1e-3),
            "sgd": lambda: optax.sgd(config.learning_rate, momentum=0.9)}[config.optimizer]()
    return optax.chain(optax.zero_nans(), base)  # a rollout that went numerically bad must not move the constants


def tune(config: TuneConfig, progress: bool = True) -> dict:
    """Run the optimisation on the 3LP plant; return a JSON-ready record (no files written).

    Raises:
        ValueError: a bad configuration; ``--plant mjx`` when the MJX rollout is missing.
    """
    config.validate()
    if config.plant == "mjx":
        from sweeps.tune_mjx import tune_mjx

        return tune_mjx(config, progress=progress)
    import jax
    import optax

    from jaxlp.presets import get_params
    from sweeps import objective as O

    t_start = time.perf_counter()
    with jax.enable_x64(config.x64):
        params = get_params(config.robot)
        spec = config.objective_spec()
        dist = config.distribution()
        train = O.sample_scenarios(jax.random.PRNGKey(config.seed), config.batch, dist)
        held = O.sample_scenarios(jax.random.PRNGKey(config.seed + 1), config.batch, dist)
        seed_c, lateral = jax.jit(lambda s: O.seed_constants(params, spec, s))(train)
        raw = O.to_raw(seed_c, spec.window_max)
        # one compiled function for training and held-out scenarios (same batch size)
        value_grad = jax.jit(jax.value_and_grad(lambda r, s: O.objective(r, params, lateral, s, spec), has_aux=True))
        opt = _optimizer(config)
        state = opt.init(raw)
        history = dict(loss=[], fall=[], error=[], fell_rate=[], grad_norm=[], step_s=[])
        best = (np.inf, raw, -1)
        bar = _bar(config.steps, progress)
        for step in range(config.steps + 1):  # the last pass only evaluates the final iterate
            t0 = time.perf_counter()
            (loss, costs), grad = value_grad(raw, train)
            loss = float(loss)
            history["loss"].append(loss)
            history["fall"].append(float(np.mean(costs.fall)))
            history["error"].append(float(np.mean(costs.error)))
            history["fell_rate"].append(float(np.mean(costs.fell)))
            gnorm = float(optax.tree.norm(grad))
            history["grad_norm"].append(gnorm)
            if np.isfinite(loss) and loss < best[0]:
                best = (loss, raw, step)
            if step == config.steps:
                break
            updates, state = opt.update(grad, state, raw)
            raw = optax.apply_updates(raw, updates)
            history["step_s"].append(time.perf_counter() - t0)
            bar.set_postfix(loss=f"{loss:.4f}", fell=f"{history['fell_rate'][-1]:.0%}")
            bar.update(1)
        bar.close()
        tuned_raw = best[1]
        tuned = O.from_raw(tuned_raw, spec.window_max)
        (held_before, held_costs_before), _ = value_grad(O.to_raw(seed_c, spec.window_max), held)
        (held_after, held_costs_after), _ = value_grad(tuned_raw, held)
    return dict(
        plant=config.plant, config=dataclasses.asdict(config),
        constants_before=seed_c.as_dict(), constants_after=tuned.as_dict(),
        lateral_deadzone=[float(v) for v in np.asarray(lateral)],
        loss_before=history["loss"][0], loss_after=float(best[0]), best_step=int(best[2]),
        fell_rate_before=history["fell_rate"][0], fell_rate_after=history["fell_rate"][best[2]],
        heldout_loss_before=float(held_before), heldout_loss_after=float(held_after),
        heldout_fell_rate_before=float(np.mean(held_costs_before.fell)),
        heldout_fell_rate_after=float(np.mean(held_costs_after.fell)),
        error_weight=spec.error_weight, history=history, wall_s=time.perf_counter() - t_start,
    )


def _bar(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="step", file=sys.stderr, disable=not enabled, desc="tune", dynamic_ncols=True,
                mininterval=0.5)


def loss_png(record: dict) -> bytes:
    """The loss curve (training loss, its fall and error terms, the share of training rollouts that fell)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = record["history"]
    steps = np.arange(len(h["loss"]))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax.plot(steps, h["loss"], "k-", label="training loss")
    ax.plot(steps, h["fall"], "C3--", label="fall term (smooth)")
    w = record.get("error_weight", 0.1)
    ax.plot(steps, np.asarray(h["error"]) * w, "C0:", label=f"footstep-error term (x{w:g})")
    ax.axhline(record["heldout_loss_before"], color="0.5", lw=0.8)
    ax.plot([0, steps[-1]], [record["heldout_loss_before"], record["heldout_loss_after"]], "s", color="0.4",
            label="held-out loss (seed, tuned)")
    ax.axvline(record["best_step"], color="C2", lw=0.8, label="kept iterate")
    ax.set_xlabel(f"{record['config']['optimizer']} step")
    ax.set_ylabel("loss")
    ax.legend(fontsize=7)
    ax.set_title(f"{record['plant']}: tuning of the estimation constants")
    ax2.plot(steps, 100 * np.asarray(h["fell_rate"]), "C3-")
    ax2.set_xlabel(f"{record['config']['optimizer']} step")
    ax2.set_ylabel("training rollouts that fell, %")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def run_holdout_validation(record: dict, out: Path | None = None, **grid) -> dict:
    """Held-out push grids with the seed and the tuned constants; returns ``holdout.compare`` plus the runs.

    ``grid`` overrides :func:`sweeps.holdout.holdout_configs` arguments.
    """
    import jax
    import jax.numpy as jnp

    from sweeps import holdout
    from sweeps.objective import constants_from_dict

    cfg = record["config"]
    grid.setdefault("noise_std_m", 0.5 * (cfg["noise_min_m"] + cfg["noise_max_m"]))
    grid.setdefault("controller", cfg["controller"])
    with jax.enable_x64(cfg["x64"]):
        lateral = jnp.asarray(record["lateral_deadzone"])
        sets = {"seed": constants_from_dict(record["constants_before"]),
                "tuned": constants_from_dict(record["constants_after"])}
        runs = {name: [holdout.run_holdout(c_cfg, c, lateral, cfg["bias_std_m"])
                       for c_cfg in holdout.holdout_configs(**grid)] for name, c in sets.items()}
    table = holdout.compare(runs)
    if out is not None:
        from sweeps.runner import save_text_atomic

        holdout.plot_holdout(Path(out) / "holdout.png", runs)
        holdout.save_runs(Path(out) / "holdout.npz", runs)
        save_text_atomic(Path(out) / "holdout.json", json.dumps(dict(table, grid=_jsonable(grid)), indent=1))
    return dict(table=table, runs=runs)


def _jsonable(d: dict) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


def write_outputs(out: Path, record: dict) -> None:
    """``tuned.json`` and ``loss.png`` in ``out``, each written atomically."""
    from sweeps.runner import save_bytes_atomic, save_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_text_atomic(out / "tuned.json", json.dumps(record, indent=1))
    save_bytes_atomic(out / "loss.png", loss_png(record))


HELP = "tune the dead-zone and filter constants by gradient (optax)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``coman-sweep tune`` (registered by :mod:`sweeps.cli`)."""
    d = TuneConfig()
    p.add_argument("--plant", choices=PLANTS, default=d.plant, help="3lp (exact gradients) or mjx")
    p.add_argument("--robot", default=d.robot, help="3LP parameter preset")
    p.add_argument("--controller", choices=("time-projection", "dlqr"), default=d.controller)
    p.add_argument("--steps", type=int, default=d.steps, help=f"optimiser steps (default {d.steps})")
    p.add_argument("--lr", type=float, default=d.learning_rate, help="learning rate in log/logit coordinates")
    p.add_argument("--optimizer", choices=OPTIMIZERS, default=d.optimizer)
    p.add_argument("--batch", type=int, default=d.batch, help="training scenarios (fixed sample)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--n-steps", type=int, default=d.n_steps, help="steps per training rollout")
    p.add_argument("--impulse-max", type=float, default=d.impulse_max_ns, help="largest training impulse, N s")
    p.add_argument("--noise-min", type=float, default=d.noise_min_m, help="sensor noise std range, m")
    p.add_argument("--noise-max", type=float, default=d.noise_max_m)
    p.add_argument("--bias", type=float, default=d.bias_std_m, help="std of the per-rollout sensor bias, m")
    p.add_argument("--tune-weights", action="store_true", help="also tune the DLQR weight scales")
    p.add_argument("--holdout", action=argparse.BooleanOptionalAction, default=True,
                   help="validate on held-out push grids (default on): 3LP grids for --plant 3lp, "
                        "MJX sweeps for --plant mjx")
    p.add_argument("--holdout-mjx", action="store_true",
                   help="--plant 3lp: also validate the tuned constants on held-out MJX sweeps")
    p.add_argument("--out", type=Path, default=Path("tune-out"), help="output folder (default tune-out)")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--x64", action="store_true", help="64-bit floats")


def config_from_args(args) -> TuneConfig:
    return TuneConfig(plant=args.plant, robot=args.robot, controller=args.controller, steps=args.steps,
                      learning_rate=args.lr, optimizer=args.optimizer, batch=args.batch, seed=args.seed,
                      n_steps=args.n_steps, impulse_max_ns=args.impulse_max, noise_min_m=args.noise_min,
                      noise_max_m=args.noise_max, bias_std_m=args.bias, tune_weights=args.tune_weights,
                      x64=args.x64).validate()


def run(args, parser) -> int:
    """Run ``coman-sweep tune``; bad arguments exit 2 with one line (``parser.error``)."""
    try:
        config = config_from_args(args)
        from jaxlp.presets import get_params

        get_params(config.robot)
        if config.plant == "mjx" or args.holdout_mjx:
            from sweeps.tune_mjx import check_available

            check_available()
    except (ValueError, RuntimeError, ImportError) as e:
        parser.error(str(e).splitlines()[0])
    record = tune(config, progress=not args.no_progress)
    record["command"] = "coman-sweep " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    write_outputs(args.out, record)
    c0, c1 = record["constants_before"], record["constants_after"]
    print(f"{config.plant}: loss {record['loss_before']:.4f} -> {record['loss_after']:.4f} (step "
          f"{record['best_step']}); held-out {record['heldout_loss_before']:.4f} -> "
          f"{record['heldout_loss_after']:.4f}; training falls {record['fell_rate_before']:.0%} -> "
          f"{record['fell_rate_after']:.0%}; {record['wall_s']:.1f} s")
    for k in c0:
        print(f"  {k:30s} {c0[k]:10.4g} -> {c1[k]:10.4g}")
    if args.holdout and config.plant == "3lp":
        table = run_holdout_validation(record, args.out)["table"]
        for name, t in table.items():
            steps = "-" if t["mean_steps_to_recover"] is None else f"{t['mean_steps_to_recover']:.2f}"
            print(f"  held-out grid, {name} constants: {t['recovery_rate']:.1%} of {t['rollouts']} recovered; "
                  f"{t['settled_within_tol']} pushed walks settled under {t['recover_tol']:g}, after {steps} steps "
                  f"on average; median late landing error {t['late_error_median']:.3f}")
        print(f"wrote {args.out}/tuned.json, loss.png, holdout.json, holdout.npz, holdout.png")
    else:
        print(f"wrote {args.out}/tuned.json, loss.png")
    if (args.holdout and config.plant == "mjx") or args.holdout_mjx:
        from sweeps import holdout_mjx

        table = holdout_mjx.run_mjx_holdout(record, args.out, progress=not args.no_progress)["table"]
        print(holdout_mjx.format_table(table))
        print(f"wrote {args.out}/holdout_mjx.json, holdout_mjx.npz, holdout_mjx.png and the sweeps in "
              f"{args.out}/holdout-mjx/")
    return 0
