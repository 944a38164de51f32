"""``coman-sweep tune --plant mjx``: the dead-zones and ``zeta`` of the MJX COMAN walk, by gradients through contact.

The plant is :func:`mjx_coman.walking.rollout.walk`: COMAN in MuJoCo MJX under
the seed's walking controller, pushed on the torso during a short walk
(``MJX_SECONDS``). Tuned: the four sagittal dead-zone thresholds and the IIR
constant ``zeta`` of :class:`mjx_coman.walking.controller.ControllerParams`
(the velocity window is a static integer there). The loss is the sagittal
sway after the push: the mean square of the true pelvis-minus-stance-foot
distance (``trace.true_rel_m``), in cm^2, over a small fixed batch of pushes.

Gradients are forward-mode (``jax.jacfwd``): MJX's constraint solver runs a
``lax.while_loop`` (unless ``opt.iterations == 1``), which reverse mode
cannot differentiate. How far they can be trusted is what
:func:`gradient_check` measures against central differences.
"""

from __future__ import annotations

import jaxlp  # noqa: F401  (XLA CPU flags before JAX starts)

import time

import numpy as np

MJX_SECONDS = 1.2  # start-up phase, one walking phase, the push in it
NAMES = ("deadzone_swing_position_m", "deadzone_pelvis_position_m", "deadzone_swing_velocity_mps",
         "deadzone_pelvis_velocity_mps", "zeta")


def check_available() -> None:
    """Raise ``RuntimeError`` (one line) when the MJX walking rollout is not available."""
    try:
        from mjx_coman.walking import controller, rollout  # noqa: F401
    except ImportError as e:
        raise RuntimeError(f"plant 'mjx': the MJX walking rollout is not available ({e}); use --plant 3lp") from None
    if not hasattr(rollout, "walk") or not hasattr(controller, "make_controller_params"):
        raise RuntimeError("plant 'mjx': mjx_coman.walking lacks walk / make_controller_params; use --plant 3lp")


def setup(seconds: float = MJX_SECONDS, soft_contacts: bool = False):
    """Environment, seed controller parameters and walk spec (under the caller's float precision).

    ``soft_contacts``: foot-floor time constant 0.05 s instead of 0.02 s, one solver
    iteration and 4 line-search iterations (smoother contact, cheaper derivatives).
    """
    import mjx_coman
    from mjx_coman import env as E
    from mjx_coman.walking import controller as C, rollout as RO

    m = mjx_coman.load_model()
    if soft_contacts:
        m.pair_solref[:, 0] = 0.05
        m.opt.iterations = 1
        m.opt.ls_iterations = 4
    env = E.make_env_params(mj_model=m)
    return env, C.make_controller_params(env, 0.0), RO.WalkSpec(seconds=seconds, record_every=5)


def pushes(n: int, seed: int, impulse_max_ns: float = 4.0, seconds: float = MJX_SECONDS):
    """``n`` pushes of 0.1 s in the walking phase of a short walk: start 0.45-0.75 ``seconds``, forward or backward."""
    import jax.numpy as jnp

    from mjx_coman.walking import rollout as RO

    rng = np.random.default_rng(seed)
    start = rng.uniform(0.45, 0.75, n) * seconds
    imp = rng.uniform(0.25, 1.0, n) * impulse_max_ns
    heading = np.where(rng.uniform(size=n) < 0.5, 0.0, np.pi)
    p = RO.make_push(start, 0.1, impulse_ns=imp, direction_rad=heading)
    return RO.WalkPush(p.start_s, jnp.broadcast_to(p.duration_s, (n,)), p.force_n)


def raw_of(ctrl_params):
    import jax.numpy as jnp

    z = ctrl_params.zeta
    return jnp.concatenate([jnp.log(ctrl_params.deadzone), (jnp.log(z) - jnp.log1p(-z))[None]])


def loss_fn(env, ctrl_params, spec, batch, keys):
    """``loss(raw) -> (sway cm^2, fell per push)`` over a batch of pushes (raw: log thresholds, logit zeta)."""
    import jax
    import jax.numpy as jnp

    from mjx_coman.walking import rollout as RO

    def loss(raw):
        cp = ctrl_params.replace(deadzone=jnp.exp(raw[:4]), zeta=jax.nn.sigmoid(raw[4]))
        r = jax.vmap(lambda p, k: RO.walk(env, cp, p, spec, k))(batch, keys)
        sway = jnp.mean(r.trace.true_rel_m[:, :, 0, 1] ** 2, axis=1) * 1e4
        return jnp.mean(sway), r.fell

    return loss


def gradient_check(eps=(1e-2, 1e-3, 1e-4), soft_contacts: bool = False, seconds: float = MJX_SECONDS,
                   impulse_ns: float = 3.0) -> dict:
    """Forward-mode gradient of one pushed walk's sway vs central differences, per constant (float64)."""
    import jax
    import jax.numpy as jnp

    from mjx_coman.walking import rollout as RO

    with jax.enable_x64(True):
        env, cp, spec = setup(seconds, soft_contacts)
        push = RO.make_push([0.5 * seconds], 0.1, impulse_ns=[impulse_ns], direction_rad=[0.0])
        batch = RO.WalkPush(push.start_s, jnp.asarray([0.1]), push.force_n)
        keys = jax.random.split(jax.random.PRNGKey(0), 1)
        loss = loss_fn(env, cp, spec, batch, keys)
        raw0 = raw_of(cp)
        f = jax.jit(lambda r: loss(r)[0])
        t0 = time.perf_counter()
        value = float(f(raw0))
        fwd_s = time.perf_counter() - t0
        g = jax.jit(jax.jacfwd(lambda r: loss(r)[0]))
        t0 = time.perf_counter()
        grad = np.asarray(g(raw0))
        grad_s = time.perf_counter() - t0
        fd = {}
        for i, name in enumerate(NAMES):
            fd[name] = [(float(f(raw0.at[i].add(e))) - float(f(raw0.at[i].add(-e)))) / (2 * e) for e in eps]
    return dict(loss_cm2=value, eps=list(eps), soft_contacts=soft_contacts, seconds=seconds,
                gradient={n: float(v) for n, v in zip(NAMES, grad)}, central_differences=fd,
                first_forward_s=fwd_s, first_gradient_s=grad_s)


def tune_mjx(config, progress: bool = True) -> dict:
    """A short optax run on the MJX walk (``config.batch`` pushes, at most 2); same record as the 3LP run."""
    import dataclasses

    import jax
    import jax.numpy as jnp
    import optax

    from sweeps.tune import _bar, _optimizer

    check_available()
    t_start = time.perf_counter()
    n = min(config.batch, 2)
    with jax.enable_x64(config.x64):
        env, cp, spec = setup()
        train, held = pushes(n, config.seed), pushes(n, config.seed + 1)
        keys = jax.random.split(jax.random.PRNGKey(config.seed), n)
        value_grad = {name: (jax.jit(lambda r, b=b: loss_fn(env, cp, spec, b, keys)(r)),
                             jax.jit(jax.jacfwd(lambda r, b=b: loss_fn(env, cp, spec, b, keys)(r)[0])))
                      for name, b in (("train", train), ("held", held))}
        raw = raw_of(cp)
        raw0 = raw
        opt = _optimizer(config)
        state = opt.init(raw)
        history = dict(loss=[], fall=[], error=[], fell_rate=[], grad_norm=[], step_s=[])
        best = (np.inf, raw, -1)
        bar = _bar(config.steps, progress)
        for step in range(config.steps + 1):
            t0 = time.perf_counter()
            loss, fell = value_grad["train"][0](raw)
            loss = float(loss)
            history["loss"].append(loss)
            history["error"].append(loss)
            history["fall"].append(float(np.mean(fell)))
            history["fell_rate"].append(float(np.mean(fell)))
            if np.isfinite(loss) and loss < best[0]:
                best = (loss, raw, step)
            if step == config.steps:
                break
            grad = value_grad["train"][1](raw)
            history["grad_norm"].append(float(jnp.linalg.norm(grad)))
            updates, state = opt.update(grad, state, raw)
            raw = optax.apply_updates(raw, updates)
            history["step_s"].append(time.perf_counter() - t0)
            bar.set_postfix(loss=f"{loss:.3f}")
            bar.update(1)
        bar.close()
        held_before, held_fell_before = value_grad["held"][0](raw0)
        held_after, held_fell_after = value_grad["held"][0](best[1])

    def consts(r):
        r = np.asarray(r, float)
        d = dict(zip(NAMES, [*np.exp(r[:4]), 1.0 / (1.0 + np.exp(-r[4]))]))
        d.update(window_samples=float(cp.window), weight_scale_position=1.0, weight_scale_velocity=1.0,
                 weight_scale_torque=1.0)
        return {k: float(v) for k, v in d.items()}

    return dict(
        plant="mjx", config=dataclasses.asdict(config), constants_before=consts(raw0), constants_after=consts(best[1]),
        lateral_deadzone=None, loss_before=history["loss"][0], loss_after=float(best[0]), best_step=int(best[2]),
        fell_rate_before=history["fell_rate"][0], fell_rate_after=history["fell_rate"][best[2]],
        heldout_loss_before=float(held_before), heldout_loss_after=float(held_after),
        heldout_fell_rate_before=float(np.mean(held_fell_before)),
        heldout_fell_rate_after=float(np.mean(held_fell_after)),
        error_weight=1.0, history=history, wall_s=time.perf_counter() - t_start,
        loss_definition="mean sagittal (pelvis - stance foot)^2, cm^2, over a 1.2 s walk pushed in its walking phase",
        pushes=dict(train=np.asarray(train.force_n)[:, 0].tolist(), held=np.asarray(held.force_n)[:, 0].tolist()),
    )
