"""The controller contract, over every registered name: a new controller passes it or is not registered.

Every position-controlled name runs in one shared batch (``shared_walks`` in ``tests/mjx_coman/conftest.py``: the
families bundled into one compiled, vmapped, forward-differentiated walk); each torque-controlled family in its
own (``torque_walks``, each row on its plant). Checked per name: ``init`` and ``step`` jit and vmap (in the
batch: no compilation of their own); a walk of 2.4 s (1 s in the torque batch) from the controller's own
start without a fall; every output finite; the telemetry as declared; and, per family, the forward-mode derivative of a short
rollout cost (the mean horizontal CoM over the first 0.3 s) with respect to one tunable (the first
scalar one with a nonzero default) against central differences of +-5 %: within 5 % (float32). A torque
family's derivative is a second compilation of its batch (a QP a tick, forward-differentiated: about 2 min
on 2 cores), so its gradient check is ``slow``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_coman import controllers
from mjx_coman.actuators import NU
from mjx_coman.actuators import MODE_POSITION, MODE_TORQUE
from mjx_coman.controllers.base import SUPPORT_DOUBLE, SUPPORT_RIGHT, Telemetry

NAMES = controllers.names()
FAMILIES = [n for i, n in enumerate(NAMES) if all(controllers.get(m).core() != controllers.get(n).core()
                                                  for m in NAMES[:i])]
GRAD_RTOL = 0.05


def _unpushed_row(rows, name) -> int:
    return next(i for i, (n, push, _, delta) in enumerate(rows) if n == name and push is None and delta == 0.0)


def _finite(tree) -> bool:
    return all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(tree)
               if np.issubdtype(np.asarray(x).dtype, np.floating))


@pytest.mark.parametrize("name", NAMES)
def test_init_and_step_jit_and_vmap_in_the_batch(name, family_walks):
    """The batch jits and vmaps ``init`` (over keys) and ``step`` (over states, readings and configs): every
    row's commands and telemetry have the declared shapes and dtypes, finite."""
    rows, res = family_walks(name)[:2]
    i = _unpushed_row(rows, name)
    cmd, tel = (jax.tree_util.tree_map(lambda x: x[i], res.saved[k]) for k in ("command", "telemetry"))
    n_rec = res.time_s.shape[1]
    assert cmd.target.shape == (n_rec, NU) and cmd.torso_force_n.shape == (n_rec, 3) and cmd.mode.shape == (n_rec,)
    assert isinstance(tel, Telemetry) and _finite((cmd, tel))
    assert tel.support.dtype == jnp.int32 and tel.step.dtype == jnp.int32 and tel.support.shape == (n_rec,)
    for field in ("next_footstep_m", "footstep_adjustment_m", "com_m", "com_vel_mps"):
        assert getattr(tel, field).shape == (n_rec, 2), field
    assert np.all((np.asarray(tel.phase) >= 0) & (np.asarray(tel.phase) <= 1))
    plant = controllers.get(name).gait(controllers.default_config(name)).plant
    mode = MODE_POSITION if plant == "position" else MODE_TORQUE  # what its plant takes
    assert np.all(np.asarray(cmd.mode) == mode), (name, np.unique(cmd.mode))


@pytest.mark.parametrize("name", NAMES)
def test_walks_from_its_own_start_without_falling(name, family_walks):
    rows, res = family_walks(name)[:2]
    i = _unpushed_row(rows, name)
    one = jax.tree_util.tree_map(lambda x: x[i], res)
    assert not one.fell and not one.nan and one.fall_time_s == np.inf
    assert _finite(one.saved) and np.isfinite(one.mean_speed_mps) and np.isfinite(one.max_abs_footstep_adjustment_m)
    assert one.steps_to_recover == 0  # unpushed
    tel = one.saved["telemetry"]
    n_rec = one.time_s.shape[0]
    assert tel.support.shape == (n_rec,) and tel.step.shape == (n_rec,) and tel.phase.shape == (n_rec,)
    assert set(np.unique(tel.support)) <= {SUPPORT_DOUBLE, 1, SUPPORT_RIGHT}
    assert np.all((tel.phase >= 0) & (tel.phase <= 1))
    for field in ("next_footstep_m", "footstep_adjustment_m", "com_m", "com_vel_mps"):
        assert getattr(tel, field).shape == (n_rec, 2), field
    assert np.all(one.saved["pelvis_m"][:, 2] > 0.4)  # upright the whole time


def _torque(name) -> bool:
    return controllers.get(name).gait(controllers.default_config(name)).plant != "position"


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if _torque(n) else n for n in FAMILIES])
def test_gradient_of_a_short_rollout_matches_central_differences(name, family_walks):
    b = family_walks(name, gradient=True)
    rows, cost, dcost, probe, h, (i0, ip, im) = b.rows, b.cost, b.dcost, b.probe, b.h, b.sel
    assert rows[i0][3] == 0.0 and rows[ip][3] == h and rows[im][3] == -h
    fd = (cost[ip] - cost[im]) / (2 * h)
    assert np.isfinite(dcost[i0]) and abs(fd) > 1e-6, (probe, fd)  # the tunable moves the CoM
    assert abs(dcost[i0] - fd) <= GRAD_RTOL * abs(fd), (probe, dcost[i0], fd)
