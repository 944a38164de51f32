"""Several controller families as one controller: a ``lax.switch`` on an index in the config.

A rollout compiles the physics once per controller; most of a walk's
compilation is the physics. :func:`bundle` makes one
:class:`~mjx_coman.controllers.base.Controller` out of several, so one
compiled walk (vmapped over rows that pick different members) runs them all:
the config is ``BundleConfig(index, configs)`` (a member's index and every
member's config), the state is the tuple of the members' states, and the
telemetry's ``extra`` is the tuple of the members' extras (zeros for the
members not running). Under ``vmap`` a switch on a batched index evaluates
every member each tick and keeps the chosen one's output, so a bundle costs
the sum of its members' controller ticks (the physics is shared).

The members must share the reset posture and the control period; the
bundle's gait is its first member's (or the chosen one's, on the host).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Sequence

import jax
import jax.numpy as jnp

from mjx_coman.controllers.base import Controller, Gait


@functools.partial(jax.tree_util.register_dataclass, data_fields=["index", "configs"], meta_fields=[])
@dataclasses.dataclass(frozen=True)
class BundleConfig:
    """``index``: int32, the member that runs; ``configs``: every member's config (a tuple)."""

    index: jax.Array
    configs: tuple

    def replace(self, **kw) -> "BundleConfig":
        return dataclasses.replace(self, **kw)


def bundle_config(index: int, configs: Sequence) -> BundleConfig:
    """The config of a bundle that runs member ``index``."""
    return BundleConfig(jnp.asarray(index, jnp.int32), tuple(configs))


def bundle(members: Sequence[Controller], name: str = "bundle") -> Controller:
    """One controller that runs ``members[config.index]`` (see the module docstring).

    Raises:
        ValueError: fewer than two members.
    """
    members = tuple(members)
    if len(members) < 2:
        raise ValueError(f"a bundle needs at least two controllers, got {len(members)}")

    def init(config: BundleConfig, env_params, key):
        return tuple(m.init(c, env_params, key) for m, c in zip(members, config.configs))

    def step(config: BundleConfig, state, obs):
        outs = [jax.eval_shape(m.step, c, s, obs) for m, c, s in zip(members, config.configs, state)]
        zeros = [jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), o[2].extra) for o in outs]

        def branch(i):
            def run(ops):
                configs, states, o = ops
                s_i, cmd, tel = members[i].step(configs[i], states[i], o)
                new = tuple(s_i if j == i else states[j] for j in range(len(members)))
                extra = tuple(tel.extra if j == i else zeros[j] for j in range(len(members)))
                return new, cmd, tel._replace(extra=extra)
            return run

        return jax.lax.switch(config.index, [branch(i) for i in range(len(members))], (config.configs, state, obs))

    def gait(config: BundleConfig) -> Gait:
        gaits = [m.gait(c) for m, c in zip(members, config.configs)]
        for g in gaits[1:]:
            if g.knee_rad != gaits[0].knee_rad or g.control_period_s != gaits[0].control_period_s:
                raise ValueError("bundled controllers must share the reset posture and the control period, got "
                                 + ", ".join(f"{m.name}: {g.knee_rad} rad, {g.control_period_s} s"
                                             for m, g in zip(members, gaits)))
        try:
            return gaits[int(config.index)]
        except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerIntegerConversionError):
            return gaits[0]  # traced index: the shared facts only (posture, control period)

    return Controller(name=name, make_config=bundle_config, init=init, step=step, gait=gait, settings=(),
                      privileged=any(m.privileged for m in members),
                      description="bundle of " + ", ".join(m.name for m in members))
