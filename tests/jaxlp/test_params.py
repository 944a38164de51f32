import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlp import params as P
from jaxlp.presets import coman_table, get_params, human_table

# brief 3LP_MODEL.md section 1
BRIEF = dict(m1=14.17, m2=6.39, h1=0.5242, h2=0.232403, h3=0.189619, I2=0.207492, pw=0.0636)


@pytest.mark.parametrize("name,value", sorted(BRIEF.items()))
def test_coman_matches_brief(coman, name, value):
    assert float(getattr(coman, name)) == pytest.approx(value, rel=2e-6)


def test_human_preset_proportions():
    p = get_params("human", height_m=1.8, mass_kg=75.0)
    assert float(p.m1 + 2 * p.m2) == pytest.approx(75.0 * (1 - 0.0), rel=1e-9)
    assert 0.50 < float(p.h1) / 1.8 < 0.56  # hip height about 0.53 of stature
    assert 0.30 < float(p.h2 / p.h1) < 0.45  # leg CoM about a third down the leg
    assert float(p.m2) / 75.0 == pytest.approx(0.1416 + 0.0433 + 0.0137)  # de Leva thigh + shank + foot
    assert float(p.h3) > 0.0


def test_human_scales_with_height_and_mass():
    a = get_params("human", height_m=1.6, mass_kg=60.0)
    b = get_params("human", height_m=1.6 * 1.1, mass_kg=60.0 * 1.1)
    assert float(b.h1 / a.h1) == pytest.approx(1.1, rel=1e-9)
    # inertia ~ mass * length^2
    assert float(b.I2 / a.I2) == pytest.approx(1.1**3, rel=1e-9)


def test_torso_backpack_raises_torso_com():
    base = coman_table()
    heavy = P.add_point_mass(base, 5.0, segment="torso", position_m=0.3)
    p0, p1 = P.from_segments(base), P.from_segments(heavy)
    assert float(p1.m1 - p0.m1) == pytest.approx(5.0)
    expected_h3 = (float(p0.m1) * float(p0.h3) + 5.0 * 0.3) / (float(p0.m1) + 5.0)
    assert float(p1.h3) == pytest.approx(expected_h3, rel=1e-12)
    assert float(p1.m2) == float(p0.m2)


def test_leg_point_mass_moves_leg_com_and_inertia():
    base = coman_table()
    heavy = P.add_point_mass(base, 1.0, segment="leg", position_m=0.5)
    p0, p1 = P.from_segments(base), P.from_segments(heavy)
    assert float(p1.m2) == pytest.approx(float(p0.m2) + 1.0)
    assert float(p1.h2) > float(p0.h2)
    # parallel axis: a point mass far below the CoM adds inertia
    assert float(p1.I2) > float(p0.I2)


def test_from_segments_is_differentiable():
    table = coman_table()
    grad = jax.grad(lambda t: P.from_segments(t).I2)(table)
    eps = 1e-6
    bumped = dataclasses.replace(table, leg_mass_kg=table.leg_mass_kg.at[2].add(eps))
    fd = (P.from_segments(bumped).I2 - P.from_segments(table).I2) / eps
    assert float(grad.leg_mass_kg[2]) == pytest.approx(float(fd), rel=1e-4)


@pytest.mark.parametrize(
    "field,value,match",
    [("m1", 0.0, "m1"), ("m2", -1.0, "m2"), ("h1", 0.0, "h1"), ("I2", -0.1, "I2"),
     ("h2", 0.6, "h2"), ("pw", -0.01, "pw"), ("g", float("nan"), "g")],
)
def test_bad_values_raise(field, value, match):
    vals = dict(BRIEF)
    vals[field] = value
    with pytest.raises(ValueError, match=match):
        P.make_params(**vals)


@pytest.mark.parametrize("kwargs,match", [(dict(height_m=-1.0, mass_kg=70.0), "height_m"),
                                           (dict(height_m=1.7, mass_kg=0.0), "mass_kg")])
def test_bad_human_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        human_table(**kwargs)


def test_unknown_robot_and_segment():
    with pytest.raises(ValueError, match="robot"):
        get_params("atlas")
    with pytest.raises(ValueError, match="segment"):
        P.add_point_mass(coman_table(), 1.0, segment="arm", position_m=0.1)
    with pytest.raises(ValueError, match="position_m"):
        P.add_point_mass(coman_table(), 1.0, segment="leg", position_m=2.0)


def test_params_vmap_over_a_batch(coman):
    batch = jax.tree.map(lambda x: jnp.stack([x, 1.1 * x]), coman)
    total = jax.vmap(lambda p: p.total_mass_kg)(batch)
    np.testing.assert_allclose(np.asarray(total), [float(coman.total_mass_kg), 1.1 * float(coman.total_mass_kg)])
