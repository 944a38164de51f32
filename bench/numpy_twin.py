"""The project's pure array functions executed by NumPy: the controller of ``bench/numpy_twin_loop.py``.

``bench/sweep_throughput.py`` also times "the same controller in NumPy driving
native MuJoCo, one rollout at a time" (``numpy_twin_steps_per_s``). Rather than
a hand port of the walking controller (estimation, time-projection table,
adaptive lift, inverse kinematics, knee compensation, hip switching), which
would drift from the real one, :func:`twin` rebuilds a function of the
project with its module globals rebound: ``jnp`` becomes a NumPy namespace
whose arrays also understand JAX's out-of-place updates ``x.at[i].set(v)`` and
``.add(v)``, and every function or module of the project it refers to is
rebuilt the same way (recursively). The result runs the very same source,
every operation executed eagerly by NumPy on small arrays, which is how a
NumPy controller of this pipeline spends its time. ``pytest -m slow tests/bench`` checks
that the twin's motor targets equal the jitted JAX controller's.

Only pure functions written against ``jnp`` twin; classes (NamedTuples,
dataclasses) are shared, and ``jax.tree_util`` works on NumPy leaves as is.
"""

from __future__ import annotations

import types

import numpy as np

PACKAGES = ("jaxlp", "mjx_coman")


class TwinArray(np.ndarray):
    """A NumPy array with JAX's functional update syntax ``x.at[idx].set(v)`` / ``.add(v)`` / ``.get()``."""

    @property
    def at(self) -> "_At":
        return _At(self)


class _At:
    def __init__(self, a):
        self.a = a

    def __getitem__(self, idx):
        return _Update(self.a, idx)


class _Update:
    def __init__(self, a, idx):
        self.a, self.idx = a, idx

    def _copy(self, value):
        dtype = np.result_type(self.a, value)
        return np.array(self.a, dtype=dtype, copy=True).view(TwinArray)

    def set(self, value):
        out = self._copy(value)
        out[self.idx] = value
        return out

    def add(self, value):
        out = self._copy(value)
        np.add.at(out, self.idx, value)
        return out

    def get(self):
        return self.a[self.idx]


def as_twin(x):
    """``x`` as a :class:`TwinArray` (NumPy arrays and scalars); anything else unchanged."""
    if isinstance(x, TwinArray):
        return x
    if isinstance(x, (np.ndarray, np.generic, float, int, bool)) or hasattr(x, "__array__"):
        return np.asarray(x).view(TwinArray)
    return x


def _wrap(fn):
    def call(*args, **kwargs):
        out = fn(*args, **kwargs)
        return out.view(TwinArray) if type(out) is np.ndarray else out
    call.__name__ = getattr(fn, "__name__", "numpy_function")
    return call


def _numpy_namespace() -> types.ModuleType:
    ns = types.ModuleType("jnp_twin", "NumPy standing in for jax.numpy (arrays with .at updates)")
    for name in dir(np):
        obj = getattr(np, name)
        setattr(ns, name, _wrap(obj) if callable(obj) and not isinstance(obj, type) else obj)
    return ns


JNP = _numpy_namespace()
_TWINS: dict[int, object] = {}


def _ours(obj) -> bool:
    name = getattr(obj, "__module__", None) if not isinstance(obj, types.ModuleType) else obj.__name__
    return bool(name) and name.split(".")[0] in PACKAGES


def _twin_globals(module_globals: dict) -> dict:
    """A module's globals with ``jnp``, JAX array constants and the project's functions and modules twinned."""
    import jax

    g = dict(module_globals)
    for name, obj in module_globals.items():
        if name == "jnp":
            g[name] = JNP
        elif isinstance(obj, jax.Array):  # a module-level constant: NumPy too, or every use is a JAX op
            g[name] = as_twin(np.asarray(obj))
        elif isinstance(obj, types.FunctionType) and _ours(obj):
            g[name] = twin(obj)
        elif isinstance(obj, types.ModuleType) and _ours(obj):
            g[name] = twin_module(obj)
    return g


def twin(fn: types.FunctionType) -> types.FunctionType:
    """``fn`` rebuilt with ``jnp`` (and the project functions it calls) bound to their NumPy twins."""
    key = id(fn)
    if key not in _TWINS:
        new = types.FunctionType(fn.__code__, {}, fn.__name__, fn.__defaults__, fn.__closure__)
        new.__kwdefaults__ = fn.__kwdefaults__
        new.__doc__ = fn.__doc__
        _TWINS[key] = new  # before the globals: recursive references resolve to the twin
        new.__globals__.update(_twin_globals(fn.__globals__))
    return _TWINS[key]


def twin_module(module: types.ModuleType) -> types.SimpleNamespace:
    """A namespace of the module's attributes, twinned as :func:`twin` twins a function's globals."""
    key = id(module)
    if key not in _TWINS:
        ns = types.SimpleNamespace()
        _TWINS[key] = ns  # before the attributes: modules that import each other resolve to the twin
        vars(ns).update(_twin_globals(vars(module)))
    return _TWINS[key]


def to_twin_tree(tree):
    """Every array leaf of a pytree (e.g. ``ControllerParams``) as a :class:`TwinArray` (float64)."""
    import jax

    def leaf(x):
        a = np.asarray(x)
        return a.astype(np.float64).view(TwinArray) if np.issubdtype(a.dtype, np.floating) else a.view(TwinArray)

    return jax.tree_util.tree_map(leaf, tree)
