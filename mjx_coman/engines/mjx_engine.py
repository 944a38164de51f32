"""MuJoCo MJX: the physics in JAX, differentiable, compiled with the rest of the rollout (the default)."""

from __future__ import annotations

from mujoco import mjx

from mjx_coman.engines.base import Engine


class MjxEngine(Engine):
    """``mjx.step``; holds no model (the ``mjx.Model`` travels in the environment parameters)."""

    name = "mjx"
    differentiable = True

    def step(self, model, data):
        return mjx.step(model, data)

    def for_model(self, mj_model):
        return self

    def __eq__(self, other):
        return type(other) is MjxEngine

    def __hash__(self):
        return hash(MjxEngine)

    def __repr__(self):
        return "MjxEngine()"
