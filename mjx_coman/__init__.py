"""COMAN in MuJoCo MJX: model, series-elastic actuators, sensors, environment.

The model is generated from the CAD link table by :mod:`mjx_coman.mjcf`;
:func:`model_path` gives the scene file (floor, light, robot) and
:func:`load_model` the compiled ``mujoco.MjModel``.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import mujoco

# mujoco.mjx prints "Failed to import warp" on stdout when Warp is absent; send it to stderr
# so that the command lines' JSON on stdout stays parseable.
with contextlib.redirect_stdout(sys.stderr):
    from mujoco import mjx  # noqa: F401

ASSETS_DIR = Path(__file__).resolve().parent / "assets"


def model_path() -> Path:
    """Path of the scene MJCF (floor, light and the robot)."""
    return ASSETS_DIR / "scene.xml"


def load_model() -> mujoco.MjModel:
    """Compile the scene into a ``mujoco.MjModel`` (loads in MuJoCo and ``mjx.put_model``)."""
    return mujoco.MjModel.from_xml_path(str(model_path()))
