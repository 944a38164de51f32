"""Property-based checks of the sweep configuration's validation (hypothesis): any values are either
refused with a GridError naming the field or accepted finite and in range; never another exception."""

import math

import pytest
from hypothesis import given, settings, strategies as st

from sweeps.grid import MAX_N_STEPS, GridError, SweepConfig

ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=64)
FLOAT_FIELDS = ("push_duration_s", "step_time_s", "speed_mps", "noise_std_m", "bias_m", "bias_std_m",
                "recover_tol", "randomize_mass_pct", "randomize_leg_pct")


@settings(max_examples=300, deadline=None)
@given(field=st.sampled_from(FLOAT_FIELDS), value=ANY_FLOAT)
def test_a_float_field_is_refused_by_name_or_accepted_finite(field, value):
    try:
        cfg = SweepConfig(**{field: value}).validate()
    except GridError as e:
        assert field in str(e) and "\n" not in str(e)
        return
    v = getattr(cfg, field)
    assert math.isfinite(v)
    if field in ("push_duration_s", "step_time_s", "recover_tol"):
        assert v > 0
    if field not in ("speed_mps", "bias_m"):
        assert v >= 0


@settings(max_examples=200, deadline=None)
@given(n_steps=st.integers(-10, 10**12), push_step=st.integers(-10, 10**6), seed=st.integers(-10, 2**70),
       chunk=st.integers(-10, 10**6))
def test_integer_fields_are_bounded(n_steps, push_step, seed, chunk):
    try:
        cfg = SweepConfig(n_steps=n_steps, push_step=push_step, seed=seed, chunk=chunk).validate()
    except GridError as e:
        assert any(name in str(e) for name in ("n_steps", "push_step", "seed", "chunk"))
        return
    assert 0 <= cfg.push_step < cfg.n_steps <= MAX_N_STEPS and 0 <= cfg.seed < 2**32 and cfg.chunk >= 1


@settings(max_examples=200, deadline=None)
@given(phases=st.lists(ANY_FLOAT, max_size=4), impulses=st.lists(ANY_FLOAT, max_size=4))
def test_grid_axes_are_finite_and_in_range_or_refused(phases, impulses):
    try:
        cfg = SweepConfig(phases=tuple(phases), impulses_ns=tuple(impulses)).validate()
    except GridError:
        return
    assert cfg.phases and all(0.0 <= p < 1.0 for p in cfg.phases)
    assert cfg.impulses_ns and all(math.isfinite(v) and v >= 0 for v in cfg.impulses_ns)


@pytest.mark.parametrize("field,value", [("robot", "human"), ("n_steps", MAX_N_STEPS + 1)])
def test_refusals_that_name_the_option(field, value):
    kw = {field: value, **({"model": "mjx"} if field == "robot" else {})}
    with pytest.raises(GridError, match=field):
        SweepConfig(**kw).validate()
