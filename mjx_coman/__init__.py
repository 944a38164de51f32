"""COMAN in MuJoCo MJX: model, series-elastic actuators, sensors, environment, controllers, rollouts judged on ground truth.

The model is generated from the CAD link table by :mod:`mjx_coman.mjcf`;
:func:`model_path` gives the scene file (floor, light, robot) and
:func:`load_model` the compiled ``mujoco.MjModel``.
"""

from __future__ import annotations

from jaxlp.xla_flags import configure_cpu

configure_cpu()  # before anything below starts JAX's backend (see jaxlp.xla_flags)

import contextlib  # noqa: E402
import io  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402

# mujoco.mjx prints "Failed to import warp" on stdout when the optional Warp backend is absent
# (always, on CPU); swallow that notice so that the command lines' JSON on stdout stays parseable
# and their one-line errors on stderr stay one line.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx  # noqa: F401

ASSETS_DIR = Path(__file__).resolve().parent / "assets"


def model_path() -> Path:
    """Path of the scene MJCF (floor, light and the robot)."""
    return ASSETS_DIR / "scene.xml"


def load_model() -> mujoco.MjModel:
    """Compile the scene into a ``mujoco.MjModel`` (loads in MuJoCo and ``mjx.put_model``)."""
    return mujoco.MjModel.from_xml_path(str(model_path()))
