"""sweeps.holdout_mjx: tuned constants into MJX sweeps (mapping, files, the controller they reach), slow held-out run."""

import json
from pathlib import Path

import numpy as np
import pytest

from sweeps import holdout_mjx
from sweeps.grid import SweepConfig

TUNED = Path(__file__).parents[2] / "notebooks" / "data" / "05" / "tuned.json"


def test_sweep_fields_of_a_tune_record():
    record = json.loads(TUNED.read_text())
    after = record["constants_after"]
    f = holdout_mjx.load_constants(TUNED)
    assert f["deadzone"] == pytest.approx((after["deadzone_swing_position_m"], after["deadzone_pelvis_position_m"],
                                           after["deadzone_swing_velocity_mps"], after["deadzone_pelvis_velocity_mps"]))
    assert f["zeta"] == pytest.approx(after["zeta"])
    assert f["velocity_window"] == round(after["window_samples"])  # the MJX window is whole samples
    before = holdout_mjx.load_constants(TUNED, "before")
    assert before["zeta"] == pytest.approx(0.1, abs=1e-6) and before["velocity_window"] == 30
    cfgs = holdout_mjx.holdout_configs(f, phases=(0.5,), impulses_ns=(0.0, 3.0))
    assert [c.direction for c in cfgs] == ["forward", "backward"] and all(c.zeta == f["zeta"] for c in cfgs)


@pytest.mark.parametrize("text, match", [
    ("{not json", "cannot read"), ('{"constants_after": {"zeta": 0.1}}', "lack 'deadzone_swing_position_m'"),
    ("[1, 2]", "no constants"),
])
def test_bad_constants_files_name_the_problem(tmp_path, text, match):
    path = tmp_path / "c.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        holdout_mjx.load_constants(path)


def test_constants_reach_the_walking_controller():
    from sweeps import model_mjx

    cfg = SweepConfig(model="mjx", deadzone=(0.001, 0.002, 0.03, 0.05), zeta=0.25, velocity_window=12).validate()
    _, ctrl = model_mjx.nominal(cfg)
    np.testing.assert_allclose(np.asarray(ctrl.deadzone), cfg.deadzone, rtol=1e-6)
    assert float(ctrl.zeta) == pytest.approx(0.25) and ctrl.window == 12


@pytest.mark.parametrize("args, word", [
    (["map", "--constants", "MISSING"], "--constants applies to --model mjx only"),
    (["map", "--model", "mjx", "--constants", "MISSING"], "cannot read constants"),
])
def test_constants_option_errors_exit_2(args, word, tmp_path, capsys):
    from sweeps.cli import main

    with pytest.raises(SystemExit) as exc:
        main([a.replace("MISSING", str(tmp_path / "none.json")) for a in args] + ["--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_mjx_holdout_compares_the_sets_and_resumes(tmp_path):
    """Thresholds of 1 m and 10 m/s leave no error past the dead-zone: no footstep adjustment, so a 6 N s push
    that the seed's constants recover at phase 0 topples the walk; a re-run resumes every chunk."""
    record = json.loads(TUNED.read_text())
    record["constants_before"] = dict(record["constants_after"], deadzone_swing_position_m=0.004,
                                      deadzone_pelvis_position_m=0.004, deadzone_swing_velocity_mps=0.04,
                                      deadzone_pelvis_velocity_mps=0.04, zeta=0.1, window_samples=30.0)
    record["constants_after"] = dict(record["constants_before"], deadzone_swing_position_m=1.0,
                                     deadzone_pelvis_position_m=1.0, deadzone_swing_velocity_mps=10.0,
                                     deadzone_pelvis_velocity_mps=10.0)
    grid = dict(directions=("forward",), phases=(0.0,), impulses_ns=(0.0, 6.0), n_steps=7, chunk=2)
    out = holdout_mjx.run_mjx_holdout(record, tmp_path, progress=False, **grid)
    seed, tuned = (out["runs"][k][0].results for k in ("seed", "tuned"))
    assert not seed["fell"].any(), seed
    assert not tuned["fell"][0] and tuned["fell"][1]
    table = json.loads((tmp_path / "holdout_mjx.json").read_text())
    assert table["seed"]["recovery_rate"] == 1.0 and table["tuned"]["recovery_rate"] == 0.5
    assert (tmp_path / "holdout_mjx.png").stat().st_size > 1000
    again = holdout_mjx.run_mjx_holdout(record, tmp_path, progress=False, **grid)
    assert all(r.timing["rollouts_resumed"] == 2 for lst in again["runs"].values() for r in lst)
