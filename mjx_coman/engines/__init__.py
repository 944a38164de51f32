"""Physics engines for the environment: ``mjx`` (MuJoCo MJX, differentiable, the default) and ``native``
(MuJoCo C over a thread pool, for CPU sweeps). One engine per module under :class:`~.base.Engine`; the
environment (:func:`mjx_coman.env.step`) knows only :meth:`Engine.step`.
"""

from __future__ import annotations

import mujoco

from mjx_coman.engines.base import Engine
from mjx_coman.engines.mjx_engine import MjxEngine
from mjx_coman.engines.native import NativeEngine

ENGINES = ("mjx", "native")
MJX = MjxEngine()


def make_engine(name: str, mj_model: mujoco.MjModel | None = None, n_threads: int | None = None) -> Engine:
    """The engine ``name`` for ``mj_model`` (needed by ``native``).

    Raises:
        ValueError: an unknown name (listing the known ones), ``native`` without a model, a bad ``n_threads``.
    """
    if name == "mjx":
        return MJX
    if name == "native":
        if mj_model is None:
            raise ValueError("engine 'native' needs the MjModel it steps")
        return NativeEngine(mj_model, n_threads)
    raise ValueError(f"engine={name!r} is not one of {', '.join(ENGINES)}")


__all__ = ["ENGINES", "Engine", "MJX", "MjxEngine", "NativeEngine", "make_engine"]
