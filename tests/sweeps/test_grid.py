"""sweeps.grid: grid parsing, validation, configuration identity."""

import math

import numpy as np
import pytest

from sweeps.grid import DIRECTIONS_RAD, GridError, SweepConfig, grid_inputs, parse_impulses, parse_phases
from sweeps.models import check


@pytest.mark.parametrize("text, expected", [
    ("4", (0.0, 0.25, 0.5, 0.75)), ("0,0.5", (0.0, 0.5)), ("0.3", (0.3,)),
])
def test_parse_phases(text, expected):
    assert parse_phases(text) == pytest.approx(expected)


@pytest.mark.parametrize("text, expected", [("0:10:3", (0.0, 5.0, 10.0)), ("1,2.5", (1.0, 2.5)), ("3", (3.0,))])
def test_parse_impulses(text, expected):
    assert parse_impulses(text) == pytest.approx(expected)


@pytest.mark.parametrize("parse, text, match", [
    (parse_phases, "0", "count >= 1"), (parse_phases, "", "empty|count"), (parse_phases, "0.2,1.0", r"\[0, 1\)"),
    (parse_impulses, "0:10:0", "empty grid"), (parse_impulses, "-1,2", "non-negative"),
    (parse_impulses, "1,inf", "finite"), (parse_impulses, "1:2", "start:stop:num"), (parse_impulses, "a", "N s"),
])
def test_bad_grids_name_the_problem(parse, text, match):
    with pytest.raises(GridError, match=match):
        parse(text)


@pytest.mark.parametrize("fields, match", [
    (dict(phases=()), "empty"), (dict(impulses_ns=(1.0, -2.0)), "non-negative"),
    (dict(controller="pid"), "unknown controller 'pid'"), (dict(model="bullet"), "unknown model.*3lp.*mjx"),
    (dict(model="3lp", controller="no-deadzone"), "no-deadzone"), (dict(direction="up"), "unknown direction"),
    (dict(push_step=10), "push_step"), (dict(randomize_mass_pct=60.0), "below 50"),
    (dict(model="3lp", randomize_spring_pct=5.0), "mjx only"), (dict(model="mjx", noise_std_m=1e-3), "3lp only"),
    (dict(chunk=0), "chunk"), (dict(noise_std_m=math.nan), "noise_std_m"), (dict(speed_mps=math.inf), "speed_mps"),
    (dict(model="mjx", recover_tol=0.1), "recover_tol"), (dict(step_time_s=0.0), "step_time_s"),
    (dict(controller_overrides=(("zeta", 0.2), ("deadzone", (1, 1, 1, 1)))), "sorted"),
    (dict(controller_overrides=(("nope", 1.0),)), "unknown setting 'nope'"),
    (dict(controller_overrides=(("zeta", 1.5),)), "zeta"),
    (dict(controller_overrides=(("deadzone", (0.01, 0.02)),)), "deadzone"),
    (dict(model="mjx", controller="nope"), "unknown controller 'nope'.*time-projection"),
    (dict(model="mjx", controller_overrides=(("window", 0),)), "window"),
    (dict(model="mjx", controller_overrides=(("window_samples", 3.0),)), "unknown setting 'window_samples'"),
    (dict(model="mjx", step_time_s=0.5), "step_time_s"),
    (dict(model="mjx", speed_mps=0.5), "forward_mps"),
])
def test_validate_names_the_bad_value(fields, match):
    with pytest.raises(GridError, match=match):
        check(SweepConfig(**fields))


def test_grid_is_phase_major_and_the_hash_is_the_identity():
    cfg = SweepConfig(phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0), direction="left")
    inp = grid_inputs(cfg)
    np.testing.assert_array_equal(inp.index, np.arange(6))
    np.testing.assert_array_equal(inp.phase, [0, 0, 0, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(inp.impulse_ns, [1, 2, 3, 1, 2, 3])
    assert np.all(inp.direction_rad == DIRECTIONS_RAD["left"])
    same = SweepConfig(phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0), direction="left")
    assert cfg.hash() == same.hash() and len(cfg.hash()) == 16
    assert cfg.hash() != SweepConfig(phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0), direction="left", seed=1).hash()


def test_controller_overrides_are_part_of_the_identity_and_round_trip():
    base = check(SweepConfig(model="mjx"))
    tuned = check(base.with_overrides({"zeta": 0.2, "deadzone": [0.004, 0.004, 0.04, 0.04]}))
    assert tuned.controller_overrides == (("deadzone", (0.004, 0.004, 0.04, 0.04)), ("zeta", 0.2))
    assert tuned.to_dict()["controller_overrides"] == {"deadzone": [0.004, 0.004, 0.04, 0.04], "zeta": 0.2}
    assert len({base.hash(), tuned.hash(), base.with_overrides({"zeta": 0.3}).hash()}) == 3
    assert tuned.compiled_part().overrides() == {"deadzone": (0.004, 0.004, 0.04, 0.04), "zeta": 0.2}
    assert SweepConfig.from_dict(tuned.to_dict()) == tuned
    assert base.to_dict()["results_version"] == 2  # results judged on ground truth: older folders are other sweeps
