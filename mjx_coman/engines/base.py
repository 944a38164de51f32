"""The physics engine protocol: what advances the rigid bodies one timestep inside :func:`mjx_coman.env.step`.

Everything around the physics (the delay line, the motor boards and springs, the sensors, the controller,
the ground-truth judge) is the same JAX code on every engine; an engine only maps ``(model, data)`` with
``ctrl`` and ``xfrc_applied`` set to the data one timestep later, with MuJoCo's semantics: positions and
velocities integrated, the kinematic and contact fields those of the state the step started from (as
``mj_step`` leaves them).
"""

from __future__ import annotations

import abc

import mujoco
from mujoco import mjx


class Engine(abc.ABC):
    """One physics engine (hashable: it is a static field of :class:`mjx_coman.env.EnvParams`).

    Attributes:
        name: the registry name (``mjx``, ``native``).
        differentiable: ``jax.jvp``/``jax.grad`` go through :meth:`step`.
    """

    name: str = ""
    differentiable: bool = True

    @abc.abstractmethod
    def step(self, model: mjx.Model, data: mjx.Data) -> mjx.Data:
        """One physics timestep (traceable; vmap over robots)."""

    @abc.abstractmethod
    def for_model(self, mj_model: mujoco.MjModel) -> "Engine":
        """This engine for another compiled model (a scene variant: terrain, slope, payload)."""
