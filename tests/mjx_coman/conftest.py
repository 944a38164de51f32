"""Shared, session-scoped fixtures: one compiled reset and one compiled tick chunk."""

import jax
import numpy as np
import pytest

from mjx_coman import experiments
from mjx_coman.env import make_env_params, standing_posture


@pytest.fixture(scope="session")
def env_params():
    return make_env_params()


@pytest.fixture(scope="session")
def standing_q():
    return standing_posture()[0]


@pytest.fixture(scope="session")
def reset_state(env_params):
    return experiments._reset(jax.random.PRNGKey(0), env_params)


@pytest.fixture(scope="session")
def stand_run(env_params, reset_state, standing_q):
    """One second of standing under position control (500 ticks), every tick recorded."""
    n = 500
    final, rec = experiments.run(env_params, reset_state, np.broadcast_to(standing_q, (n, len(standing_q))),
                                 np.zeros((n, 3)))
    return final, rec
