"""jaxlp tests run in 64-bit floats (check values, finite differences)."""

import jax
import pytest


@pytest.fixture(scope="module", autouse=True)
def _x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def coman():
    from jaxlp.presets import get_params

    with jax.enable_x64(True):
        return get_params("coman")
