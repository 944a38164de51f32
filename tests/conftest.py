"""Test-wide settings: the XLA CPU flags of :mod:`jaxlp.xla_flags`, set before JAX starts; test grouping.

Under pytest-xdist (``-n 2 --dist loadgroup``, the README's test command) each test module is one group, so
its module-scoped fixtures are built once; modules that share a session-scoped compilation share a group:
the shared walk of every position-controlled controller (``tests/mjx_coman/conftest.py``; each torque-controlled
family has its own), and the subprocesses that share JAX's
persistent compilation cache (the walk command line and notebook 03; the studies command line and notebook 06;
the scorecard's agreement test and notebook 08).
"""

import os
import shutil
import tempfile

import pytest

from jaxlp.xla_flags import configure_cpu

configure_cpu()

CACHE_ENV = "JAX_COMPILATION_CACHE_DIR"
MIN_TIME_ENV = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"


def pytest_configure(config):
    """One JAX persistent compilation cache for the session, shared by the xdist workers (they inherit the
    controller's environment) and the subprocesses: a walk compiled by one worker, or by an earlier test with
    a fresh ``jax.jit`` of the same program, is loaded by the next instead of compiled again. A fresh folder
    per session (removed at its end) unless the caller set one."""
    if not hasattr(config, "workerinput") and CACHE_ENV not in os.environ:
        os.environ[CACHE_ENV] = tempfile.mkdtemp(prefix="jax-test-cache-")
        config._jax_cache_owned = os.environ[CACHE_ENV]
    # every program, however quick to compile: a subprocess or worker loads the few hundred small eager ops
    # (tens of ms each to compile) that every process of the suite otherwise compiles again
    os.environ.setdefault(MIN_TIME_ENV, "0")
    import jax

    jax.config.update("jax_compilation_cache_dir", os.environ[CACHE_ENV])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(os.environ[MIN_TIME_ENV]))


def pytest_unconfigure(config):
    owned = getattr(config, "_jax_cache_owned", None)
    if owned:
        shutil.rmtree(owned, ignore_errors=True)

SHARED_GROUPS = {
    "walks": ("test_contract.py", "test_rollout.py", "test_ground_truth.py", "test_estimation.py", "test_native.py"),
    "walk-subprocesses": ("test_walk_cli.py", "test_notebook_03.py"),
    "studies-subprocesses": ("test_studies_cli.py", "test_notebook_06.py"),
    "side-by-side": ("test_scorecard.py", "test_notebook_08.py"),
}


# Groups that take a minute or more on 2 cores (``--durations``), longest first.
LONGEST_FIRST = ("studies-subprocesses", "side-by-side", "walk-subprocesses",
                 "walks", "torque-walks-footstep-mpc",
                 "torque-walks-wbc-stand", "torque-walks-straight-leg", "tests/mjx_coman/test_env.py",
                 "tests/sweeps/test_sweeps.py", "tests/sweeps/test_sharded.py", "tests/mjx_coman/test_scenarios.py", "tests/sweeps/test_tune.py",
                 "tests/jaxlp/test_simulate.py", "tests/mjx_coman/test_notebook_02.py", "tests/mjx_coman/test_sensors.py")


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook, which reads the markers into the node ids
def pytest_collection_modifyitems(config, items):
    import jax

    if jax.config.jax_enable_x64:  # a module that sets it at import changes every later test in its worker
        raise pytest.UsageError("a test module turned jax_enable_x64 on at import: use `with jax.enable_x64(True):`"
                                " in a fixture (tests/jaxlp/conftest.py) instead")
    group_of = {f: g for g, files in SHARED_GROUPS.items() for f in files}
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            name = item.path.name
            group = group_of.get(name, str(item.path.relative_to(config.rootpath)))
            name = getattr(getattr(item, "callspec", None), "params", {}).get("name")
            if group == "walks" and _torque_controlled(name):
                group = f"torque-walks-{_family_of(name)}"  # each torque family's batch compiles apart
            item.add_marker(pytest.mark.xdist_group(group))
    # Longest groups first: xdist hands out groups in collection order, so a long one collected last kept one
    # worker busy minutes after the other had finished (longest-processing-time-first scheduling).
    rank = {g: i for i, g in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda it: rank.get(it.get_closest_marker("xdist_group").args[0], len(rank)))


def _family_of(name) -> str:
    from mjx_coman import controllers

    core = controllers.get(name).core()
    return next(n for n in controllers.names() if controllers.get(n).core() == core)


def _torque_controlled(name) -> bool:
    if not isinstance(name, str):
        return False
    from mjx_coman import controllers

    return name in controllers.names() and controllers.get(name).gait(controllers.default_config(name)).plant != "position"
