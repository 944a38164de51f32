"""Tuning on the ``mjx`` model (:func:`tune_problem`) and its held-out grid (:func:`holdout_grid`).

Forward-mode derivatives (``jax.jacfwd``: MJX's constraint solver runs a ``lax.while_loop``, which reverse mode
cannot differentiate) of the ground-truth sway after a push with respect to the controller's tunable settings,
on the MJX engine (the derivatives go through the physics).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from sweeps.models import TuneProblem
from sweeps.models.mjx_env import _controllers, _rollout_module, nominal_env

TUNE_SECONDS_AFTER = 0.8  # the walk goes on two steps after the push (the sway they take)


def _transform(setting):
    """``(to_raw, from_raw)`` of a tunable by its bounds: logit between two, log above one, identity."""
    lo, hi = setting.bounds if setting.bounds is not None else (None, None)
    if lo is not None and hi is not None:
        return (lambda x: jnp.log(x - lo) - jnp.log(hi - x)), (lambda r: lo + (hi - lo) * jax.nn.sigmoid(r))
    if lo is not None:
        return (lambda x: jnp.log(x - lo)), (lambda r: lo + jnp.exp(r))
    return (lambda x: x), (lambda r: r)


def sway_record(state):
    """A save function: the sagittal CoM offset from the loaded feet (heading frame), m."""
    from mjx_coman import ground_truth as gt

    d = state.env.data
    off = gt.com_m(d)[:2] - gt.support_point(d)[:2]
    yaw = gt.pelvis_yaw_rad(d)
    return jnp.cos(yaw) * off[0] + jnp.sin(yaw) * off[1]


def tune_problem(tc) -> TuneProblem:
    """Ground-truth sway after pushes of the MJX walk, as a function of the controller's tunable settings.

    ``tc.tunables`` names the settings (default: the controller's ``tune_default``); each moves in
    unconstrained coordinates by its bounds. The scenarios: ``min(tc.batch, 2)`` 0.1 s pushes, forward or
    backward, in walking step ``tc.push_step`` (at 30-70 % of it, 25-100 % of ``tc.impulse_max_ns``) of a walk
    that ends ``TUNE_SECONDS_AFTER`` later; the loss is the mean square of the sagittal distance of the CoM
    from the loaded feet (:func:`mjx_coman.ground_truth.support_point`) over the walk, cm^2.
    """
    ctrls, ro = _controllers(), _rollout_module()
    ctrl = ctrls.get(tc.controller)  # the names are checked before the config is built (seconds for the 3LP's)
    names = tuple(tc.tunables or ctrl.tune_default or ctrl.tunables())
    by_name = {s.name: s for s in ctrl.settings}
    for n in names:
        if n not in by_name or not by_name[n].tunable:
            raise ValueError(f"{n!r} is not a tunable setting of {tc.controller}; tunable: {', '.join(ctrl.tunables())}")
    if not names:
        raise ValueError(f"controller {tc.controller!r} has no tunable settings to tune")
    ctrl, cfg0 = ctrls.load(tc.controller, dict(tc.controller_overrides or {}))
    tf = {n: _transform(by_name[n]) for n in names}
    g = ctrl.gait(cfg0)
    env = nominal_env(1.0, g.plant)
    start = g.first_step_s + tc.push_step * g.step_time_s
    seconds = start + g.step_time_s + TUNE_SECONDS_AFTER
    spec, save = ro.WalkSpec(seconds=seconds), ro.SaveAt(sway_record, every=5)
    n = min(tc.batch, 2)

    def pushes(seed):
        rng = np.random.default_rng(seed)
        t0 = start + rng.uniform(0.3, 0.7, n) * g.step_time_s
        imp = rng.uniform(0.25, 1.0, n) * tc.impulse_max_ns
        heading = np.where(rng.uniform(size=n) < 0.5, 0.0, np.pi)
        p = ro.make_push(t0, 0.1, impulse_ns=imp, direction_rad=heading)
        return ro.Push(p.start_s, jnp.broadcast_to(p.duration_s, (n,)), p.force_n)

    batches = {"train": pushes(tc.seed), "held": pushes(tc.seed + 1)}
    keys = jax.random.split(jax.random.PRNGKey(tc.seed), n)
    joy = ctrls.joystick(tc.speed_mps)

    def physical(raw):
        return {k: tf[k][1](v) for k, v in raw.items()}

    def loss(raw, batch):
        cfg = cfg0.replace(**physical(raw))
        r = jax.vmap(lambda p, k: ro.walk(ctrl.core(), cfg, env, p, k, spec, joy, save))(batch, keys)
        return jnp.mean(r.saved**2) * 1e4, r.fell

    fns = {split: (jax.jit(lambda r, b=b: loss(r, b)), jax.jit(jax.jacfwd(lambda r, b=b: loss(r, b)[0])))
           for split, b in batches.items()}

    def value(raw, split):
        loss_v, fell = fns[split][0](raw)
        return loss_v, dict(fell=fell)

    def vg(raw, split):
        return value(raw, split), fns[split][1](raw)

    def to_values(raw):
        return {k: (tuple(float(x) for x in np.ravel(v)) if np.ndim(v) else float(v))
                for k, v in ((k, np.asarray(v)) for k, v in physical(raw).items())}

    def constants(raw):
        out = {}
        for k, v in to_values(raw).items():
            if isinstance(v, tuple):
                out.update({f"{k}_{i}": x for i, x in enumerate(v)})
            else:
                out[k] = v
        return out

    raw0 = {k: tf[k][0](jnp.asarray(getattr(cfg0, k))) for k in names}
    return TuneProblem(raw0=raw0, value=value, value_and_grad=vg, constants=constants, overrides=to_values,
                       info=dict(tunables=list(names), loss_definition=(
                           "mean square of the sagittal CoM offset from the loaded feet, cm^2, over a "
                           f"{seconds:g} s walk pushed in walking step {tc.push_step}"),
                           pushes=dict(train=np.asarray(batches["train"].force_n)[:, 0].tolist(),
                                       held=np.asarray(batches["held"].force_n)[:, 0].tolist())))


def holdout_grid(record: dict) -> dict:
    """Held-out MJX sweeps of a tuning record: forward, backward, left and right, 4 phases x 15 impulses of
    1-8 N s (240 walks per set of constants) in walking step 2 of 8-step walks, nominal IMU/F-T noise and
    2 mrad encoder offsets (the systematic errors the dead-zones are for)."""
    return dict(directions=("forward", "backward", "left", "right"), phases=(0.0, 0.25, 0.5, 0.75),
                impulses_ns=tuple(float(v) for v in np.linspace(1.0, 8.0, 15)), n_steps=8, push_step=2,
                sensor_noise_scale=1.0, encoder_offset_std_rad=0.002, chunk=60)
