"""sweeps.cross_engine: outcome agreement of two sweeps; the engine field of a sweep's identity and devices
(``coman-sweep engines``' bad arguments are in ``tests/test_entry_points.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from sweeps.cross_engine import boundary_gap_ns, outcome_agreement
from sweeps.grid import GridError, SweepConfig


def _grid(fell):
    """A 2-phase x 4-impulse forward grid with the given outcomes (impulse-minor rows)."""
    fell = np.asarray(fell, bool).ravel()
    phase = np.repeat([0.0, 0.5], 4)
    imp = np.tile([0.0, 2.0, 4.0, 6.0], 2)
    return dict(index=np.arange(8), phase=phase, impulse_ns=imp, direction_rad=np.zeros(8), fell=fell,
                steps_to_recover=np.where(fell, -1, 2))


def test_agreement_counts_the_differing_pushes_and_their_distance_to_the_boundary():
    mjx = _grid([[0, 0, 1, 1], [0, 0, 0, 1]])
    native = _grid([[0, 1, 1, 1], [0, 0, 0, 1]])
    native["steps_to_recover"][0] = 3
    a = outcome_agreement(mjx, native)
    assert a["rollouts"] == 8 and a["identical"] == 7 and a["identical_fraction"] == pytest.approx(7 / 8)
    assert a["fell_mjx"] == 3 and a["fell_native"] == 4
    (d,) = a["differing"]
    assert d == dict(phase=0.0, impulse_ns=2.0, direction_deg=0.0, fell_mjx=False, fell_native=True,
                     boundary_gap_ns=1.0)  # the MJX lane flips between 2 and 4 N s
    # both recovered in 4 rows: one of them with another step count
    assert a["steps_to_recover_identical_fraction"] == pytest.approx(3 / 4)
    assert a["steps_to_recover_mean_abs_difference"] == pytest.approx(1 / 4)


def test_boundary_gap_is_infinite_in_a_lane_of_one_outcome():
    gap = boundary_gap_ns(_grid([[0, 0, 0, 0], [0, 1, 1, 1]]))
    assert np.all(np.isinf(gap[:4])) and gap[4:].tolist() == [1.0, 1.0, 3.0, 5.0]


def test_agreement_refuses_two_different_grids():
    other = _grid(np.zeros(8))
    other["impulse_ns"] = other["impulse_ns"] + 1
    with pytest.raises(ValueError, match="impulse_ns"):
        outcome_agreement(_grid(np.zeros(8)), other)


def test_the_engine_is_part_of_a_sweeps_identity_and_mjx_keeps_the_old_hash():
    mjx = SweepConfig(model="mjx").validate()
    assert "engine" not in mjx.to_dict()  # sweeps written before the field keep their hash
    native = SweepConfig(model="mjx", engine="native").validate()
    assert native.to_dict()["engine"] == "native" and native.hash() != mjx.hash()
    assert SweepConfig.from_dict(native.to_dict()) == native
    with pytest.raises(GridError, match="'ode'"):
        SweepConfig(model="mjx", engine="ode").validate()
    with pytest.raises(GridError, match="--model mjx only"):
        SweepConfig(model="3lp", engine="native").validate()


def test_a_native_sweep_runs_on_one_device_of_several(monkeypatch):
    import jax

    from sweeps import runner

    monkeypatch.setattr(jax, "devices", lambda: ["cpu:0", "cpu:1", "cpu:2", "cpu:3"])
    assert runner.sweep_devices(SweepConfig(model="mjx")) == ("cpu:0", "cpu:1", "cpu:2", "cpu:3")
    assert runner.sweep_devices(SweepConfig(model="mjx", engine="native")) == ("cpu:0",)
