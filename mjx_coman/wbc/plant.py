"""What the whole-body QP reads of the robot each tick: :class:`Plant`, plain arrays, and its layout.

The fields carry the names of ``mjx_coman.dynamics.WholeBody`` (which this package does not import);
:func:`plant_from` copies them from any object that has them. Conventions (MuJoCo's): ``qvel`` is the
free base's world linear velocity, its local angular velocity, then the 23 hinges in
``mjx_coman.actuators.JOINT_NAMES`` order (actuated joint ``i`` is ``qvel[6 + i]``); frame Jacobians have
rows linear then angular velocity, world axes; the centroidal momentum matrix has rows linear momentum
then angular momentum about the CoM, world axes; foot 0 is the right foot, 1 the left.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

N_BASE = 6
N_FEET = 2
N_CORNERS = 4  # per foot: lowest points of the contact spheres at (0.12, +-0.04), (-0.06, +-0.04)
N_FORCES = N_FEET * N_CORNERS * 3  # a world-frame 3D force per corner
LEG_JOINTS = 12  # joints 0..11 (right then left leg)
UPPER_JOINTS = 11  # joints 12..22: 3 waist, 8 arm


class Plant(NamedTuple):
    """Whole-body terms of one state (arrays; vmappable). ``nv = 6 + nu``.

    Attributes:
        mass: joint-space inertia M, (nv, nv).
        bias: Coriolis, centrifugal and gravity forces h (MuJoCo's ``qfrc_bias``), (nv,).
        passive: passive forces (``qfrc_passive``), (nv,); the dynamics read ``M qdd + bias - passive``.
        contact_jac: corner point Jacobians, (2, 4, 3, nv).
        contact_bias_acc: corner ``Jdot qdot``, (2, 4, 3).
        contact_pos: corner positions, world, (2, 4, 3).
        sole_jac: sole-site frame Jacobians, (2, 6, nv).
        sole_bias_acc: sole-site ``Jdot qdot``, (2, 6).
        sole_rot: sole-site orientations (columns: axes in world), (2, 3, 3).
        torso_jac, torso_bias_acc, torso_rot: torso site, (6, nv), (6,), (3, 3).
        pelvis_jac, pelvis_bias_acc, pelvis_rot: pelvis site, (6, nv), (6,), (3, 3).
        com: whole-body CoM, world, (3,); com_vel: its velocity, (3,).
        com_jac: CoM Jacobian, (3, nv); com_bias_acc: its ``Jdot qdot``, (3,).
        cmm: centroidal momentum matrix, (6, nv); cmm_bias: ``Adot qdot``, (6,).
    """

    mass: jax.Array
    bias: jax.Array
    passive: jax.Array
    contact_jac: jax.Array
    contact_bias_acc: jax.Array
    contact_pos: jax.Array
    sole_jac: jax.Array
    sole_bias_acc: jax.Array
    sole_rot: jax.Array
    torso_jac: jax.Array
    torso_bias_acc: jax.Array
    torso_rot: jax.Array
    pelvis_jac: jax.Array
    pelvis_bias_acc: jax.Array
    pelvis_rot: jax.Array
    com: jax.Array
    com_vel: jax.Array
    com_jac: jax.Array
    com_bias_acc: jax.Array
    cmm: jax.Array
    cmm_bias: jax.Array


def plant_shapes(nv: int) -> dict[str, tuple[int, ...]]:
    """The shape of every :class:`Plant` field for ``nv`` velocities (unbatched)."""
    f, c = N_FEET, N_CORNERS
    return dict(mass=(nv, nv), bias=(nv,), passive=(nv,), contact_jac=(f, c, 3, nv), contact_bias_acc=(f, c, 3),
                contact_pos=(f, c, 3), sole_jac=(f, 6, nv), sole_bias_acc=(f, 6), sole_rot=(f, 3, 3),
                torso_jac=(6, nv), torso_bias_acc=(6,), torso_rot=(3, 3), pelvis_jac=(6, nv),
                pelvis_bias_acc=(6,), pelvis_rot=(3, 3), com=(3,), com_vel=(3,), com_jac=(3, nv),
                com_bias_acc=(3,), cmm=(6, nv), cmm_bias=(6,))


def check_plant(plant: Plant) -> int:
    """Check the (static) shapes of an unbatched plant; return ``nv``.

    Raises:
        ValueError: naming the field whose shape is wrong, or ``nv < 7``.
    """
    nv = int(np.shape(plant.mass)[-1]) if np.ndim(plant.mass) == 2 else -1
    if nv <= N_BASE:
        raise ValueError(f"plant.mass must be (nv, nv) with nv > {N_BASE}, got shape {np.shape(plant.mass)}")
    for name, shape in plant_shapes(nv).items():
        got = tuple(np.shape(getattr(plant, name)))
        if got != shape:
            raise ValueError(f"plant.{name} has shape {got}, expected {shape} for nv={nv}")
    return nv


def plant_from(terms) -> Plant:
    """A :class:`Plant` of the same-named attributes of ``terms`` (e.g. ``mjx_coman.dynamics.terms(...)``).

    Raises:
        ValueError: naming the attributes ``terms`` lacks.
    """
    missing = [f for f in Plant._fields if not hasattr(terms, f)]
    if missing:
        raise ValueError(f"{type(terms).__name__} lacks the plant fields {missing}")
    return Plant(**{f: getattr(terms, f) for f in Plant._fields})
