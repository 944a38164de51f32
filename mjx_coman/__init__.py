"""COMAN in MuJoCo MJX: model, series-elastic actuators, sensors, environment.

The model is generated from the CAD link table by :mod:`mjx_coman.mjcf`;
:func:`model_path` gives the scene file (floor, light, robot) and
:func:`load_model` the compiled ``mujoco.MjModel``.
"""

from __future__ import annotations

from pathlib import Path

import mujoco

ASSETS_DIR = Path(__file__).resolve().parent / "assets"


def model_path() -> Path:
    """Path of the scene MJCF (floor, light and the robot)."""
    return ASSETS_DIR / "scene.xml"


def load_model() -> mujoco.MjModel:
    """Compile the scene into a ``mujoco.MjModel`` (loads in MuJoCo and ``mjx.put_model``)."""
    return mujoco.MjModel.from_xml_path(str(model_path()))
