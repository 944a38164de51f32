"""3LP model parameters, built from a segment table.

The 3LP model (seed 000, section "3LP Model"; brief ``3LP_MODEL.md`` section 1)
lumps a humanoid into three linear pendulums joined by a massless pelvis:

* ``m1``: torso (trunk, arms, head) with its CoM ``h3`` above the pelvis;
* ``m2``: each leg, its CoM ``h2`` below the hip, inertia ``I2`` about that CoM;
* ``h1``: the pelvis height (leg length), ``pw``: half the pelvis width.

Parameters are array pytrees so that ``jax.vmap``, ``jax.grad`` and optax reach
every one of them. The builders (:func:`make_params`, :func:`from_segments`,
the presets) validate concrete values and raise ``ValueError`` naming the bad
value; the dataclass constructor itself does not validate so that JAX can
rebuild it from tracers.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

GRAVITY_MPS2 = 9.81


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _check_positive(name: str, value) -> None:
    """Raise ``ValueError`` if a concrete ``value`` is not finite and positive."""
    if not _is_concrete(value):
        return
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise ValueError(f"{name} must be finite and positive, got {arr.tolist()}")


def _check_nonnegative(name: str, value) -> None:
    if not _is_concrete(value):
        return
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"{name} must be finite and non-negative, got {arr.tolist()}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ThreeLPParams:
    """Physical parameters of the 3LP model (SI units).

    Attributes:
        m1: torso (upper body) mass, kg.
        m2: mass of one leg, kg.
        h1: pelvis height = leg length, m.
        h2: distance from the hip down to the leg CoM, m.
        h3: torso CoM height above the pelvis, m.
        I2: leg inertia about its own CoM (sagittal = lateral), kg m^2.
        pw: half pelvis width (hip offset from the pelvis centre), m.
        g: gravity, m/s^2.
        other_mass_kg: mass of the robot that no 3LP body carries (COMAN: the
            pelvis, which the 3LP keeps massless), kg; it enters only
            :attr:`total_mass_kg`, which scales the DLQR torque cost.
    """

    m1: jax.Array
    m2: jax.Array
    h1: jax.Array
    h2: jax.Array
    h3: jax.Array
    I2: jax.Array
    pw: jax.Array
    g: jax.Array
    other_mass_kg: jax.Array

    @property
    def model_mass_kg(self) -> jax.Array:
        """Mass of the 3LP bodies, ``m1 + 2 m2`` (kg)."""
        return self.m1 + 2.0 * self.m2

    @property
    def total_mass_kg(self) -> jax.Array:
        """The robot's nominal total mass, ``m1 + 2 m2 + other_mass_kg`` (kg; COMAN 28.5)."""
        return self.model_mass_kg + self.other_mass_kg

    def as_dict(self) -> dict[str, float]:
        """Concrete values as plain floats (for reports and JSON)."""
        return {f.name: float(getattr(self, f.name)) for f in dataclasses.fields(self)}

    def validate(self) -> "ThreeLPParams":
        """Check concrete values; return ``self`` so calls chain.

        Raises:
            ValueError: a non-positive mass, length or inertia, a negative
                pelvis width, or a leg CoM at or below the foot (``h2 >= h1``).
        """
        for name in ("m1", "m2", "h1", "h2", "I2", "g"):
            _check_positive(name, getattr(self, name))
        _check_nonnegative("h3", self.h3)
        _check_nonnegative("pw", self.pw)
        _check_nonnegative("other_mass_kg", self.other_mass_kg)
        if _is_concrete(self.h1) and _is_concrete(self.h2):
            h1 = np.asarray(self.h1, float)
            h2 = np.asarray(self.h2, float)
            if np.any(h2 >= h1):
                raise ValueError(
                    f"h2 (hip to leg CoM, {h2.tolist()} m) must be smaller than "
                    f"h1 (leg length, {h1.tolist()} m)"
                )
        return self


def make_params(
    m1: float,
    m2: float,
    h1: float,
    h2: float,
    h3: float,
    I2: float,
    pw: float,
    g: float = GRAVITY_MPS2,
    other_mass_kg: float = 0.0,
) -> ThreeLPParams:
    """Build validated 3LP parameters from their values.

    Raises:
        ValueError: see :meth:`ThreeLPParams.validate`.
    """
    vals = dict(m1=m1, m2=m2, h1=h1, h2=h2, h3=h3, I2=I2, pw=pw, g=g, other_mass_kg=other_mass_kg)
    return ThreeLPParams(**{k: jnp.asarray(v, dtype=float) for k, v in vals.items()}).validate()


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SegmentTable:
    """A humanoid as lumped mass elements, from which 3LP parameters follow.

    Leg elements hang below the hip joint: each has a mass, its CoM distance
    below the hip, and its inertia about its own CoM (sagittal). Upper-body
    elements each have a mass and a CoM height above the pelvis. A backpack or
    a sensor box is one more element (see :func:`add_point_mass`).

    Attributes:
        leg_mass_kg: (n,) masses of one leg's elements.
        leg_com_below_hip_m: (n,) CoM distances below the hip.
        leg_inertia_kgm2: (n,) inertia of each element about its own CoM.
        leg_length_m: hip-to-sole length (the 3LP ``h1``).
        upper_mass_kg: (k,) masses of the upper-body elements.
        upper_com_height_m: (k,) CoM heights above the pelvis.
        half_pelvis_width_m: hip offset from the pelvis centre.
        other_mass_kg: mass in neither the legs nor the upper body (a pelvis
            the 3LP keeps massless); counted only in the total mass.
    """

    leg_mass_kg: jax.Array
    leg_com_below_hip_m: jax.Array
    leg_inertia_kgm2: jax.Array
    leg_length_m: jax.Array
    upper_mass_kg: jax.Array
    upper_com_height_m: jax.Array
    half_pelvis_width_m: jax.Array
    other_mass_kg: jax.Array

    def validate(self) -> "SegmentTable":
        """Raise ``ValueError`` for a non-physical concrete table; return ``self``."""
        _check_nonnegative("leg_mass_kg", self.leg_mass_kg)
        _check_positive("sum(leg_mass_kg)", jnp.sum(self.leg_mass_kg) if _is_concrete(self.leg_mass_kg) else self.leg_mass_kg)
        _check_nonnegative("leg_com_below_hip_m", self.leg_com_below_hip_m)
        _check_nonnegative("leg_inertia_kgm2", self.leg_inertia_kgm2)
        _check_positive("leg_length_m", self.leg_length_m)
        _check_nonnegative("upper_mass_kg", self.upper_mass_kg)
        _check_positive("sum(upper_mass_kg)", jnp.sum(self.upper_mass_kg) if _is_concrete(self.upper_mass_kg) else self.upper_mass_kg)
        _check_nonnegative("half_pelvis_width_m", self.half_pelvis_width_m)
        _check_nonnegative("other_mass_kg", self.other_mass_kg)
        return self


def rod_chain_leg(
    masses_kg: Sequence[float],
    lengths_m: Sequence[float],
    com_ratios: Sequence[float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Leg elements of a vertical chain of thin rods (thigh, shank, foot...).

    Each segment starts where the previous one ends; its CoM lies at
    ``com_ratio * length`` from its proximal end; its inertia about its own CoM
    is that of a thin rod, ``m L^2 / 12`` (brief section 1).

    Returns:
        masses, CoM distances below the hip, inertias about own CoM, and the
        total length (hip to sole).

    Raises:
        ValueError: mismatched lengths, non-positive lengths, ratios outside [0, 1].
    """
    m = np.asarray(masses_kg, float)
    length = np.asarray(lengths_m, float)
    r = np.asarray(com_ratios, float)
    if not (m.shape == length.shape == r.shape) or m.ndim != 1:
        raise ValueError(
            f"masses_kg, lengths_m and com_ratios must be 1-D of one length, got shapes "
            f"{m.shape}, {length.shape}, {r.shape}"
        )
    _check_positive("lengths_m", length)
    _check_nonnegative("masses_kg", m)
    if np.any((r < 0) | (r > 1)):
        raise ValueError(f"com_ratios must lie in [0, 1], got {r.tolist()}")
    starts = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    com = starts + r * length
    inertia = m * length**2 / 12.0
    return m, com, inertia, float(np.sum(length))


def from_segments(table: SegmentTable, g: float = GRAVITY_MPS2) -> ThreeLPParams:
    """Lump a segment table into 3LP parameters (brief section 1).

    ``m2`` is the leg mass, ``h2`` the mass-weighted mean CoM distance below
    the hip, ``I2`` the sum of the element inertias plus their parallel-axis
    terms about the leg CoM; ``m1`` and ``h3`` lump the upper body. Pure jnp:
    differentiable with respect to every entry of the table.

    Raises:
        ValueError: for a non-physical concrete table or result.
    """
    table.validate()
    m2 = jnp.sum(table.leg_mass_kg)
    h2 = jnp.sum(table.leg_mass_kg * table.leg_com_below_hip_m) / m2
    I2 = jnp.sum(table.leg_inertia_kgm2 + table.leg_mass_kg * (table.leg_com_below_hip_m - h2) ** 2)
    m1 = jnp.sum(table.upper_mass_kg)
    h3 = jnp.sum(table.upper_mass_kg * table.upper_com_height_m) / m1
    params = ThreeLPParams(
        m1=m1, m2=m2, h1=jnp.asarray(table.leg_length_m, float), h2=h2, h3=h3, I2=I2,
        pw=jnp.asarray(table.half_pelvis_width_m, float), g=jnp.asarray(g, float),
        other_mass_kg=jnp.asarray(table.other_mass_kg, float),
    )
    return params.validate()


def add_point_mass(
    table: SegmentTable, mass_kg: float, *, segment: str, position_m: float
) -> SegmentTable:
    """Add a point mass (a backpack, a battery) to the torso or to each leg.

    Args:
        table: the table to extend (returned as a new table).
        mass_kg: the added mass, kg (> 0).
        segment: ``"torso"`` (``position_m`` is the height above the pelvis) or
            ``"leg"`` (added to both legs; ``position_m`` is the distance below
            the hip, within the leg length).
        position_m: see ``segment``.

    Raises:
        ValueError: unknown segment, non-positive mass, position off the leg.
    """
    _check_positive("mass_kg", mass_kg)
    if segment == "torso":
        return dataclasses.replace(
            table,
            upper_mass_kg=jnp.append(table.upper_mass_kg, mass_kg),
            upper_com_height_m=jnp.append(table.upper_com_height_m, position_m),
        )
    if segment == "leg":
        if not 0.0 <= float(position_m) <= float(table.leg_length_m):
            raise ValueError(
                f"position_m={position_m} m lies off the leg (0 to {float(table.leg_length_m)} m below the hip)"
            )
        return dataclasses.replace(
            table,
            leg_mass_kg=jnp.append(table.leg_mass_kg, mass_kg),
            leg_com_below_hip_m=jnp.append(table.leg_com_below_hip_m, position_m),
            leg_inertia_kgm2=jnp.append(table.leg_inertia_kgm2, 0.0),
        )
    raise ValueError(f"segment must be 'torso' or 'leg', got {segment!r}")
