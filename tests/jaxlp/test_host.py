"""host_eval: concrete NumPy results inside a trace, in the caller's float width, one program."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxlp.host import host_eval


def _fn(x):
    return {"y": jnp.cumsum(jnp.eye(3) @ x), "n": jnp.sum(x > 0)}


def test_inside_a_trace_the_result_is_concrete():
    seen = {}

    @jax.jit
    def outer(z):
        seen["inner"] = host_eval(_fn, np.arange(3.0))  # the argument of the outer trace is not used
        return z + seen["inner"]["y"]

    out = outer(jnp.ones(3))
    assert isinstance(seen["inner"]["y"], np.ndarray) and isinstance(seen["inner"]["n"], np.ndarray)
    np.testing.assert_allclose(seen["inner"]["y"], [0.0, 1.0, 3.0])
    assert int(seen["inner"]["n"]) == 2
    np.testing.assert_allclose(np.asarray(out), [1.0, 2.0, 4.0])


def test_the_callers_float_width_is_kept():
    with jax.enable_x64(False):  # a context, not the global setting: the thread does not inherit it by itself
        assert host_eval(_fn, np.arange(3.0))["y"].dtype == np.float32
    with jax.enable_x64(True):
        assert host_eval(_fn, np.arange(3.0))["y"].dtype == np.float64


def test_under_compile_time_eval_it_is_one_program(monkeypatch):
    """The thread escapes the context: one compilation of ``jit(_fn)``, no op-by-op eager compiles."""
    compiled = []
    real = jax._src.compiler.backend_compile_and_load
    monkeypatch.setattr(jax._src.compiler, "backend_compile_and_load",
                        lambda *a, **k: compiled.append(1) or real(*a, **k))
    with jax.ensure_compile_time_eval():
        out = host_eval(lambda x: _fn(x * 1.5), np.arange(3.0))  # a fresh function: not in jit's cache
    np.testing.assert_allclose(out["y"], [0.0, 1.5, 4.5])
    assert len(compiled) <= 1
