"""sweeps.grid: validation, row order, configuration identity."""

import math

import numpy as np
import pytest

from sweeps.grid import DIRECTIONS_RAD, GridError, SweepConfig, grid_inputs
from sweeps.models import check


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


def test_several_directions_repeat_the_grid_direction_major_and_keep_old_hashes():
    one = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0), direction="left")
    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0),
                      directions=("forward", "90", "backward")).validate()
    assert cfg.n_per_direction == 6 and cfg.n_rollouts == 18
    g, g1 = grid_inputs(cfg), grid_inputs(one)
    for d, heading in enumerate((0.0, math.pi / 2, math.pi)):  # rows 6d..6d+5 are direction d's whole grid
        np.testing.assert_array_equal(g.phase[6 * d:6 * d + 6], g1.phase)
        np.testing.assert_array_equal(g.impulse_ns[6 * d:6 * d + 6], g1.impulse_ns)
        np.testing.assert_allclose(g.direction_rad[6 * d:6 * d + 6], heading)
    np.testing.assert_array_equal(grid_inputs(cfg.for_direction(1)).direction_rad, g1.direction_rad)
    assert "directions" not in one.to_dict()  # sweeps of one direction keep their hashes
    assert SweepConfig.from_dict(cfg.to_dict()) == cfg and cfg.hash() != one.hash()
    assert cfg.compiled_part() == one.compiled_part()  # headings are inputs: one compilation for all
    with pytest.raises(GridError, match="unknown direction 'up'"):
        SweepConfig(directions=("forward", "up")).validate()


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
    assert base.to_dict()["results_version"] == 4  # failed solves recorded as such: older folders are other sweeps


def test_scenario_rows_are_scenario_minor_and_part_of_the_identity():
    from sweeps.grid import freeze_scenario, scenario_columns

    base = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(0.0, 2.0, 4.0))
    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(0.0, 2.0, 4.0),
                      scenario=freeze_scenario({"slope_deg": [0, 5], "payload_kg": [0, 1, 2]})).validate()
    assert cfg.scenario == (("payload_kg", (0.0, 1.0, 2.0)), ("slope_deg", (0.0, 5.0)))
    assert cfg.n_scenarios == 6 and cfg.n_rollouts == 6 * base.n_rollouts
    g, g0 = grid_inputs(cfg), grid_inputs(base)
    for s in range(6):  # rows s::6 are scenario s's grid, in the grid's own order
        np.testing.assert_array_equal(g.phase[s::6], g0.phase)
        np.testing.assert_array_equal(g.impulse_ns[s::6], g0.impulse_ns)
        assert np.all(g.scenario_index[s::6] == s)
    cols = scenario_columns(cfg, g.scenario_index)
    assert cols["payload_kg"][:6].tolist() == [0, 0, 1, 1, 2, 2] and cols["slope_deg"][:6].tolist() == [0, 5] * 3
    assert SweepConfig.from_dict(cfg.to_dict()) == cfg
    assert "scenario" not in base.to_dict()  # sweeps without scenarios keep their hashes
    assert cfg.hash() != base.hash()
    assert cfg.compiled_part().scenario == cfg.scenario  # a rollout finds its scenario from its index
    act = SweepConfig(model="mjx", scenario=freeze_scenario({"actuator": ["ideal", "sea"]})).validate()
    assert act.scenario == (("actuator", ("ideal", "sea")),) and act.n_scenarios == 2
    with pytest.raises(GridError, match="actuator='hydraulic'"):
        SweepConfig(model="mjx", scenario=freeze_scenario({"actuator": ["hydraulic"]})).validate()
    with pytest.raises(GridError, match="terrain takes one value"):
        SweepConfig(model="mjx", scenario=freeze_scenario({"terrain": ["flat", "rough:2"]})).validate()
    with pytest.raises(GridError, match="mjx only"):
        SweepConfig(model="3lp", scenario=freeze_scenario({"payload_kg": [1]})).validate()


def test_a_rollout_takes_its_own_scenarios_parameters():
    """The MJX model's scenario parameters (host-built, one compilation for all) hold each scenario in its row."""
    from mjx_coman.scenarios import select
    from sweeps.grid import freeze_scenario
    from sweeps.models import mjx

    cfg = SweepConfig(model="mjx", scenario=freeze_scenario({"payload_kg": [0, 1.5], "delay_ms": [0, 10],
                                                            "imu_noise_deg": [3]})).validate()
    params, axes = mjx.scenario_env(cfg)
    base = mjx.nominal_env(cfg.sensor_noise_scale)
    torso = 1 + [i for i in range(params.model.body_mass.shape[1] - 1)
                 if float(params.model.body_mass[1, i + 1] - params.model.body_mass[0, i + 1]) != 0][0]
    for i, row in enumerate(cfg.scenarios()):
        p = select(params, axes, i)
        assert float(p.model.body_mass[torso] - base.model.body_mass[torso]) == pytest.approx(row["payload_kg"], 1e-6)
        assert int(p.actuator.delay_ticks) == int(base.actuator.delay_ticks) + round(row["delay_ms"] / 2)
        assert float(p.sensor.imu_orientation_noise_rad) == pytest.approx(math.radians(3), 1e-6)
