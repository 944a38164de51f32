"""Named 3LP parameter sets: the seed's COMAN table, human ratios, and the MJCF robot.

``coman`` is the segment table of seed 000 (brief ``3LP_MODEL.md`` section 1):
COMAN masses with human-proportioned segment lengths. ``human`` scales the
de Leva (1996) adjustments of the Zatsiorsky-Seluyanov segment parameters
(male) to a given height and mass.

Other packages add presets without this one knowing them: through
:func:`register_preset`, or through the ``jaxlp.presets`` entry-point group
of their distribution (``coman-mjcf``, derived from the MJCF of the simulated
robot, comes that way from ``mjx_coman.threelp_params``; see ``pyproject.toml``).
"""

from __future__ import annotations

from importlib import metadata
from typing import Callable

import jax.numpy as jnp
import numpy as np

from jaxlp.params import GRAVITY_MPS2, SegmentTable, ThreeLPParams, _check_positive, from_segments, rod_chain_leg

# Seed 000 / brief section 1: COMAN masses, human-like segment lengths.
_COMAN_LEG = dict(
    masses_kg=(3.61, 1.4, 1.38),  # thigh, shank, foot
    lengths_m=(0.2269, 0.2522, 0.0451),  # foot: ankle height (its vertical extent)
    com_ratios=(0.4033, 0.4165, 0.4633),
)
# The brief gives the upper-body masses (trunk, 2 upper arms, 2 forearms; head
# and hands 0) but not their heights; its lumped torso CoM height is used.
_COMAN_UPPER_MASS_KG = (7.65, 2.22, 2.22, 1.04, 1.04)
_COMAN_TORSO_COM_M = 0.189619
_COMAN_HALF_PELVIS_M = 0.0636
# The robot's nominal total mass (brief section 1; the seed authors' M of the
# DLQR torque cost) exceeds the listed segments by the pelvis the 3LP leaves out.
COMAN_TOTAL_MASS_KG = 28.5


def coman_table() -> SegmentTable:
    """The seed's COMAN segment table (brief section 1)."""
    m, com, inertia, length = rod_chain_leg(**_COMAN_LEG)
    return SegmentTable(
        leg_mass_kg=jnp.asarray(m),
        leg_com_below_hip_m=jnp.asarray(com),
        leg_inertia_kgm2=jnp.asarray(inertia),
        leg_length_m=jnp.asarray(length),
        upper_mass_kg=jnp.asarray(_COMAN_UPPER_MASS_KG),
        upper_com_height_m=jnp.full(len(_COMAN_UPPER_MASS_KG), _COMAN_TORSO_COM_M),
        half_pelvis_width_m=jnp.asarray(_COMAN_HALF_PELVIS_M),
        other_mass_kg=jnp.asarray(COMAN_TOTAL_MASS_KG - sum(_COMAN_UPPER_MASS_KG) - 2.0 * sum(_COMAN_LEG["masses_kg"])),
    ).validate()


# de Leva (1996), male: mass fraction, length / stature, CoM ratio from the
# proximal end. Stature 1741 mm in the reference data.
_DE_LEVA = {
    "thigh": (0.1416, 422.2 / 1741, 0.4095),
    "shank": (0.0433, 434.0 / 1741, 0.4459),
    "foot": (0.0137, 0.039, 0.5),  # vertical extent: ankle height ~0.039 H (Winter)
    "trunk": (0.4346, 531.9 / 1741, 0.4486),  # CERV (top) to mid-hip
    "head": (0.0694, 242.9 / 1741, 0.5976),  # vertex to CERV, CoM from the vertex
    "upper_arm": (0.0271, 281.7 / 1741, 0.5772),
    "forearm": (0.0162, 268.9 / 1741, 0.4574),
    "hand": (0.0061, 86.2 / 1741, 0.7900),
}
_SHOULDER_ABOVE_HIP = 0.29  # shoulder joint centre above the hip joint, per stature
_HALF_HIP_SPACING = 0.05  # half the hip joint centre spacing, per stature


def human_table(height_m: float, mass_kg: float) -> SegmentTable:
    """A human segment table from standard anthropometric ratios.

    Args:
        height_m: stature, m (> 0).
        mass_kg: body mass, kg (> 0).

    Raises:
        ValueError: non-positive height or mass.
    """
    _check_positive("height_m", height_m)
    _check_positive("mass_kg", mass_kg)
    H, M = float(height_m), float(mass_kg)
    seg = {k: (f * M, r_len * H, c) for k, (f, r_len, c) in _DE_LEVA.items()}
    m, com, inertia, length = rod_chain_leg(
        masses_kg=[seg[k][0] for k in ("thigh", "shank", "foot")],
        lengths_m=[seg[k][1] for k in ("thigh", "shank", "foot")],
        com_ratios=[seg[k][2] for k in ("thigh", "shank", "foot")],
    )
    trunk_m, trunk_len, trunk_c = seg["trunk"]
    head_m, head_len, head_c = seg["head"]
    sh = _SHOULDER_ABOVE_HIP * H
    ua_m, ua_len, ua_c = seg["upper_arm"]
    fa_m, fa_len, fa_c = seg["forearm"]
    ha_m, ha_len, ha_c = seg["hand"]
    upper = [
        (trunk_m, trunk_len * (1.0 - trunk_c)),
        (head_m, trunk_len + head_len * (1.0 - head_c)),
        (2 * ua_m, sh - ua_c * ua_len),  # arms hanging
        (2 * fa_m, sh - ua_len - fa_c * fa_len),
        (2 * ha_m, sh - ua_len - fa_len - ha_c * ha_len),
    ]
    return SegmentTable(
        leg_mass_kg=jnp.asarray(m),
        leg_com_below_hip_m=jnp.asarray(com),
        leg_inertia_kgm2=jnp.asarray(inertia),
        leg_length_m=jnp.asarray(length),
        upper_mass_kg=jnp.asarray([u[0] for u in upper]),
        upper_com_height_m=jnp.asarray([u[1] for u in upper]),
        half_pelvis_width_m=jnp.asarray(_HALF_HIP_SPACING * H),
        other_mass_kg=jnp.asarray(0.0),  # de Leva's fractions sum to the whole body
    ).validate()


BUILT_IN = ("coman", "human")
ENTRY_POINT_GROUP = "jaxlp.presets"
_REGISTERED: dict[str, Callable[..., ThreeLPParams]] = {}


def register_preset(name: str, build: Callable[..., ThreeLPParams]) -> None:
    """Add a named preset: ``build(g=...)`` returns its 3LP parameters."""
    if name in BUILT_IN:
        raise ValueError(f"preset {name!r} is built in")
    _REGISTERED[name] = build


def _entry_points() -> dict:
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def robot_names() -> tuple[str, ...]:
    """Every preset name: the built-in ones, registered ones and those of installed entry points."""
    return tuple(dict.fromkeys((*BUILT_IN, *_REGISTERED, *sorted(_entry_points()))))


def get_params(robot: str = "coman", *, height_m: float = 1.75, mass_kg: float = 70.0,
               g: float = GRAVITY_MPS2) -> ThreeLPParams:
    """3LP parameters of a named robot.

    Args:
        robot: ``"coman"`` (seed 000), ``"human"`` (``height_m``, ``mass_kg``)
            or another preset of :func:`robot_names` (e.g. ``"coman-mjcf"``,
            derived from the simulated robot's MJCF).

    Raises:
        ValueError: an unknown name.
    """
    if robot == "coman":
        return from_segments(coman_table(), g=g)
    if robot == "human":
        return from_segments(human_table(height_m, mass_kg), g=g)
    if robot not in _REGISTERED:
        ep = _entry_points().get(robot)
        if ep is None:
            raise ValueError(f"unknown robot {robot!r}; choose one of {', '.join(robot_names())}")
        _REGISTERED[robot] = ep.load()  # imported only when asked for
    return _REGISTERED[robot](g=g)


def leg_length_ratio(params: ThreeLPParams, height_m: float) -> float:
    """``h1 / height``: a sanity figure for human tables (about 0.53)."""
    return float(np.asarray(params.h1) / height_m)
