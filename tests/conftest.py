"""Test-wide settings.

XLA's multi-threaded Eigen pool on the CPU can wedge a run at random on small
machines (seen here with 2 cores); single-threaded Eigen avoids it. Set before
JAX initialises its backend.
"""

import os

_flag = "--xla_cpu_multi_thread_eigen=false"
if _flag not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _flag).strip()
